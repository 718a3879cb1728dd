"""References nobody here wrote, shared by the tests and the benches: ffmpeg's v360 filter and brute-force overlaps.

``v360_*``: ffmpeg's ``v360`` filter (the project's outside reference) on numpy frames.
The ffmpeg binary is the one shipped by the ``imageio-ffmpeg`` package. Frames go in and
come out as raw RGB through pipes (no files, no codec): ``format=gbrp`` keeps v360 in
RGB, so the only differences from our views are v360's geometry and interpolation.

v360's conventions, read from ``libavfilter/vf_v360.c`` and checked by bench/v360_agreement.py
-------------------------------------------------------------------------------------
- Flat (perspective) output: pixel ``(i, j)`` has its centre at ``(2i + 1) / w - 1`` times
  ``tan(h_fov / 2)`` (same as ours).
- Equirect input: ``uf = (lon / pi + 1) * W / 2`` is used directly as an array index
  (taps ``floor(uf) - 1 .. floor(uf) + 2``), i.e. v360 puts pixel ``k``'s centre at
  ``lon = k / W * 360 - 180``, half a pixel left of (and above) SPEC.md's centre rule.
  Our maps + 0.5 (array-index convention) reproduce v360's sampling positions.
- ``interp=cubic`` is the 4-point Lagrange cubic (not Keys/OpenCV a = -0.75), weights
  ``lrintf(cx * cy * 16385)``, sum shifted right by 14 (floor), clipped.
- Beyond a pole, rows reflect without repeating the edge row (``-y``; SPEC's continuation
  repeats it: row -1 is row 0 on the opposite meridian).
"""

from __future__ import annotations

import functools
import os
import subprocess
import tempfile
import time

import cv2
import imageio_ffmpeg
import numpy as np

from simulator.sphere.geometry import extract_view
from simulator.sphere.windows import WindowGrid

__all__ = [
    "brute_overlaps",
    "compare_with_v360",
    "ffmpeg_exe",
    "psnr",
    "tile_displacement",
    "v360_convert",
    "v360_filter",
    "v360_time_ms",
    "v360_view",
]


@functools.lru_cache(maxsize=1)
def ffmpeg_exe() -> str:
    return imageio_ffmpeg.get_ffmpeg_exe()


def v360_filter(yaw_deg, pitch_deg, roll_deg, hfov_deg, vfov_deg, size, interp="cubic") -> str:
    """The ``-vf`` string: equirect in, flat out, RGB planar throughout."""
    w, h = size
    return (
        f"format=gbrp,v360=e:flat:h_fov={hfov_deg:.10g}:v_fov={vfov_deg:.10g}:w={w}:h={h}"
        f":yaw={yaw_deg:.10g}:pitch={pitch_deg:.10g}:roll={roll_deg:.10g}:interp={interp}"
    )


def v360_view(
    img: np.ndarray,
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    *,
    hfov_deg: float = 90.0,
    vfov_deg: float | None = None,
    size: tuple[int, int] = (256, 256),
    interp: str = "cubic",
) -> np.ndarray:
    """ffmpeg v360's perspective view of an ``(H, W, 3)`` uint8 RGB equirect frame.

    Same argument meaning as :func:`simulator.sphere.geometry.extract_view` (degrees, yaw +
    right, pitch + up, roll + right ear down, ``size = (width, height)``); the values are
    passed to v360 as they are (v360's signs agree with SPEC.md). Returns
    ``(height, width, 3)`` uint8.
    """
    vfov_deg = hfov_deg if vfov_deg is None else vfov_deg
    img = np.ascontiguousarray(img)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    H, W = img.shape[:2]
    cmd = [
        ffmpeg_exe(),
        "-v",
        "error",
        "-hide_banner",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-s",
        f"{W}x{H}",
        "-i",
        "-",
        "-vf",
        v360_filter(yaw_deg, pitch_deg, roll_deg, hfov_deg, vfov_deg, size, interp),
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-",
    ]
    r = subprocess.run(cmd, input=img.tobytes(), capture_output=True, check=False)
    if r.returncode != 0:
        raise RuntimeError(f"ffmpeg v360 failed: {r.stderr.decode(errors='replace').strip()}")
    w, h = size
    out = np.frombuffer(r.stdout, np.uint8)
    if out.size != w * h * 3:
        raise RuntimeError(f"ffmpeg v360 returned {out.size} bytes; expected {w * h * 3}")
    return out.reshape(h, w, 3)


