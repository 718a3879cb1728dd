"""The CLI as a whole: registry, exit statuses, and choice lists kept in step with the
modules they mirror (the command modules copy them to stay light to import)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from simulator import analyze, geometry, headpath, synth
from simulator.cli import COMMANDS, build_parser, main
from simulator.commands import analyze as c_analyze
from simulator.commands import headpath as c_headpath
from simulator.commands import preprocess as c_preprocess
from simulator.commands import render as c_render
from simulator.commands import synth as c_synth
from simulator.commands import viewport as c_viewport


def test_choice_lists_match_their_modules():
    assert c_preprocess._LAYOUTS == geometry.LAYOUTS
    assert c_render._LAYOUTS == geometry.LAYOUTS
    assert c_viewport._LAYOUTS == geometry.LAYOUTS
    assert c_viewport._EYES == geometry.EYES
    assert c_viewport._INTERPS == geometry.INTERPS
    assert c_preprocess._GRIDS == tuple(geometry.GRID_PRESETS)
    assert c_headpath._KINDS == headpath.SYNTH_KINDS
    assert c_headpath._FORMATS == ("auto", *headpath.FORMATS)
    assert c_synth._SCENES == synth.SCENES
    assert c_analyze._FLOW_STATS == analyze.FLOW_STATS


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
