"""The CLI as a whole: registry, exit statuses, and choice lists from simulator.core.choices."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from simulator.cli import COMMANDS, build_parser, main
from simulator.core import choices
from simulator.core.choices import OPACITY_SOURCES
from simulator.sphere import windows
from simulator.synth import SCENES
from simulator.traces import readers
from simulator.traces.path import SYNTH_KINDS


def _choices(parser: argparse.ArgumentParser, *path: str) -> dict[str, tuple]:
    """``{option: choices}`` of the subcommand reached by ``path`` (e.g. "headpath", "convert")."""
    for name in path:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[name]
    return {
        (a.option_strings[0] if a.option_strings else a.dest): tuple(a.choices)
        for a in parser._actions
        if a.choices is not None and not isinstance(a, argparse._SubParsersAction)
    }


def test_choice_lists_come_from_one_module():
    """The parsers offer exactly the library's choices (both read simulator.core.choices)."""
    p = build_parser()
    for cmd in ("preprocess", "render", "viewport"):
        assert _choices(p, cmd)["--layout"] == choices.LAYOUTS
    assert _choices(p, "viewport")["--eye"] == choices.EYES
    assert _choices(p, "viewport")["--interp"] == choices.INTERPS
    assert _choices(p, "preprocess")["--grid"] == tuple(windows.GRID_PRESETS)
    assert _choices(p, "preprocess")["--method"] == choices.PREPROCESS_METHODS
    assert _choices(p, "headpath", "synth")["kind"] == SYNTH_KINDS
    assert _choices(p, "headpath", "convert")["--format"] == ("auto", *readers.FORMATS)
    assert _choices(p, "synth")["--scene"] == SCENES
    assert _choices(p, "epof")["--opacity-source"] == OPACITY_SOURCES
    assert _choices(p, "analyze")["--flow-stat"] == choices.FLOW_STATS


def test_headset_names_and_a_light_parser():
    """The --headset help lists the profiles from simulator.core.choices, and building the whole
    parser (every subcommand's options) imports no numpy (the CLI's fast start)."""
    from simulator.sphere.headsets import HEADSETS

    assert tuple(HEADSETS) == choices.HEADSET_NAMES
    code = "import sys, simulator.cli as c; c.build_parser(); print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_command_is_registered():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sorted(sub.choices) == sorted(COMMANDS)


def test_usage_errors_exit_2(capsys):
    assert main([]) == 2  # prints the help
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["viewport", "x.png"])  # -o, --yaw, --pitch missing
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "required: -o/--output, --yaw, --pitch" in err


def test_python_dash_m_is_the_same_program():
    r = subprocess.run(
        [sys.executable, "-m", "simulator", "--version"],
        check=False,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0
    assert r.stdout.startswith("vimsim ")
