"""A node failure during ``vimsim study`` on a two-node Ray cluster (loopback): wall time
of the study whose second node's raylet is killed mid-study, as a ratio to the same study
uninterrupted on the same cluster (both with the grid cached), and whether the outputs
match (viewings.csv and every EPOF CSV byte for byte).

The study: one synthetic clip (4 s, 256x128, sphere grid), 24 viewings (scripted traces),
two 1-CPU nodes. The kill lands when the first viewing's state file appears (tasks are
then running on both nodes); Ray reruns the tasks that were on the dead node on the
other one (``max_retries``).

Run: .venv/bin/python bench/ray_node_kill.py
"""

from __future__ import annotations

import csv
import json
import shutil
import sys
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "study"))
from ray_loopback import kill_raylet, loopback_cluster, use_loopback

use_loopback()

from simulator.cli import main

OUT = REPO / "bench" / "_out" / "ray_node_kill"
N_VIEWINGS = 24


def _inputs(d: Path) -> Path:
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    synthesize(SynthConfig("rotate", seconds=4.0, fps=15, size=(256, 128)), d / "clip.mp4")
    for i in range(N_VIEWINGS):
        save_headpath_csv(d / f"P{i:02d}.csv", synth("look-around", 4.5, rate_hz=30, seed=i))
    m = d / "study.toml"
    m.write_text(
        '[study]\nname = "kill"\n\n[[videos]]\nid = "clip"\npath = "clip.mp4"\n'
        'method = "sphere"\nwindow_size = 64\ncell = 5\n\n[[viewings]]\nvideo = "clip"\n'
        'trace = "P*.csv"\nparticipant = "{stem}"\n'
    )
    return m


def _run(m: Path, out: Path, cache: Path, address: str) -> float:
    t0 = time.monotonic()
    rc = main(["study", str(m), "-o", str(out), "--cache-dir", str(cache),
               "--executor", f"ray:{address}", "--no-progress"])  # fmt: skip
    dt = time.monotonic() - t0
    print(f"  {out.name}: exit {rc}, {dt:.2f} s", file=sys.stderr)
    return dt


def _same(a: Path, b: Path) -> tuple[bool, int, int]:
    ra = list(csv.DictReader(open(a / "viewings.csv", newline="")))  # noqa: SIM115
    rb = list(csv.DictReader(open(b / "viewings.csv", newline="")))  # noqa: SIM115
    names = sorted(p.name for p in (a / "epof").glob("*.csv"))
    same = [(a / "epof" / n).read_bytes() == (b / "epof" / n).read_bytes()
            for n in names if (b / "epof" / n).is_file()]  # fmt: skip
    ok = ra == rb and len(same) == len(names) and all(same)
    return ok, sum(same), len(names)


def main_bench() -> None:
    shutil.rmtree(OUT, ignore_errors=True)
    OUT.mkdir(parents=True)
    m = _inputs(OUT)
    nodes: list = []
    with loopback_cluster(OUT / "ray_logs", node_procs=nodes) as address:
        cache = OUT / "cache"
        _run(m, OUT / "cold", cache, address)  # fills the grid cache
        t_ref = _run(m, OUT / "uninterrupted", cache, address)
        killed = OUT / "killed"
        info = {}

        def kill() -> None:
            while not list((killed / "state").glob("*.json")):
                time.sleep(0.02)
            info["done_before"] = len(list((killed / "state").glob("*.json")))
            info["pid"] = kill_raylet(nodes[1])
            info["at"] = time.monotonic()

        th = threading.Thread(target=kill, daemon=True)
        th.start()
        t0 = time.monotonic()
        t_kill = _run(m, killed, cache, address)
        th.join(5)
    ok, n_same, n = _same(OUT / "uninterrupted", killed)
    s = json.loads((killed / "study.json").read_text())
    print(
        f"node killed {info['at'] - t0:.2f} s into the study ({info['done_before']} of "
        f"{N_VIEWINGS} viewings done); Ray nodes alive at the end: {s['ray_nodes']}"
    )
    print(f"uninterrupted {t_ref:.2f} s, with the node killed {t_kill:.2f} s")
    print(f"outputs identical: {ok} ({n_same}/{n} EPOF CSVs byte-identical, viewings.csv "
          f"{'equal' if ok else 'differs'})")  # fmt: skip
    print(f"ratio (killed / uninterrupted wall time): {t_kill / t_ref:.2f}")


if __name__ == "__main__":
    main_bench()
