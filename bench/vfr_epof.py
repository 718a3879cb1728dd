"""Variable frame rate: EPOF on a clip with irregular timestamps against the analytic truth, frame by frame.

Usage: .venv/bin/python bench/vfr_epof.py [--seconds 3] [--size 512x256] [--supersample 8]

A synthetic rotation (the ``rotate`` scene of :mod:`simulator.synth`, analytic truth,
30 deg/s about the vertical) at 30 fps, encoded losslessly (x264 qp 0), has every third
frame dropped by ffmpeg with the
timestamps kept (0, 1/30, 3/30, 4/30, 6/30, ...: a 0.067 s gap after every second frame).
``preprocess_sphere`` of that clip, then the EPOF of a static head: every frame's EPOF
against the truth (the exact viewport mean of the analytic speed field). Anchor in the
same run: the same EPOF had speed used frame index / fps (what vimsim did before): frames
after a gap read twice the speed. The constant-rate clip (before dropping) is measured
in the same run as the reference for the flow estimator's own error. Goal: every VFR
frame within 2% of the truth. ``--paper``: paper mode too (its window POFs read low on
their borders, docs/sphere.md: a bias of its own, the same in both clips).

**The clip is rendered as a camera records it**: each pixel the mean of ``S x S``
samples (``--supersample S``, default 8: rendered at ``S`` times the size, then
``cv2.INTER_AREA``), because ``vimsim synth`` draws each pixel as one bicubic sample of
its panorama: a sub-pixel shift then changes the frame's sharpness with the shift's
fractional part, and the flow of such a clip swings by about +-5% from frame to frame
with that phase (at 512x256, 1.4 px a frame), in the constant-rate clip as much as in
the variable-rate one: an artefact of the synthetic clip, not of timing (no sensor
samples a point per pixel). ``--supersample 1`` measures that clip (docs/sources.md). **Lossless**, because x264's
B-frames (crf 12) are coded coarser than its P-frames and the flow of each frame pair
then alternates by +-1.5% (worst ~5%) with the frame types, again in both clips: the
same frames are also measured through x264 crf 12, printed apart (informational).
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from simulator.epof import compute_epof, viewport_epof
from simulator.media.gridfile import load_grid
from simulator.media.video import VideoWriter, probe
from simulator.preprocess import SphereConfig, preprocess_sphere
from simulator.preprocess.paper import preprocess_video
from simulator.sphere.geometry import lonlat_to_dir
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig
from simulator.synth.scenes import make_scene
from simulator.testing.reference import ffmpeg_exe
from simulator.traces.path import HeadPath

CELL = 4.0


def render_frames(seconds: float, size: tuple[int, int], ss: int):
    """The rotate scene's frames at 30 fps (RGB), each pixel the mean of ``ss x ss``
    samples, and the truth: the static head's EPOF (deg/s)."""
    w, h = size
    scene = make_scene(SynthConfig("rotate", seconds=seconds, fps=30.0, size=(w * ss, h * ss)))

    def frame(k: int) -> np.ndarray:
        f = scene.render(k / 30.0)
        return f if ss == 1 else cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA)

    with ThreadPoolExecutor(2) as pool:
        frames = list(pool.map(frame, range(round(seconds * 30.0))))
    lon = np.radians(-180.0 + CELL * (np.arange(round(360 / CELL)) + 0.5))
    lat = np.radians(90.0 - CELL * (np.arange(round(180 / CELL)) + 0.5))
    speed = scene.speed_dps(0.0, lonlat_to_dir(*np.meshgrid(lon, lat)))  # constant in time
    return frames, float(viewport_epof(speed[None], CELL, 0.0, 0.0, 0.0, hfov_deg=107.0)[0])


def clips(d: Path, frames, crf: int) -> tuple[Path, Path]:
    """The constant-rate clip (x264 ``crf``; 0 = lossless) and its variable-rate copy
    with every third frame dropped, timestamps kept (ffmpeg, the same ``crf``)."""
    cfr, vfr = d / f"cfr{crf}.mp4", d / f"vfr{crf}.mp4"
    with VideoWriter(cfr, 30.0, frames[0].shape[1::-1], crf=crf) as vw:
        for f in frames:
            vw.write(f)
    subprocess.run([ffmpeg_exe(), "-v", "error", "-y", "-i", str(cfr), "-vf",
                    "select='not(eq(mod(n\\,3)\\,2))'", "-fps_mode", "vfr", "-c:v", "libx264",
                    "-crf", str(crf), str(vfr)], check=True)  # fmt: skip
    return cfr, vfr


