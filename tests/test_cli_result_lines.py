"""Every command prints its result line on stdout (the table below must name every command
of the parser: a new one is added here), runs with tiny inputs in dependency order."""

from __future__ import annotations

import argparse
import csv
import shutil
from pathlib import Path

import pytest

from simulator.cli import build_parser, main

#: Commands whose result line is asserted by their own test, which builds what they need
#: (calibrate: a dozen rated clips); named here so the table below stays complete.
_ELSEWHERE = {("calibrate",): "tests/discomfort/test_calibrate.py"}
#: Commands whose result line is a verdict, not a written path.
_NO_PATH = {("compare",)}


def _leaves(parser, pre=()):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, p in a.choices.items():
                subs = [x for x in p._actions if isinstance(x, argparse._SubParsersAction)]
                yield from _leaves(p, (*pre, name)) if subs else [(*pre, name)]


def _analysis_data(path):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "condition", "ssq_n", "ssq_o", "ssq_d", "ssq_total", "mssq", "flow"])
        for i in range(8):
            w.writerow(
                [f"p{i}", "GR" if i % 2 else "NR", 9.54, 7.58, 13.92, 10 + 3 * i, 5 + i, 40 + i]
            )
    return path


def _commands(d) -> list[tuple[tuple[str, ...], list[str]]]:
    """(leaf, argv) in the order they can run (later ones read earlier outputs)."""
    v, p, g = str(d / "v.mp4"), str(d / "p.csv"), str(d / "g.npz")
    (d / "study.toml").write_text(
        '[[videos]]\nid = "v"\npath = "v.mp4"\nmethod = "sphere"\nwindow_size = 32\n'
        '[[viewings]]\nvideo = "v"\ntrace = "p.csv"\n'
    )
    eye = ["--eye-size", "32x32", "--no-progress"]
    return [
        (("synth",), ["synth", v, "--scene", "coaster", "--seconds", "1", "--fps", "10",
                      "--size", "256x128"]),
        (("viewport",), ["viewport", v, "-o", str(d / "view.png"), "--yaw", "10", "--pitch",
                         "0", "--size", "32x32"]),
        (("headpath", "synth"), ["headpath", "synth", "static", "-o", p, "--seconds", "1.2"]),
        (("headpath", "convert"), ["headpath", "convert", p, "-o", str(d / "p2.csv")]),
        (("headpath", "show"), ["headpath", "show", p, "-o", str(d / "p.png")]),
        (("preprocess",), ["preprocess", v, "-o", g, "--method", "sphere", "--window-size",
                           "32", "--no-progress"]),
        (("ego",), ["ego", g, "-o", str(d / "ego.csv"), "--no-progress"]),
        (("epof",), ["epof", g, p, "-o", str(d / "e.csv")]),
        (("render",), ["render", v, p, "-o", str(d / "r"), "--grid", g, *eye]),
        (("frames",), ["frames", v, p, "-o", str(d / "f"), "--at", "0.5", *eye]),
        (("compare",), ["compare", str(d / "f"), str(d / "golden")]),
        (("analyze",), ["analyze", str(_analysis_data(d / "data.csv")), "-o", str(d / "an")]),
        (("export",), ["export", g, "-o", str(d / "unity")]),
        (("grid", "import"), ["grid", "import", str(d / "cao"), "-o", str(d / "cao.npz"),
                              "--fps", "10"]),
        (("study",), ["study", str(d / "study.toml"), "-o", str(d / "st"), "--cache-dir",
                      str(d / "cache"), "--no-progress", "--no-report"]),
        (("report",), ["report", str(d / "st")]),
        (("screen",), ["screen", v, "-o", str(d / "sc"), "--viewers", "2", "--grid", g,
                       "--no-progress"]),
        (("demo",), ["demo", "-o", str(d / "demo"), "--seconds", "1", "--no-progress"]),
    ]  # fmt: skip


@pytest.mark.slow
def test_every_command_prints_its_result_line_on_stdout(tmp_path, capsys):
    cmds = _commands(tmp_path)
    assert sorted([*(leaf for leaf, _ in cmds), *_ELSEWHERE]) == sorted(_leaves(build_parser()))
    for leaf, test in _ELSEWHERE.items():  # that test runs it and reads its stdout
        text = (Path(__file__).parent.parent / test).read_text()
        assert f'"{leaf[-1]}"' in text and "readouterr().out" in text, (leaf, test)
    for leaf, argv in cmds:
        if leaf == ("compare",):  # goldens: the frames, as a reviewed copy
            shutil.copytree(tmp_path / "f", tmp_path / "golden")
        if leaf == ("grid", "import"):  # the authors' layout, from vimsim's own export
            paper = str(tmp_path / "paper.npz")
            assert main(["preprocess", str(tmp_path / "v.mp4"), "-o", paper, "--method", "paper",
                         "--window-size", "32", "--no-progress"]) == 0  # fmt: skip
            assert main(["export", paper, "-o", str(tmp_path / "cao"), "--format", "cao-csv"]) == 0
            capsys.readouterr()
        rc = main(argv)
        cap = capsys.readouterr()
        assert rc == 0, (leaf, cap.err)
        lines = [ln for ln in cap.out.splitlines() if ln.strip()]
        assert lines, f"vimsim {' '.join(leaf)} printed no result line on stdout"
        # the result names what was written (a path under the test folder)
        assert str(tmp_path) in cap.out or leaf in _NO_PATH, (leaf, cap.out)
