"""Agreement of our perspective views with ffmpeg's v360 on every real panorama.

Usage: .venv/bin/python bench/v360_agreement.py [--size 256] [--fov 90] [--interp lagrange]

Per panorama (each eye of stereo ones) x orientation: PSNR (dB, RGB) and the median
|local displacement| (px, phase correlation on 32x32 tiles, textured tiles only) between
``simulator.sphere.geometry.extract_view`` and ``v360=e:flat:...:interp=cubic``. For |yaw| > 30
deg v360 looks at yaw 0 of the panorama rolled by whole columns (v360 drifts with yaw;
the drift is measured and printed first). Rows whose view contains a pole are reported
separately (neither side prefilters; aliasing there makes PSNR content-dependent).
Goals: median PSNR >= 40 dB, median displacement <= 0.1 px.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from simulator.media import video
from simulator.sphere import geometry
from simulator.testing.reference import compare_with_v360, psnr, tile_displacement, v360_view

REAL = REPO.parent / "shared" / "data" / "real" / "equirect"
GOAL_PSNR_DB = 40.0
GOAL_DISP_PX = 0.1

#: (yaw, pitch, roll) in degrees: seam (+-180, 179), roll != 0, pitch +-80, mixed.
ORIENTATIONS_DEG = [
    (0, 0, 0), (15, 0, 0), (-20, 10, 0), (30, -15, 0), (45, 0, 0), (90, 0, 0),
    (-90, 20, 0), (135, -30, 0), (180, 0, 0), (-180, 0, 0), (179, 5, 0), (0, 0, 30),
    (0, 0, -45), (20, 15, 10), (-60, -20, -20), (120, 30, 60), (0, 45, 0), (0, -45, 0),
    (0, 80, 0), (0, -80, 0), (60, 80, 20), (-120, -80, -30),
]  # fmt: skip


def panoramas() -> list[tuple[str, np.ndarray]]:
    """(name, one eye's RGB equirect frame in stored pixels) for every real panorama."""
    out = []
    for rel in ("vrview/petra.jpg", "pannellum/examplepano.jpg", "threejs/equirectangular.png",
                "py360convert/example_input.png"):  # fmt: skip
        out.append((rel, video.read_frame(REAL / rel)))
    for eye in ("left", "right"):
        out.append((f"vrview/dolphins_stereo_tb.jpg[{eye}]",
                    video.read_frame(REAL / "vrview/dolphins_stereo_tb.jpg", layout="top-bottom", eye=eye)))  # fmt: skip
    for n in ("1", "6"):  # letterboxed 3840x2160: the equirect is rows 120..2039
        out.append(
            (
                f"avtrack360/{n}.jpg[rows 120:2040]",
                video.read_frame(REAL / f"avtrack360/{n}.jpg")[120:2040],
            )
        )
    # Anamorphic: stored 1920x1080, SAR 9:8. Both sides sample stored pixels (rawvideo to v360).
    out.append(("threejs/pano.mp4[frame 0]", video.read_frame(REAL / "threejs/pano.mp4", 0)))
    for eye in ("left", "right"):  # half side-by-side: each eye 960x1024 stored
        out.append((f"threejs/MaryOculus.mp4[frame 0, {eye}]",
                    video.read_frame(REAL / "threejs/MaryOculus.mp4", 0, layout="side-by-side", eye=eye)))  # fmt: skip
    return out


def sees_pole(yaw: float, pitch: float, roll: float, hfov: float, vfov: float) -> bool:
    """True when the view's frustum contains the north or south pole."""
    R = geometry.head_rotation(yaw, pitch, roll).as_matrix()
    for pole in ((0, 1, 0), (0, -1, 0)):
        x, y, z = R.T @ np.array(pole, float)  # pole in the head frame
        if (
            z > 0
            and abs(x / z) <= np.tan(np.radians(hfov / 2))
            and abs(y / z) <= np.tan(np.radians(vfov / 2))
        ):
            return True
    return False


def v360_yaw_drift(img: np.ndarray, size: tuple[int, int], fov: float) -> None:
    """v360 against itself: view at yaw Y vs view at yaw 0 of the panorama rolled by Y."""
    W = img.shape[1]
    print("v360 self-consistency (its view at yaw Y vs yaw 0 of the panorama rolled by Y):")
    for yaw in (15.0, 45.0, 90.0, 180.0):
        k = round(yaw / 360 * W)
        a = v360_view(img, k * 360 / W, 0, 0, hfov_deg=fov, size=size)
        b = v360_view(np.roll(img, -k, axis=1), 0, 0, 0, hfov_deg=fov, size=size)
        d = tile_displacement(b, a)
        print(
            f"  yaw {yaw:5.0f}: PSNR {psnr(a, b):5.1f} dB, median |disp| {np.median(np.hypot(*d.T)):.3f} px"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256, help="view width = height, px (default 256)")
    ap.add_argument("--fov", type=float, default=90.0, help="hfov = vfov, degrees (default 90)")
    ap.add_argument(
        "--interp",
        default="lagrange",
        choices=geometry.INTERPS,
        help="our kernel (default lagrange)",
    )
    ap.add_argument("--quick", action="store_true", help="first 2 panoramas only")
    a = ap.parse_args(argv)
    size = (a.size, a.size)
    t0 = time.perf_counter()
    pans = panoramas()[: 2 if a.quick else None]
    v360_yaw_drift(pans[0][1], size, a.fov)
    print(f"\nviews {a.size}x{a.size}, {a.fov:g} deg FOV, our kernel {a.interp}; v360 interp=cubic")
    print(
        f"{'panorama':44s} {'WxH':>9s} {'yaw':>5s} {'pitch':>5s} {'roll':>5s} {'PSNR dB':>8s} {'|d| px':>7s} {'tiles':>5s} pole"
    )
    rows = []
    for name, img in pans:
        H, W = img.shape[:2]
        for yaw, pitch, roll in ORIENTATIONS_DEG:
            r = compare_with_v360(img, yaw, pitch, roll, hfov_deg=a.fov, size=size, interp=a.interp)
            pole = sees_pole(yaw, pitch, roll, a.fov, a.fov)
            rows.append((name, r["psnr_db"], r["disp_px"], pole))
            print(f"{name:44s} {W:4d}x{H:<4d} {yaw:5.0f} {pitch:5.0f} {roll:5.0f} {r['psnr_db']:8.2f} "
                  f"{r['disp_px']:7.3f} {r['n_tiles']:5d} {'pole' if pole else ''}")  # fmt: skip
    print("\nper panorama (non-pole rows): median PSNR dB, median |d| px")
    for name, _ in pans:
        sel = [r for r in rows if r[0] == name and not r[3]]
        print(
            f"  {name:44s} {np.median([r[1] for r in sel]):6.2f} {np.nanmedian([r[2] for r in sel]):6.3f}"
        )
    for label, sel in (("non-pole rows", [r for r in rows if not r[3]]), ("pole rows", [r for r in rows if r[3]]),
                       ("all rows", rows)):  # fmt: skip
        p = np.median([r[1] for r in sel])
        d = np.nanmedian([r[2] for r in sel])
        print(f"{label:14s} n={len(sel):3d}: median PSNR {p:6.2f} dB (goal >= {GOAL_PSNR_DB:g}: "
              f"{'met' if p >= GOAL_PSNR_DB else 'NOT met'}, ratio {p / GOAL_PSNR_DB:.3f}); "
              f"median |d| {d:.3f} px (goal <= {GOAL_DISP_PX:g}: {'met' if d <= GOAL_DISP_PX else 'NOT met'}, "
              f"ratio {d / GOAL_DISP_PX:.2f})")  # fmt: skip
    print(f"[{time.perf_counter() - t0:.0f} s]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
