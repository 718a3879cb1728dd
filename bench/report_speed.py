"""The study report on the 48-user study of bench/study_48users.py, and the web runtime in headless Chromium.

Figures (each against a reference measured in the same run):
* report build time / the time of the plots and tables the study already makes
  (``simulator.study.outputs.write_study_outputs`` rerun here); goal <= 1.5x. The first
  build makes the browser copy of the video (a stream copy here), a rebuild reuses it;
* JS EPOF per call in headless Chromium (paper and sphere mode, 2000 random poses: the
  first pass fills the sphere-mode weight cache, the figure is the mean over repeated
  passes) / Python's one-query path; goals <= 50 us paper, <= 100 us sphere;
* replay frame rate at 1280x720 in headless Chromium (SwiftShader; upload of the current
  video frame + draw + a 1-pixel read to wait for the GPU) / the video's frame rate.

Run: .venv/bin/python bench/report_speed.py   (needs Debian's chromium and chromium-driver)
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _pano import loop_study  # bench/_pano.py: the looped clip and its 48-user manifest

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "_out" / "report_48users"
VIMSIM = str(Path(sys.executable).with_name("vimsim"))


def _study() -> Path:
    manifest = loop_study(OUT)
    out = OUT / "study"
    if not (out / "study.json").is_file():
        subprocess.run([VIMSIM, "study", str(manifest), "-o", str(out), "--cache-dir",
                        str(OUT / "cache"), "--no-progress", "--no-report"], check=True)  # fmt: skip
    return out


def plots_seconds(out: Path, manifest: Path | None = None) -> float:
    """The study's plots and tables (``write_study_outputs``) made again, timed (seconds)."""
    from simulator.study import load_manifest
    from simulator.study.outputs import write_study_outputs

    s = json.loads((out / "study.json").read_text())
    m = load_manifest(manifest or OUT / "study.toml")
    with open(out / "viewings.csv", newline="") as f:
        table = list(csv.DictReader(f))
    grids = {v: Path(d["grid"]) for v, d in s["videos"].items()}
    t0 = time.perf_counter()
    write_study_outputs(m, out, grids, table)
    return time.perf_counter() - t0


_JS = """
const [poses, path, base] = args;
const m = await import(base + 'assets/vimsim.js');
const out = {};
const per = (rt, qs) => { let s = 0; const t0 = performance.now();
  for (const q of qs) s += rt.epof(q[0], q[1], q[2], q[3]);
  return (performance.now() - t0) * 1000 / qs.length; };
for (const mode of ['paper', 'sphere']) {
  const rt = await m.loadExport(base + 'bench-' + mode + '/');
  const cold = per(rt, poses);
  let n = 0, s = 0; const t1 = performance.now();
  while (performance.now() - t1 < 500) { for (const q of poses) { s += rt.epof(q[0], q[1], q[2], q[3]); n++; } }
  const rt2 = await m.loadExport(base + 'bench-' + mode + '/');  // a fresh cache
  out[mode] = {cold, warm: (performance.now() - t1) * 1000 / n, path: per(rt2, path)};
}
return out;
"""


def _browser_figures(out: Path, rng) -> dict:
    from simulator.export.web import export_web
    from simulator.mitigation.grf import comfort_rule
    from simulator.report.serve import start_server
    from tests.browser_support import Browser

    s = json.loads((out / "study.json").read_text())
    grid = Path(next(iter(s["videos"].values()))["grid"])
    report = out / "report"
    for mode in ("paper", "sphere"):  # beside the report (served with it), removed after
        export_web(grid, report / f"bench-{mode}", method=mode, rule=comfort_rule(), example=False)
    n = 2000
    poses = np.column_stack([rng.uniform(0, 160, n), rng.uniform(-180, 180, n),
                             rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)])  # fmt: skip
    ep = min((out / "epof").glob("*.csv"))
    rows = [ln.split(",") for ln in ep.read_text().splitlines() if ln and ln[0] != "#"][1:]
    path = [[float(r[1]), float(r[2]), float(r[3]), float(r[4])] for r in rows]
    srv = start_server(report)
    b = Browser()
    try:
        b.get(srv.url + "index.html")
        epof = b.run_async(_JS, poses.tolist(), path, srv.url)
        epof["cpu"] = _cpu_per_call(b, poses.tolist(), srv.url)
        page = next(p.name for p in sorted(report.glob("viewing-*.html")))
        b.get(srv.url + page + "?size=1280x720")
        fps = b.run_async("""
            for (let i = 0; i < 1200 && !(window.vimsimReplay && window.vimsimReplay.ready); i++)
              await new Promise((r) => setTimeout(r, 50));
            if (!window.vimsimReplay) return null;
            await window.vimsimReplay.seek(30.0);
            window.vimsimReplay.measure(3);
            return [window.vimsimReplay.measure(30), window.vimsimReplay.measure(30, false),
                    window.vimsimReplay.canvas.toDataURL('image/png')];""")
        console, _ = b.drain()
        if fps:
            import base64
            import io

            from PIL import Image

            png = Image.open(io.BytesIO(base64.b64decode(fps.pop().split(",", 1)[1])))
            level = float(np.asarray(png.convert("L")).mean())
            if level < 5 or console:  # a black view or a WebGL complaint: not a measurement
                raise SystemExit(
                    f"replay drew nothing (mean level {level:.1f}) or complained: {console}"
                )
        renderer = b.gl_renderer()
    finally:
        b.close()
        srv.close()
        import shutil

        for mode in ("paper", "sphere"):
            shutil.rmtree(report / f"bench-{mode}", ignore_errors=True)
    return {"epof": epof, "fps": fps, "renderer": renderer, "path_frames": len(path)}


