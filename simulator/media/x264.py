"""x264's CPU kernels for reproducible H.264 output: everything the CPU has except AVX-512.

x264 (core 165, as bundled with PyAV 18), on its AVX-512 kernels with its macroblock-tree
rate control on (the default), reads heap memory it never wrote: the encoded stream then
depends on what that memory held before, i.e. on the process's history. A fresh process gets zeroed pages
and repeats itself; a long one (``vimsim demo`` after synth and preprocess, a study
worker) gets recycled heap and the same frames encode to different bits (about 35-40 dB
PSNR between two runs). Evidence (``docs/reliability.md``, "Reproducible encodes"):
the same yuv420p frames under glibc's ``MALLOC_PERTURB_`` give a different stream per
fill byte with x264's own CPU detection, and one stream for every fill byte with that
detection less the AVX-512 bit (or with ``mbtree=0``, or without assembly).

:func:`x264_params` is what :class:`simulator.media.video.VideoWriter` passes as
``x264-params``: ``asm=N``, x264's own ``x264_cpu_detect()`` with the AVX-512 bit
cleared, so every other kernel (AVX2, FMA3, BMI2, ...) and the rate control stay as
they are. On a CPU without AVX-512 it is None (x264's choice is already reproducible).
The x264 library is the one this process loaded (found in ``/proc/self/maps``); where
it cannot be found (not Linux, x264 linked into libavcodec without its symbols) it is
None as well, and encodes on AVX-512 CPUs there keep x264's behaviour.
"""

from __future__ import annotations

import ctypes
import functools
import os

__all__ = ["x264_params"]


class _CpuName(ctypes.Structure):
    """One entry of x264's ``x264_cpu_names`` table (x264.h ``x264_cpu_name_t``)."""

    _fields_ = [("name", ctypes.c_char_p), ("flags", ctypes.c_uint32)]


def _flag(lib, name: str) -> int:
    """The CPU flag bits x264's ``x264_cpu_names`` gives ``name`` (0 when it has none)."""
    table = (_CpuName * 64).in_dll(lib, "x264_cpu_names")
    for entry in table:
        if not entry.flags or entry.name is None:
            return 0
        if entry.name.decode() == name:
            return int(entry.flags)
    return 0


def _loaded_x264():
    """The loaded x264 library (``ctypes.CDLL``), or None."""
    try:
        with open("/proc/self/maps") as f:
            paths = {ln.split()[-1] for ln in f if "/libx264" in ln or "/libavcodec" in ln}
    except OSError:
        return None
    for path in sorted(paths, key=lambda p: "libx264" not in os.path.basename(p)):
        try:
            lib = ctypes.CDLL(path)
            lib.x264_cpu_detect.restype = ctypes.c_uint32
            return lib
        except (OSError, AttributeError):
            continue
    return None


@functools.cache
def x264_params() -> str | None:
    """``"asm=N"``: x264's detected CPU flags less AVX-512 (module docstring), or None when
    x264 would use no AVX-512 kernel (or cannot be asked). Call after ``import av``."""
    lib = _loaded_x264()
    if lib is None:
        return None
    try:
        avx512 = _flag(lib, "AVX512") & ~_flag(lib, "AVX2")
        flags = int(lib.x264_cpu_detect())
    except (ValueError, AttributeError):
        return None
    if not avx512 or not flags & avx512:
        return None
    return f"asm={flags & ~avx512}"