def v360_convert(img: np.ndarray, output: str, size: tuple[int, int], options: str = "") -> np.ndarray:
    """ffmpeg v360's conversion of an ``(H, W, 3)`` uint8 RGB equirect frame to projection
    ``output`` (v360's name: ``eac``, ``c3x2``, ``c6x1``, ``dfisheye``, ``hequirect``, ...)
    of ``size = (width, height)``; ``options``: extra ``:key=value`` v360 options (e.g.
    ``":h_fov=190:v_fov=190"`` for a dual fisheye's lens). Bicubic (v360's Lagrange)."""
    img = np.ascontiguousarray(img)
    H, W = img.shape[:2]
    w, h = size
    vf = f"format=gbrp,v360=e:{output}:w={w}:h={h}:interp=cubic{options}"
    cmd = [ffmpeg_exe(), "-v", "error", "-hide_banner", "-f", "rawvideo", "-pix_fmt", "rgb24",
           "-s", f"{W}x{H}", "-i", "-", "-vf", vf, "-f", "rawvideo", "-pix_fmt", "rgb24", "-"]  # fmt: skip
    r = subprocess.run(cmd, input=img.tobytes(), capture_output=True, check=False)
    if r.returncode != 0:
        raise RuntimeError(f"ffmpeg v360 failed: {r.stderr.decode(errors='replace').strip()}")
    out = np.frombuffer(r.stdout, np.uint8)
    if out.size != w * h * 3:
        raise RuntimeError(f"ffmpeg v360 returned {out.size} bytes; expected {w * h * 3}")
    return out.reshape(h, w, 3)


def v360_time_ms(
    img: np.ndarray, *, size: tuple[int, int], hfov_deg: float = 107.0, vfov_deg=None, n: int = 40
) -> float:
    """Time per frame of v360 (ms), without process start-up and decoding.

    Runs ffmpeg twice on ``n`` copies of the frame from a raw file: once with the v360
    filter, once with the same pipeline minus v360 (``format=gbrp`` only), and returns
    ``(t_with - t_without) / n`` of the wall-clock times. Threads: ffmpeg's default
    (``-filter_threads`` = cores).
    """

    vfov_deg = hfov_deg if vfov_deg is None else vfov_deg
    H, W = img.shape[:2]
    with tempfile.TemporaryDirectory() as d:
        raw = os.path.join(d, "in.rgb")
        with open(raw, "wb") as f:
            f.write(np.ascontiguousarray(img).tobytes() * n)

        def run(vf: str) -> float:
            cmd = [
                ffmpeg_exe(),
                "-v",
                "error",
                "-f",
                "rawvideo",
                "-pix_fmt",
                "rgb24",
                "-s",
                f"{W}x{H}",
                "-i",
                raw,
                "-vf",
                vf,
                "-f",
                "null",
                "-",
            ]
            best = float("inf")
            for _ in range(3):
                t0 = time.perf_counter()
                subprocess.run(cmd, check=True, capture_output=True)
                best = min(best, time.perf_counter() - t0)
            return best

        t_with = run(v360_filter(30.0, 10.0, 0.0, hfov_deg, vfov_deg, size))
        t_without = run("format=gbrp")
    return (t_with - t_without) / n * 1e3


