"""``vimsim study`` on Ray: a local runtime (``ray.init(num_cpus=2)``) and a two-node
cluster on loopback give byte-identical viewings.csv and EPOF CSVs to the local executor.
Slow (Ray start-up): kept to these two tests."""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ray_loopback import kill_raylet, loopback_cluster, use_loopback

pytest.importorskip("ray", reason="Ray is the optional extra vimsim[ray]; make test installs it")
use_loopback()  # before ray is first imported by a test

from test_study import _manifest, base  # noqa: F401  (the shared fixture)

from simulator.cli import main


def _same(a: Path, b: Path) -> None:
    assert (a / "viewings.csv").read_bytes() == (b / "viewings.csv").read_bytes()
    names = sorted(p.name for p in (a / "epof").glob("*.csv"))
    assert names == sorted(p.name for p in (b / "epof").glob("*.csv")) and len(names) == 8
    for n in names:
        assert (a / "epof" / n).read_bytes() == (b / "epof" / n).read_bytes(), n


@pytest.fixture(scope="module")
def local_run(base, tmp_path_factory):  # noqa: F811
    out = tmp_path_factory.mktemp("local") / "o"
    argv = ["study", str(_manifest(base)), "-o", str(out), "--cache-dir", str(base / "cache")]
    assert main([*argv, "--workers", "2", "--no-progress"]) == 3
    return out


def test_ray_local_runtime_identical(base, local_run, tmp_path):  # noqa: F811
    out = tmp_path / "ray"
    argv = ["study", str(_manifest(base)), "-o", str(out), "--cache-dir", str(base / "cache")]
    assert main([*argv, "--executor", "ray", "--workers", "2", "--no-progress"]) == 3
    _same(local_run, out)
    s = json.loads((out / "study.json").read_text())
    assert s["executor"] == "ray" and s["workers"] == 2 and "ray" in s["versions"]
    assert (out / "render" / "render-P01" / "summary.json").is_file()


class _NodeKiller(threading.Thread):
    """Kills the raylet of ``node`` once the study in ``out`` has completed its first
    viewing (its state file): mid-study, with the other viewings still to come."""

    def __init__(self, node, out: Path, timeout_s: float = 120.0):
        super().__init__(daemon=True)
        self.node, self.out, self.timeout_s = node, out, timeout_s
        self.at = self.done_before = None

    def run(self) -> None:
        t0 = time.monotonic()
        while time.monotonic() - t0 < self.timeout_s:
            done = list((self.out / "state").glob("*.json"))
            if done:
                self.done_before = len(done)
                kill_raylet(self.node)
                self.at = time.monotonic()
                return
            time.sleep(0.05)


def _same_or_reported(a: Path, b: Path) -> list[str]:
    """``b`` equals the uninterrupted ``a`` viewing by viewing, or a viewing whose task could
    not be rerun says so in its status and has no EPOF CSV (nothing half-written); returns
    those viewings."""
    import csv

    ra = {r["viewing"]: r for r in csv.DictReader(open(a / "viewings.csv", newline=""))}  # noqa: SIM115
    rb = {r["viewing"]: r for r in csv.DictReader(open(b / "viewings.csv", newline=""))}  # noqa: SIM115
    assert list(ra) == list(rb)
    lost = [v for v in ra if ra[v] != rb[v]]
    for v in lost:
        assert "Ray" in rb[v]["status"] or "worker" in rb[v]["status"], rb[v]
        assert not (b / "epof" / f"{v}.csv").exists() or rb[v]["status"].startswith("render")
    for v in set(ra) - set(lost):
        if (a / "epof" / f"{v}.csv").exists():
            assert (a / "epof" / f"{v}.csv").read_bytes() == (b / "epof" / f"{v}.csv").read_bytes()
    assert not [q for q in b.rglob("*") if ".tmp-" in q.name]
    return lost


def test_ray_two_node_loopback_cluster(base, local_run, tmp_path, capsys):  # noqa: F811
    """Two 1-CPU nodes, a cold cache: the video is preprocessed on the cluster (a task
    asking for more CPUs than a node has would wait for ever), same bytes as local.
    Then a node failure: the second node's raylet is killed once the first viewing of a
    new study is done; the study completes with the bytes of the uninterrupted local run
    (Ray reruns the lost tasks on the other node), or reports the viewings it lost."""
    out = tmp_path / "cluster"
    bad = base / "bad_cpus.toml"  # beside the inputs it names
    bad.write_text(
        _manifest(base).read_text().replace('eye_size = "64x64"', 'eye_size = "64x64"\ncpus = 2')
    )
    nodes: list = []
    with loopback_cluster(tmp_path / "ray_logs", node_procs=nodes) as address:
        argv = ["study", str(_manifest(base)), "-o", str(out), "--cache-dir", str(tmp_path / "c")]
        assert main([*argv, "--executor", f"ray:{address}", "--no-progress"]) == 3
        capsys.readouterr()
        argv[1] = str(bad)
        assert main([*argv, "--executor", f"ray:{address}", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "cpus = 2" in err[0] and "has 1 CPUs" in err[0], err
        # the node failure, mid-study
        killed = tmp_path / "killed"
        argv = [
            "study",
            str(_manifest(base)),
            "-o",
            str(killed),
            "--cache-dir",
            str(tmp_path / "c"),
        ]
        killer = _NodeKiller(nodes[1], killed)
        killer.start()
        t0 = time.monotonic()
        rc = main([*argv, "--executor", f"ray:{address}", "--no-progress"])
        t_end = time.monotonic()
        killer.join(5)
        err = capsys.readouterr().err
    s = json.loads((out / "study.json").read_text())
    assert s["ray_nodes"] == 2 and s["workers"] == 2
    assert next(iter(s["videos"].values()))["cache"] == "miss"
    _same(local_run, out)
    assert killer.at is not None and killer.at < t_end, "the node was not killed mid-study"
    assert killer.done_before < 9  # viewings were still to come when it died
    assert rc == 3 and "Traceback" not in err, err  # 3: the short trace fails, as locally
    lost = _same_or_reported(local_run, killed)
    print(f"node killed {killer.at - t0:.1f} s into a {t_end - t0:.1f} s study; lost: {lost}")
