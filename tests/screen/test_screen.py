"""vimsim screen: bad input is one line and exit 2, before any work."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main


@pytest.fixture
def still(tmp_path):
    p = tmp_path / "still.png"
    Image.fromarray(np.zeros((64, 128, 3), np.uint8)).save(p)
    return p


@pytest.mark.parametrize(
    ("extra", "msg"),
    [
        (["--viewers", "0"], "--viewers"),
        (["--viewer-kind", "zigzag"], "unknown viewer kind"),
        (["--opacity-rule", "absolute", "--low-dps", "30", "--high-dps", "5"], "--low-dps"),
        (["--opacity-rule", "absolute", "--low-dps", "5", "--high-dps", "5"], "--low-dps"),
        (["--opacity-rule", "absolute", "--high-dps", "nan"], "--high-dps"),
        (["--opacity-rule", "absolute", "--low-dps", "inf"], "--low-dps"),
        (["--low-dps", "3"], "--opacity-rule absolute"),
    ],
)
def test_bad_options_exit_2(tmp_path, still, capsys, extra, msg):
    out = tmp_path / "out"
    try:
        rc = main(["screen", str(still), "-o", str(out), "--no-progress", *extra])
    except SystemExit as e:  # an argparse usage error
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert msg in err
    assert not out.exists()


def test_still_image_exit_2(tmp_path, still, capsys):
    out = tmp_path / "out"
    assert main(["screen", str(still), "-o", str(out), "--no-progress", "--viewers", "2"]) == 2
    err = capsys.readouterr().err.strip()
    assert "still.png" in err and "still image" in err
    assert len(err.splitlines()) == 1
    assert not out.exists()
