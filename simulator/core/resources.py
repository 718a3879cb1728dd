"""Memory estimates checked before allocating: refuse (InputError naming the option) what would not fit."""

from __future__ import annotations

import os

from simulator.core.errors import InputError

__all__ = ["available_memory", "check_fits", "human_bytes"]


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``; ``VIMSIM_MEMORY_LIMIT`` caps it,
    e.g. for tests); a large number where it cannot be read."""
    avail = None
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = int(line.split()[1]) * 1024
                    break
    except (OSError, ValueError, IndexError):
        pass
    if avail is None:
        try:
            avail = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (OSError, ValueError, AttributeError):
            avail = 1 << 62
    limit = os.environ.get("VIMSIM_MEMORY_LIMIT")
    if limit:
        try:
            avail = min(avail, int(float(limit)))
        except ValueError:
            pass
    return avail


def human_bytes(n: float) -> str:
    """``1.5 GB`` style (powers of 1000)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} PB"  # pragma: no cover


def check_fits(nbytes: float, option: str, *, fraction: float = 0.8) -> None:
    """InputError naming ``option`` when an estimated ``nbytes`` exceeds ``fraction`` of
    the available memory (checked before the allocation, so nothing is half-done)."""
    avail = available_memory()
    if nbytes > fraction * avail:
        raise InputError(
            f"{option} needs about {human_bytes(nbytes)} of memory; "
            f"{human_bytes(avail)} is available: choose a smaller value"
        )
