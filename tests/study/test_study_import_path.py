"""A study imports only the package: workers never run a module lying in the folder the
study is started from."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

_PLANT = "from pathlib import Path\nPath({marker!r}).write_text('ran {name}')\n"


def _plant(folder: Path, marker: Path) -> None:
    """json.py and concurrent.py that leave ``marker`` behind if anything imports them."""
    for name in ("json", "concurrent"):
        (folder / f"{name}.py").write_text(_PLANT.format(marker=str(marker), name=name))


def _vimsim() -> list[str]:
    """The installed console script (what a user runs), else ``python -P -m simulator``."""
    script = Path(sys.executable).parent / "vimsim"
    return [str(script)] if script.is_file() else [sys.executable, "-P", "-m", "simulator"]


def test_safe_import_path_drops_the_working_folder(tmp_path):
    from simulator.study.executors import safe_import_path

    cwd = str(tmp_path)
    path = ["", ".", cwd, "/usr/lib/python3.11", cwd + "/sub"]
    assert safe_import_path(path, cwd) == ["/usr/lib/python3.11", cwd + "/sub"]


def test_study_from_a_folder_with_stdlib_names(tmp_path):
    """A local study started in a folder holding json.py and concurrent.py (that would write
    a marker when imported) completes, and neither was run."""
    from simulator.synth import SynthConfig, synthesize
    from simulator.traces.path import save_headpath_csv, synth

    d = tmp_path / "work"
    d.mkdir()
    marker = tmp_path / "MARKER"
    synthesize(SynthConfig("rotate", seconds=0.5, fps=10, size=(64, 32)), d / "clip.mp4")
    save_headpath_csv(d / "P01.csv", synth("look-around", 0.6, rate_hz=30, seed=0))
    (d / "s.toml").write_text(
        '[study]\nname = "t"\n\n[[videos]]\nid = "clip"\npath = "clip.mp4"\nmethod = "sphere"\n'
        'window_size = 32\n\n[[viewings]]\nvideo = "clip"\ntrace = "P01.csv"\n'
    )
    _plant(d, marker)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONSAFEPATH"}
    r = subprocess.run(
        [*_vimsim(), "study", "s.toml", "-o", "out", "--cache-dir", "cache", "--workers", "1",
         "--no-progress"],
        check=False, cwd=d, env=env, capture_output=True, text=True, timeout=240,
    )  # fmt: skip
    assert not marker.exists(), f"a module from the working folder ran: {marker.read_text()}"
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert (d / "out" / "viewings.csv").is_file()