def measure(d: Path, label: str, cfr: Path, vfr: Path, true_epof: float, seconds: float,
            paper: bool = False):  # fmt: skip
    """Print the per-frame EPOF errors of both clips (sphere mode, or ``paper`` mode);
    returns ``(worst vfr, worst cfr, vfr result)``."""
    res, worst = {}, {}
    for name, path in (("cfr", cfr), ("vfr", vfr)):
        g = d / f"{path.stem}{'-paper' if paper else ''}.npz"
        if paper:
            preprocess_video(path, g, grid=grid_preset("default"), progress=None)
        else:
            preprocess_sphere(path, g, grid=grid_preset("default"),
                              config=SphereConfig(cell_deg=CELL), progress=False)  # fmt: skip
        hp = HeadPath.from_angles_deg([0.0, seconds + 1], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])
        r = compute_epof(load_grid(g), hp, hold=True, method="paper" if paper else "sphere")
        res[name] = r
        e = r.epof_dps[1:]  # row 0 repeats row 1
        rel = np.abs(e / true_epof - 1)
        k = int(np.argmax(rel)) + 1
        worst[name] = float(rel.max())
        print(f"{label} {name}: EPOF/truth per frame median {np.median(e) / true_epof:.4f}, "
              f"worst |rel err| {rel.max() * 100:.2f}% (frame {k}, t = {r.time_s[k]:.3f} s), "
              f"frames within 2%: {np.mean(rel <= 0.02) * 100:.0f}%")  # fmt: skip
    return worst["vfr"], worst["cfr"], res["vfr"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--size", default="512x256")
    ap.add_argument("--supersample", type=int, default=8)
    ap.add_argument("--paper", action="store_true", help="also paper mode (lossless clips)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    d = Path(tempfile.mkdtemp(prefix="vimsim-vfr-"))
    t0 = time.perf_counter()
    frames, true_epof = render_frames(a.seconds, (w, h), a.supersample)
    print(f"clip: {w}x{h}, each pixel the mean of {a.supersample}x{a.supersample} samples; "
          f"rendered in {time.perf_counter() - t0:.0f} s")  # fmt: skip
    print(f"truth: EPOF of the static head {true_epof:.3f} deg/s (analytic speed field)")
    lossless = clips(d, frames, 0)
    info = probe(lossless[1])
    print(f"VFR clip: {info.n_frames} frames, first times {np.round(info.times_s()[:7], 4)} s")
    worst, worst_cfr, r = measure(d, "x264 lossless", *lossless, true_epof, a.seconds)
    dt = np.diff(r.time_s)
    gap = dt > 0.05
    rel = np.abs(r.epof_dps[1:] / true_epof - 1)
    print(f"x264 lossless vfr: worst after a 0.067 s gap {rel[gap].max() * 100:.2f}%, after a "
          f"0.033 s interval {rel[~gap].max() * 100:.2f}%")  # fmt: skip
    naive = r.epof_dps[1:] * dt * 30.0  # speed as if every interval were 1/30 s
    reln = np.abs(naive / true_epof - 1)
    print(
        f"anchor, index/fps timing on the VFR clip: worst |rel err| {reln.max() * 100:.1f}% "
        f"(after each 0.067 s gap: {np.median(naive[gap]) / true_epof:.2f} x truth)"
    )
    print(
        f"goal (every VFR frame within 2% of truth): {'met' if worst <= 0.02 else 'NOT met'}; "
        f"worst VFR / worst CFR error {worst / worst_cfr:.2f}, timestamps / index "
        f"{worst / reln.max():.3f}"
    )
    if a.paper:  # paper mode: its own bias (docs/sphere.md), the same in both clips
        wp, cp, rp = measure(d, "paper mode, x264 lossless", *lossless, true_epof, a.seconds, True)
        ep, g = rp.epof_dps[1:] / true_epof, np.diff(rp.time_s) > 0.05
        print(f"paper mode vfr: median EPOF/truth after a gap {np.median(ep[g]):.4f}, after "
              f"a 0.033 s interval {np.median(ep[~g]):.4f}; worst VFR / worst CFR {wp / cp:.2f}")  # fmt: skip
    # The same frames through x264 at crf 12 (B-frames): the codec's share of the noise.
    w12, c12, _ = measure(d, "x264 crf 12", *clips(d, frames, 12), true_epof, a.seconds)
    print(f"x264 crf 12 (informational): worst VFR / worst CFR error {w12 / c12:.2f}")


if __name__ == "__main__":
    main()
