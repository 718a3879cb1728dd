"""vimsim screen: a viewer count whose work estimate exceeds the limit asks for --force, before any work."""

from __future__ import annotations

import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.screen.run import WORK_LIMIT_CPU_S, check_work


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("bounds")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    return d / "clip.mp4"


def test_huge_viewer_count_asks_for_force(clip, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["screen", str(clip), "-o", str(out), "--viewers", "100000", "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--viewers 100000" in err and "--force" in err and "CPU hours" in err
    assert not out.exists()


def test_work_estimate_rule():
    """More viewers than the default over the limit: refused unless forced; the default
    30 viewers are never refused, however long the video (the video is the user's)."""
    with pytest.raises(InputError, match="--viewers 100000"):
        check_work(100_000, [10])
    assert check_work(100_000, [10], force=True) > WORK_LIMIT_CPU_S
    assert check_work(30, [216_000]) > WORK_LIMIT_CPU_S  # two hours at 30 fps: allowed
    assert check_work(1000, [300, 300]) < WORK_LIMIT_CPU_S
