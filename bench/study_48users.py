"""48 users of one multi-user file (360VidStr aggregated 33.txt, 165 s), EPOF of every user on
a sphere-mode grid: the whole ``vimsim study`` process, against the shell loop it replaces.

The video: the real 360 clip pano.mp4 (three.js, 25 fps, 1920x1080 anamorphic 2:1) looped
by stream copy to 4120 frames (164.8 s, within every user's 164.9 s). Its grid is made by
the first (cold) study and cached; the figure is the warm run (grid reused), the cold one
is printed too. Reference, measured in the same run: per user, ``vimsim headpath convert
33.txt --user N`` then ``vimsim epof GRID user.csv`` as separate processes (what users did
before), on 3 users, times 48. Their EPOF CSVs must equal the study's byte for byte.

Second reference, same run: the same study on a copy of the grid without the rotation /
translation parts (``field_trans_dps`` and the camera rotation left out): what the parts
cost (one viewport integration gives the EPOF and its parts).

Run: .venv/bin/python bench/study_48users.py   (goal: study <= 2 s on the 2-core machine)
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from _pano import USERS48, loop_study  # bench/_pano.py: the looped clip and its 48-user manifest


def _epof_rows(path) -> np.ndarray:
    """The data rows of an EPOF CSV (its '#' settings lines and header skipped)."""
    lines = [ln for ln in Path(path).read_text().splitlines() if ln and not ln.startswith("#")]
    return np.loadtxt(lines[1:], delimiter=",", ndmin=2, usecols=range(7))  # the EPOF columns


REPO = Path(__file__).resolve().parents[1]
TRACE = USERS48
OUT = REPO / "bench" / "_out" / "study_48users"
VIMSIM = [str(Path(sys.executable).with_name("vimsim"))]


CPU: dict[str, float] = {}


def run(argv: list[str], name: str = "") -> float:
    """Wall-clock seconds of a command; its CPU seconds (user + sys, children) in CPU[name]."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(argv, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU[name] = CPU.get(name, 0.0) + (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return wall


def main() -> int:
    manifest = loop_study(OUT)
    cache = OUT / "cache"
    cold = None
    if not any((cache / "grids").glob("*.npz")) if (cache / "grids").is_dir() else True:
        shutil.rmtree(OUT / "cold", ignore_errors=True)
        cold = run([*VIMSIM, "study", str(manifest), "-o", str(OUT / "cold"), "--cache-dir",
                    str(cache), "--no-progress"])  # fmt: skip
    shutil.rmtree(OUT / "warm", ignore_errors=True)
    load0 = os.getloadavg()[0]
    warm = run([*VIMSIM, "study", str(manifest), "-o", str(OUT / "warm"), "--cache-dir",
                str(cache), "--no-progress"])  # fmt: skip
    s = json.loads((OUT / "warm" / "study.json").read_text())
    assert s["counts"] == {"viewings": 48, "ok": 48, "with_warnings": 0, "failed": 0, "resumed": 0,
                           "renders": 0}, s[
        "counts"
    ]
    grid = next((cache / "grids").glob("*.npz"))
    # the same study over the grid without its parts
    bare = OUT / "cache-noparts"
    shutil.rmtree(bare, ignore_errors=True)
    shutil.copytree(cache, bare)
    with np.load(grid, allow_pickle=False) as z:
        keep = {k: z[k] for k in z.files if k != "field_trans_dps" and not k.startswith("ego_")}
    meta = json.loads(str(keep["meta"]))
    meta.pop("ego", None)
    keep["meta"] = np.array(json.dumps(meta))
    np.savez(bare / "grids" / grid.name, **keep)
    shutil.rmtree(OUT / "noparts", ignore_errors=True)
    noparts = run([*VIMSIM, "study", str(manifest), "-o", str(OUT / "noparts"), "--cache-dir",
                   str(bare), "--no-progress"])  # fmt: skip
    assert json.loads((OUT / "noparts" / "study.json").read_text())["counts"]["ok"] == 48

    # Reference: the per-user shell loop, 3 users.
    users = (1, 24, 48)
    loop = 0.0
    for u in users:
        csv_ = OUT / f"u{u}.csv"
        epof = OUT / f"u{u}_epof.csv"
        loop += run(
            [*VIMSIM, "headpath", "convert", str(TRACE), "--user", str(u), "-o", str(csv_)], "loop"
        )
        loop += run([*VIMSIM, "epof", str(grid), str(csv_), "-o", str(epof)], "loop")
        ours = OUT / "warm" / "epof" / f"sandwich-loop-33_user{u:02d}.csv"
        # The loop goes through the canonical CSV (angles to 10 significant digits): equal
        # to that rounding, not to the bit.
        a, b = (_epof_rows(p) for p in (ours, epof))
        assert a.shape == b.shape and np.allclose(a, b, rtol=1e-6, atol=1e-6), f"user {u}"
    loop48 = loop / len(users) * 48
    t = s["timings_s"]
    print(
        f"48 users x {s['outputs']['videos']['sandwich-loop']['moments'] and 4120} frames, sphere grid, warm cache:"
    )
    print(
        f"  vimsim study (whole process)  {warm:7.2f} s   (goal <= 2 s; inside: plan {t['plan']:.2f}, "
        f"tasks {t['tasks']:.2f}, outputs {t['outputs']:.2f}, total {t['total']:.2f})"
    )
    if cold is not None:
        print(
            f"  cold (grid made first)        {cold:7.2f} s   (sphere preprocess of 4120 frames included)"
        )
    print(
        f"  reference shell loop          {loop48:7.2f} s   ({loop / len(users):.2f} s/user measured on users {users}, x 48)"
    )
    print(f"  same study, grid without parts {noparts:6.2f} s   (ratio with / without parts "
          f"{warm / noparts:.2f}x)")  # fmt: skip
    cpu = t["cpu_driver"] + t["cpu_tasks"]
    cpu_loop = CPU["loop"] / len(users) * 48
    print(f"  ratio loop / study            {loop48 / warm:7.1f}x wall, {cpu_loop / cpu:.1f}x CPU")
    print(
        f"  CPU: study {cpu:.1f} s (driver {t['cpu_driver']:.1f} + tasks {t['cpu_tasks']:.1f}; "
        f"worker start-up not counted), i.e. >= {cpu / 2:.1f} s wall on 2 free cores; loop "
        f"{cpu_loop:.1f} s (user + sys of its processes); load average {load0:.1f} before the "
        f"study, {os.getloadavg()[0]:.1f} at the end (2 cores)"
    )
    print("  EPOF of users", users, "equal to the loop's vimsim epof (rtol 1e-6: its CSV rounding)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
