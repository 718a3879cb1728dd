"""``vimsim study`` on Ray: a local runtime (``ray.init(num_cpus=2)``) and a two-node
cluster on loopback give byte-identical viewings.csv and EPOF CSVs to the local executor.
Slow (Ray start-up): kept to these two tests."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ray_loopback import loopback_cluster, use_loopback

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


def test_ray_two_node_loopback_cluster(base, local_run, tmp_path, capsys):  # noqa: F811
    """Two 1-CPU nodes, a cold cache: the video is preprocessed on the cluster (a task
    asking for more CPUs than a node has would wait for ever), same bytes as local."""
    out = tmp_path / "cluster"
    bad = base / "bad_cpus.toml"  # beside the inputs it names
    bad.write_text(
        _manifest(base).read_text().replace('eye_size = "64x64"', 'eye_size = "64x64"\ncpus = 2')
    )
    with loopback_cluster(tmp_path / "ray_logs") as address:
        argv = ["study", str(_manifest(base)), "-o", str(out), "--cache-dir", str(tmp_path / "c")]
        assert main([*argv, "--executor", f"ray:{address}", "--no-progress"]) == 3
        capsys.readouterr()
        argv[1] = str(bad)
        assert main([*argv, "--executor", f"ray:{address}", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "cpus = 2" in err[0] and "has 1 CPUs" in err[0], err
    s = json.loads((out / "study.json").read_text())
    assert s["ray_nodes"] == 2 and s["workers"] == 2
    assert next(iter(s["videos"].values()))["cache"] == "miss"
    _same(local_run, out)
