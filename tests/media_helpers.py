"""Synthetic media for the tests: the one writer of test clips and the frame patterns they use.

Every clip is encoded by the package's own :class:`simulator.media.video.VideoWriter`
(H.264, yuv420p), so a test's video is what ``vimsim`` itself would write. Frames are
``(h, w, 3)`` uint8 RGB, top row first; sizes are ``(width, height)``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from pathlib import Path

import numpy as np

__all__ = [
    "cut_clip", "gray_frames", "noise_frames", "smooth_equirect", "sv3d_box", "with_pose",
    "write_clip",
]


def write_clip(path, frames: Iterable[np.ndarray], fps: float = 10.0, *, preset: str = "ultrafast",
               crf: int = 18, **writer) -> Path:  # fmt: skip
    """Encode ``frames`` (at least one) into ``path`` at ``fps``; ``preset``, ``crf`` and
    ``writer`` go to :class:`simulator.media.video.VideoWriter` (``crf=0``: lossless luma,
    for tests that read pixel values back)."""
    from simulator.media.video import VideoWriter

    it = iter(frames)
    first = np.asarray(next(it))
    h, w = first.shape[:2]
    with VideoWriter(path, fps, (w, h), preset=preset, crf=crf, **writer) as wr:
        wr.write(first)
        for f in it:
            wr.write(f)
    return Path(path)


def noise_frames(n: int, size=(128, 64), seed: int = 0):
    """``n`` frames of uniform noise (seeded: the same frames every run)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield rng.integers(0, 256, (size[1], size[0], 3), dtype=np.uint8)


def gray_frames(levels: Iterable[int], size=(128, 64)):
    """One uniform gray frame per level (0..255): a frame's brightness can name it."""
    for v in levels:
        yield np.full((size[1], size[0], 3), v, np.uint8)


def smooth_equirect(w: int = 256, h: int = 128) -> np.ndarray:
    """A ``w x h`` equirect of low-frequency colour fields on the sphere (no seam, no pole
    singularity) with some detail along longitude: resampling error stays small, a wrong
    face or rotation shows."""
    from simulator.sphere.geometry import equirect_pixel_lonlat, lonlat_to_dir

    lon, lat = equirect_pixel_lonlat(w, h)
    d = lonlat_to_dir(lon[None, :], lat[:, None])
    chans = [d[..., 0] * 0.8 + d[..., 1] * 0.3, d[..., 2] * 0.9 - d[..., 0] * d[..., 1], d[..., 1]]
    return np.stack([np.clip(127.5 + 120 * c, 0, 255) for c in chans], -1).astype(np.uint8)


def cut_clip(first: Path, second: Path, out: Path, at_frame: int = 10) -> Path:
    """``first``'s frames before ``at_frame``, then ``second``'s from ``at_frame`` on: a hard
    cut (ffmpeg concat, H.264 crf 12)."""
    import subprocess

    from simulator.testing.reference import ffmpeg_exe

    graph = (f"[0:v]trim=end_frame={at_frame},setpts=PTS-STARTPTS[a];[1:v]trim=start_frame="
             f"{at_frame},setpts=PTS-STARTPTS[b];[a][b]concat=n=2:v=1[v]")  # fmt: skip
    subprocess.run([ffmpeg_exe(), "-loglevel", "error", "-y", "-i", str(first), "-i", str(second),
                    "-filter_complex", graph, "-map", "[v]", "-c:v", "libx264", "-crf", "12",
                    "-pix_fmt", "yuv420p", str(out)], check=True)  # fmt: skip
    return Path(out)


# -- Spherical Video V2 metadata (the initial orientation, sv3d prhd) ------------------

_PATH = (b"moov", b"trak", b"mdia", b"minf", b"stbl", b"stsd")


def _box(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", 8 + len(payload)) + kind + payload


def sv3d_box(yaw: float, pitch: float, roll: float, projection: str = "equi") -> bytes:
    """A Spherical Video V2 ``sv3d`` box (the pose in 16.16 fixed point): ``projection``
    ``equi`` (equirect) or ``cbmp`` (cubemap, layout 0 and padding 0: what YouTube and 360
    cameras write for EAC)."""
    pose = struct.pack(">iii", *(round(v * 65536) for v in (yaw, pitch, roll)))
    prhd = _box(b"prhd", b"\0\0\0\0" + pose)
    body = bytes(16) if projection == "equi" else bytes(8)  # equi: 4 bounds; cbmp: layout, pad
    proj = _box(projection.encode(), b"\0\0\0\0" + body)
    svhd = _box(b"svhd", b"\0\0\0\0" + b"vimsim test\0")
    return _box(b"sv3d", svhd + _box(b"proj", prhd + proj))


def _child(data: bytes, start: int, end: int, kind: bytes) -> int:
    """Offset of the first ``kind`` box in ``data[start:end]``."""
    while start < end:
        size, k = struct.unpack(">I4s", data[start : start + 8])
        if k == kind:
            return start
        start += size
    raise AssertionError(f"no {kind!r} box")


def with_pose(src, dst, yaw: float, pitch: float = 0.0, roll: float = 0.0, *,
              projection: str = "equi") -> None:
    """``dst`` = the MP4 ``src`` (moov after mdat, one video track) with an ``sv3d`` box
    appended to its sample entry; the sizes of the boxes holding it grow to match."""
    data = bytearray(Path(src).read_bytes())
    heads, start, end = [], 0, len(data)
    for kind in _PATH:
        off = _child(data, start, end, kind)
        heads.append(off)
        start, end = off + (16 if kind == b"stsd" else 8), off + struct.unpack(">I", data[off : off + 4])[0]
    assert _child(data, 0, len(data), b"mdat") < heads[0]  # chunk offsets stay valid
    entry = start  # the first sample entry (avc1)
    heads.append(entry)
    box = sv3d_box(yaw, pitch, roll, projection)
    at = entry + struct.unpack(">I", data[entry : entry + 4])[0]
    data[at:at] = box
    for off in heads:
        struct.pack_into(">I", data, off, struct.unpack(">I", data[off : off + 4])[0] + len(box))
    Path(dst).write_bytes(bytes(data))
