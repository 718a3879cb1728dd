"""Flow and cost of every input projection against the same content as equirect.

Usage: .venv/bin/python bench/projection_flow.py [--seconds 2] [--size 1024x512] [--no-render]

A synthetic rotating clip (``vimsim synth --scene rotate``, equirect) is converted by
ffmpeg's ``v360`` to each projection (eac, c3x2, c6x1, dfisheye at a 190 deg lens,
hequirect = VR180's one eye) and re-encoded as equirect with the same encoder settings
(x264 crf 10: the reference decodes at the same cost per bit as the projections);
``vimsim preprocess --method sphere`` of each against that of the equirect clip, in the
same run:

- flow: the sphere-mode field of each projection vs the equirect field, per covered cell
  and frame: median relative difference (goal <= 3%), and the same for the window matrix;
- cost: preprocess wall time of each projection / the equirect's (goal <= 1.3x), and
  ``vimsim render`` (480x480 eyes, GRF at opacity 0.5) wall time likewise; also the
  ratios of CPU time (all threads), steadier on a shared machine. Render samples each
  projection as stored in the eye shader; what is left of its ratio is decoding the
  projection's larger file, so the CPU-time ratio of decoding alone (RGB, as render
  decodes, frames as stored) is printed beside it. Every timed preprocess builds its own
  source-dependent setup (tile geometry, projection maps: their caches are cleared first,
  as in a fresh ``vimsim`` process), the equirect reference's too; what depends only on
  the window grid stays warm for all.
"""

from __future__ import annotations

import os

# OpenBLAS threads as the vimsim command sets them (simulator.cli.BLAS_THREADS), before numpy loads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from simulator.media.coverage import coverage_masks
from simulator.media.gridfile import load_grid
from simulator.media.source import Source
from simulator.mitigation.grf import GrfConfig
from simulator.preprocess import SphereConfig, preprocess_sphere
from simulator.preprocess.sphere import _tile_geometry
from simulator.preprocess.tiles import _projection_tiles
from simulator.render import RenderConfig
from simulator.sphere.windows import grid_preset
from simulator.synth import SynthConfig, synthesize
from simulator.testing.reference import ffmpeg_exe
from simulator.traces.path import synth as synth_path
from simulator.viewing.job import render_viewing

LENS = 190.0


def _cases(w: int, h: int):
    f = h // 2  # cube face: 90 deg at the equirect's density
    return [
        ("eac", (3 * f, 2 * f), ""),
        ("c3x2", (3 * f, 2 * f), ""),
        ("c6x1", (6 * f, f), ""),
        ("dfisheye", (2 * h, h), f":h_fov={LENS:g}:v_fov={LENS:g}"),
        ("hequirect", (h, h), ""),
    ]


def _convert(src: Path, out: Path, name: str, size, opts: str) -> None:
    vf = "null" if name == "e" else f"v360=e:{name}:w={size[0]}:h={size[1]}:interp=cubic{opts}"
    cmd = [ffmpeg_exe(), "-v", "error", "-y", "-i", str(src), "-vf", vf, "-c:v", "libx264",
           "-crf", "10", "-preset", "veryfast", str(out)]  # fmt: skip
    subprocess.run(cmd, check=True)


def _timed(fn) -> tuple[float, float]:
    """(wall seconds, CPU seconds of this process, all threads)."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--size", default="1024x512")
    ap.add_argument("--no-render", action="store_true")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    d = Path(tempfile.mkdtemp(prefix="vimsim-proj-"))
    syn, _ = synthesize(SynthConfig("rotate", seconds=a.seconds, fps=30.0, size=(w, h)), d / "s.mp4")
    eq = d / "e.mp4"  # the reference: encoded as the projections are (same decode cost per bit)
    _convert(syn, eq, "e", (w, h), "")
    grid = grid_preset("default")
    cfg = SphereConfig(cell_deg=4.0)
    hp = synth_path("look-around", a.seconds + 0.5, rate_hz=60.0, seed=1)
    rcfg = RenderConfig(eye_size=(480, 480), grf=GrfConfig(seed=0))

    def run(name, path, lens=None):
        src = Source.open(path, projection=name, lens_fov_deg=lens)
        g = d / f"{name}.npz"
        _tile_geometry.cache_clear()  # each source pays its own setup, the reference too
        _projection_tiles.cache_clear()
        t_pre = _timed(lambda: preprocess_sphere(src, g, grid=grid, config=cfg, progress=False))
        t_ren = None
        if not a.no_render:
            t_ren = _timed(lambda: render_viewing(src, hp, d / f"r_{name}", config=rcfg,
                                                  opacity=0.5, x264_preset="ultrafast", audio=False,
                                                  progress=False))  # fmt: skip
            t_ren += _timed(lambda: sum(1 for _ in src.frames(convert=False)))  # decode alone
        return load_grid(g), t_pre, t_ren

    run("equirect", eq)  # warm-up: imports, GL context, caches
    ref, t_pre0, t_ren0 = run("equirect", eq)
    f0 = np.asarray(ref.field_dps[:], float)[1:]
    p0 = np.asarray(ref.pof_dps, float)[1:]
    print(f"equirect {w}x{h}, {f0.shape[0] + 1} frames: preprocess {t_pre0[0]:.2f} s wall, "
          f"{t_pre0[1]:.2f} s CPU" + ("" if t_ren0 is None else
          f"; render {t_ren0[0]:.2f} s wall, {t_ren0[1]:.2f} s CPU"))  # fmt: skip
    print("projection  stored      field med |rel diff|  windows med |rel diff|  "
          "preprocess ratio wall / CPU  render ratio wall / CPU  (decode alone, CPU)")  # fmt: skip
    for name, size, opts in _cases(w, h):
        path = d / f"{name}.mp4"
        _convert(syn, path, name, size, opts)
        g, t_pre, t_ren = run(name, path, LENS if name == "dfisheye" else None)
        f = np.asarray(g.field_dps[:], float)[1:]
        wins, cells = coverage_masks(g.meta)
        cm = np.ones(f.shape[1:], bool) if cells is None else cells
        ok = cm[None] & (f0 > 1.0)  # covered cells with motion
        rel = np.abs(f[np.broadcast_to(ok, f.shape)] / f0[np.broadcast_to(ok, f.shape)] - 1)
        wm = np.ones(p0.shape[1:], bool) if wins is None else wins
        pw = np.asarray(g.pof_dps, float)[1:][:, wm]
        relw = np.abs(pw / p0[:, wm] - 1)
        rr = "" if t_ren is None else (f"{t_ren[0] / t_ren0[0]:5.2f}x / {t_ren[1] / t_ren0[1]:5.2f}x"
                                       f"    ({t_ren[3] / t_ren0[3]:5.2f}x)")  # fmt: skip
        print(f"{name:10s}  {size[0]}x{size[1]:<5d}  {np.median(rel) * 100:6.2f}%"
              f"               {np.median(relw) * 100:6.2f}%                "
              f"{t_pre[0] / t_pre0[0]:5.2f}x / {t_pre[1] / t_pre0[1]:5.2f}x     {rr}")  # fmt: skip


if __name__ == "__main__":
    main()
