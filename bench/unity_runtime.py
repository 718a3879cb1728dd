"""Load time and memory of the exported C# runtime (Mono) for a 2-minute export, both modes, before and after format 3 (the grain layout and settings in the file, asynchronous load, float16 sphere field).

"Before": the runtime and exporter of commit ``BASE`` (format version 2: sphere mode summed the
whole field into double running sums at load, ~117 MB for 2 minutes at 30 fps; paper mode built
its overlap table on the calling thread). "After": this checkout (format 3: the float16 field
kept as stored and one frame's sums made when it is queried; ``LoadAsync`` builds on a worker
thread, the caller is blocked only while the task starts). Data: synthetic 2-minute grids (3600
frames at 30 fps; paper mode 11 x 24 windows, sphere mode 4 deg cells, float16), the same for
both. Each figure is the median of 3 fresh Mono processes; memory is the managed heap after the
load (``GC.GetTotalMemory(true)``) minus before it. Printed as ratios after / before (the anchor,
measured in the same run), plus the sphere-mode MB per minute of video of both.

    .venv/bin/python bench/unity_runtime.py
"""

from __future__ import annotations

import importlib.util
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from simulator.export import export_unity
from simulator.media.gridfile import save_grid
from simulator.preprocess import SphereConfig, field_meta
from simulator.sphere.windows import grid_preset

REPO = Path(__file__).resolve().parents[1]
BASE = "e8a4aea"  # the last commit with format version 2
FPS, T = 30.0, 3600  # 2 minutes
RUNS = 3

BENCH_CS = r"""
using System;
using System.Diagnostics;
using Vimsim;
static class B {
    static int Main(string[] a) {
        GC.Collect(); GC.WaitForPendingFinalizers(); GC.Collect();
        long m0 = GC.GetTotalMemory(true);
        var sw = Stopwatch.StartNew();
#if NEW
        var task = VimsimEpof.LoadAsync(a[0]);
        double blocked = sw.Elapsed.TotalMilliseconds;
        var e = task.Result;
#else
        var e = VimsimEpof.Load(a[0]);
        double blocked = sw.Elapsed.TotalMilliseconds;
#endif
        double ready = sw.Elapsed.TotalMilliseconds;
        float s = 0;
        for (int i = 0; i < 200; i++) s += e.Epof((i * 17 % 3600) / e.Fps, i % 360 - 180, 10, 0);
        long m1 = GC.GetTotalMemory(true);
        Console.WriteLine(blocked.ToString("R") + " " + ready.ToString("R") + " " + (m1 - m0) + " " + s);
        GC.KeepAlive(e);
        return 0;
    }
}
"""


def _grids(d: Path) -> dict[str, Path]:
    g = grid_preset("default")
    rng = np.random.default_rng(0)
    meta = {"fps": FPS, "n_frames": T, "flow": {"method": "bench"}, "layout": "mono", "eye": "left",
            "video": {"path": "v.mp4", "content_hash": "sha256:bench", "n_frames": T}}  # fmt: skip
    pof = (20 + 20 * rng.random((T, *g.shape))).astype(np.float32)
    save_grid(d / "paper.npz", pof, pof / 10, g, meta)
    field = (20 + 20 * rng.random((T, 45, 90))).astype(np.float16)
    save_grid(d / "sphere.npz", pof, pof / 10, g,
              {**meta, "method": "sphere", "field": field_meta(SphereConfig())}, field_dps=field)  # fmt: skip
    return {"paper": d / "paper.npz", "sphere": d / "sphere.npz"}


def _old_exporter(d: Path):
    """The exporter module of BASE, imported from its source."""
    src = subprocess.run(["git", "-C", str(REPO), "show", f"{BASE}:simulator/export/unity.py"],
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    (d / "old_unity.py").write_text(src)
    spec = importlib.util.spec_from_file_location("old_unity", d / "old_unity.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["old_unity"] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


def _compile(d: Path, name: str, cs: Path, new: bool) -> Path:
    (d / "bench.cs").write_text(BENCH_CS)
    exe = d / f"{name}.exe"
    args = ["mcs", "-optimize+", f"-out:{exe}", str(cs), str(d / "bench.cs")]
    subprocess.run(args + (["-d:NEW"] if new else []), check=True, capture_output=True)
    return exe


def _measure(exe: Path, export: Path) -> tuple[float, float, float]:
    """Medians of (blocked ms, ready ms, managed MB) over RUNS fresh processes."""
    rows = []
    for _ in range(RUNS):
        out = subprocess.run(["mono", str(exe), str(export)], capture_output=True, text=True, check=True)
        b, r, m, _s = out.stdout.split()
        rows.append((float(b), float(r), int(m) / 1e6))
    return tuple(statistics.median(c) for c in zip(*rows))


def main() -> int:
    if shutil.which("mcs") is None or shutil.which("mono") is None:
        print("needs Mono (mcs, mono): make sysdeps", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        grids = _grids(d)
        old_cs = d / "VimsimEpof_old.cs"
        old_cs.write_text(subprocess.run(
            ["git", "-C", str(REPO), "show", f"{BASE}:simulator/export/unity/VimsimEpof.cs"],
            capture_output=True, text=True, check=True).stdout)  # fmt: skip
        old_exe = _compile(d, "old", old_cs, new=False)
        new_exe = _compile(d, "new", REPO / "simulator" / "export" / "unity" / "VimsimEpof.cs", new=True)
        old_mod = _old_exporter(d)
        print(f"C# runtime load, 2-minute export ({T} frames at {FPS:g} fps), Mono, median of {RUNS} runs")
        print(f"{'mode':7s} {'':7s} {'main thread blocked':>20s} {'ready':>10s} {'managed heap':>13s}")
        for mode, grid in grids.items():
            old_x, new_x = d / f"old_{mode}", d / f"new_{mode}"
            old_mod.export_unity(grid, old_x, method=mode)
            export_unity(grid, new_x, method=mode)
            before, after = _measure(old_exe, old_x), _measure(new_exe, new_x)
            for name, (b, r, m) in (("before", before), ("after", after)):
                print(f"{mode:7s} {name:7s} {b:17.1f} ms {r:7.1f} ms {m:10.1f} MB")
            print(f"{mode:7s} ratio after / before: blocked {after[0] / before[0]:.3f}, ready "
                  f"{after[1] / before[1]:.2f}, memory {after[2] / before[2]:.3f}")  # fmt: skip
            if mode == "sphere":
                minutes = T / FPS / 60
                print(f"sphere  MB per minute of video (4 deg cells, 30 fps): before {before[2] / minutes:.1f}, "
                      f"after {after[2] / minutes:.1f}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