def _cpu_per_call(b, poses: list, base: str) -> dict:
    """CPU microseconds per call of the renderer process (DevTools Performance.getMetrics
    ProcessTime), random poses, cold weight cache each pass (2000 poses > 1024 bins):
    the machine's load does not inflate it as it does the wall time."""
    b.driver.execute_cdp_cmd("Performance.enable", {})

    def cpu() -> float:
        m = b.driver.execute_cdp_cmd("Performance.getMetrics", {})["metrics"]
        return next(x["value"] for x in m if x["name"] == "ProcessTime")

    out = {}
    for mode in ("paper", "sphere"):
        b.run_async(
            "const m = await import(args[0] + 'assets/vimsim.js');"
            "window.__rt = await m.loadExport(args[0] + 'bench-' + args[1] + '/');",
            base,
            mode,
        )
        b.driver.execute_script(
            "let s = 0; for (const q of arguments[0]) s += window.__rt.epof(...q);", poses
        )
        c0 = cpu()
        b.driver.execute_script(
            "let s = 0; for (let r = 0; r < 3; r++) for (const q of arguments[0]) s += window.__rt.epof(...q);",
            poses,
        )
        out[mode] = (cpu() - c0) * 1e6 / (3 * len(poses))
    return out


def _python_per_call(out: Path, rng) -> dict:
    from simulator.epof.exact import shared_query
    from simulator.epof.overlaps import viewport_fov, viewport_overlaps
    from simulator.media.gridfile import load_grid, require_field
    from simulator.sphere.cells import Frustum
    from simulator.sphere.windows import WindowGrid

    s = json.loads((out / "study.json").read_text())
    g = load_grid(next(iter(s["videos"].values()))["grid"])
    h, v = viewport_fov(g, None, None)
    ov = viewport_overlaps(WindowGrid.from_dict(dict(g.meta["grid"])), h, v)
    pof = np.asarray(g.pof_dps[:50], np.float32)
    field, cells = require_field(g)
    f0 = ShQ = shared_query(cells.cell_deg, Frustum.symmetric(h, v))
    d = ShQ.doubled(np.asarray(field[0]))
    q = rng.uniform(-90, 90, (2000, 3))
    t0 = time.perf_counter()
    for y, p, r in q:
        ov.epof(pof, y, p, r, 7)
    paper = (time.perf_counter() - t0) / len(q) * 1e6
    for y, p, r in q:
        f0.query(d, y, p, r)
    t0 = time.perf_counter()
    for y, p, r in q:
        f0.query(d, y, p, r)
    sphere = (time.perf_counter() - t0) / len(q) * 1e6
    return {"paper": paper, "sphere": sphere}


def main() -> int:
    from simulator.report.build import build_report

    out = _study()
    plots = plots_seconds(out)
    first = build_report(out)  # makes the browser copy (or reuses one from a former run)
    again = build_report(out)
    plots2 = plots_seconds(out)
    ref = min(plots, plots2)
    import os

    print(f"48 users x 4120 frames (sphere grid): plots and tables of the study {ref:.2f} s "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")  # fmt: skip
    print(f"  report build        {first.seconds:6.2f} s  ratio {first.seconds / ref:.2f}x  "
          f"(first build; browser copy: {json.dumps(first.copies)})")  # fmt: skip
    print(
        f"  report rebuild      {again.seconds:6.2f} s  ratio {again.seconds / ref:.2f}x  (goal <= 1.5x)"
    )
    rng = np.random.default_rng(1)
    py = _python_per_call(out, rng)
    br = _browser_figures(out, rng)
    for mode, goal in (("paper", 50), ("sphere", 100)):
        e = br["epof"][mode]
        print(f"  JS EPOF {mode:6s}      {e['path']:6.1f} us/call along a viewing's head path "
              f"({br['path_frames']} frames, fresh cache); random poses {e['cold']:.1f} us first pass, "
              f"{e['warm']:.1f} us repeated, {br['epof']['cpu'][mode]:.1f} us of renderer CPU time "
              f"(goal <= {goal}); Python one query {py[mode]:.1f} us: "
              f"ratio JS/Python {e['warm'] / py[mode]:.2f}x")  # fmt: skip
    if br["fps"]:
        fps, draw = br["fps"]
        print(f"  replay 1280x720     {fps:6.1f} fps ({fps / 25:.2f}x the video's 25 fps; drawing "
              f"alone {draw:.1f} fps, the rest is the frame's upload) on {br['renderer']}")  # fmt: skip
    else:
        print("  replay did not start")
    return 0


if __name__ == "__main__":
    sys.exit(main())