# ------------------------------------------------------------------------------ measures
def psnr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR in dB of two uint8 images (all pixels and channels; inf when identical)."""
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * np.log10(255.0**2 / mse)


def tile_displacement(
    a: np.ndarray, b: np.ndarray, *, tile: int = 32, min_std: float = 4.0
) -> np.ndarray:
    """Local displacement (px) of ``b`` relative to ``a`` by phase correlation on
    ``tile x tile`` tiles (Hann window, OpenCV ``phaseCorrelate``) of the gray images.

    Tiles with a gray-level standard deviation below ``min_std`` (flat sky, black bars:
    no texture to correlate) are skipped. Returns ``(n, 2)`` ``(dx, dy)`` per tile.
    """

    def gray(x):
        return (cv2.cvtColor(x, cv2.COLOR_RGB2GRAY) if x.ndim == 3 else x).astype(np.float32)

    ga, gb = gray(a), gray(b)
    win = cv2.createHanningWindow((tile, tile), cv2.CV_32F)
    out = []
    for r in range(0, ga.shape[0] - tile + 1, tile):
        for c in range(0, ga.shape[1] - tile + 1, tile):
            ta, tb = ga[r : r + tile, c : c + tile], gb[r : r + tile, c : c + tile]
            if ta.std() < min_std or tb.std() < min_std:
                continue
            (dx, dy), _ = cv2.phaseCorrelate(ta, tb, win)
            out.append((dx, dy))
    return np.array(out, float).reshape(-1, 2)


def compare_with_v360(
    img: np.ndarray,
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float = 0.0,
    *,
    hfov_deg: float = 90.0,
    size: tuple[int, int] = (256, 256),
    interp: str = "lagrange",
    roll_beyond_deg: float = 30.0,
) -> dict:
    """Our view and v360's of one orientation: PSNR (dB) and median tile displacement (px).

    For ``|yaw| > roll_beyond_deg`` v360 drifts with yaw (a quirk of the reference,
    measured in bench/v360_agreement.py), so the panorama is rolled by a whole number of
    columns ``k = round(yaw / 360 * W)`` and v360 looks at yaw 0 while we look at the
    exact yaw ``k * 360 / W`` of the unrolled panorama (the same view on the sphere).
    """
    W = img.shape[1]
    ref_img, ref_yaw, our_yaw = img, yaw_deg, yaw_deg
    if abs(yaw_deg) > roll_beyond_deg:
        k = round(yaw_deg / 360.0 * W)
        ref_img, ref_yaw, our_yaw = np.roll(img, -k, axis=1), 0.0, k * 360.0 / W
    ref = v360_view(ref_img, ref_yaw, pitch_deg, roll_deg, hfov_deg=hfov_deg, size=size)
    ours = extract_view(
        img, our_yaw, pitch_deg, roll_deg, hfov_deg=hfov_deg, size=size, interp=interp
    )
    d = tile_displacement(ours, ref)
    mag = np.hypot(d[:, 0], d[:, 1]) if len(d) else np.array([np.nan])
    return {
        "psnr_db": psnr(ours, ref),
        "disp_px": float(np.median(mag)),
        "n_tiles": len(d),
        "ours": ours,
        "ref": ref,
    }


# ------------------------------------------------- brute-force viewport overlaps
def _R(yaw, pitch, roll):
    """head->world matrix written out by hand: Ry(yaw) Rx(-pitch) Rz(-roll), radians."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cx, sx = np.cos(-pitch), np.sin(-pitch)
    cz, sz = np.cos(-roll), np.sin(-roll)
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return ry @ rx @ rz


def brute_overlaps(grid: WindowGrid, yaw, pitch, roll, hfov, vfov, n=256):
    """Overlap fractions (P, Y) by n x n rays of the viewport and a membership test of
    each ray in each window (rays projected into the window's frame)."""
    tx, ty = np.tan(np.radians(hfov) / 2), np.tan(np.radians(vfov) / 2)
    u = ((np.arange(n) + 0.5) / n * 2 - 1) * tx
    v = (1 - (np.arange(n) + 0.5) / n * 2) * ty
    uu, vv = np.meshgrid(u, v)
    r = np.sqrt(1 + uu**2 + vv**2)
    d = np.stack([uu / r, vv / r, 1 / r], -1).reshape(-1, 3)
    sa = (1 / r**3).ravel()
    w = (d @ _R(*np.radians([yaw, pitch, roll])).T).astype(np.float32)
    fwd = _R(*np.radians([yaw, pitch, roll]))[:, 2]
    # Circumradius of a perspective rectangle; farther centres cannot overlap (exact skip).
    rad_v = np.arctan(np.hypot(tx, ty))
    rad_w = np.arctan(
        np.hypot(np.tan(np.radians(grid.hfov_deg) / 2), np.tan(np.radians(grid.vfov_deg) / 2))
    )
    wx, wy = np.tan(np.radians(grid.hfov_deg) / 2), np.tan(np.radians(grid.vfov_deg) / 2)
    out = np.zeros(grid.shape)
    near, mats = [], []
    for i, wp in enumerate(grid.pitch_deg):
        for j, wy_ in enumerate(grid.yaw_deg):
            rw = _R(np.radians(wy_), np.radians(wp), 0.0)
            if np.arccos(np.clip(rw[:, 2] @ fwd, -1, 1)) <= rad_v + rad_w:
                near.append((i, j))
                mats.append(rw)
    m = np.concatenate(mats, axis=1).astype(np.float32)  # (3, 3W)
    acc = np.zeros(len(near))
    for s in range(0, len(w), 8192):
        q = (w[s : s + 8192] @ m).reshape(-1, len(near), 3)  # window-frame coordinates
        z = q[..., 2]
        ins = (z > 0) & (np.abs(q[..., 0]) <= wx * z) & (np.abs(q[..., 1]) <= wy * z)
        acc += sa[s : s + 8192] @ ins
    for (i, j), v in zip(near, acc):
        out[i, j] = v / sa.sum()
    return out
