"""What every command says: --quiet and --log FILE everywhere, progress bars only on
a terminal, result lines on stdout and diagnostics on stderr, the cache variable's old name."""

from __future__ import annotations

import argparse
import io

import numpy as np
import pytest

from simulator.cli import build_parser, main
from simulator.commands._progress import Tee, progress_bar, progress_stream


def _leaves(parser):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, p in a.choices.items():
                yield name, p
                yield from _leaves(p)


def test_every_command_has_quiet_and_log():
    names = []
    for name, p in _leaves(build_parser()):
        opts = {o for a in p._actions for o in a.option_strings}
        assert {"--quiet", "--log"} <= opts, name
        names.append(name)
    assert {"study", "render", "synth", "convert", "analyze"} <= set(names)


def _radians_csv(path):
    t = np.arange(0, 3, 0.1)
    rows = "".join(f"{a:.2f},{3.1 * np.sin(a):.4f},0.1,0\n" for a in t)  # degrees? radians
    path.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n" + rows)
    return path


def test_quiet_and_log(tmp_path, capsys):
    src = _radians_csv(tmp_path / "rad.csv")
    log = tmp_path / "run.log"
    assert main(["headpath", "convert", str(src), "-o", str(tmp_path / "a.csv"), "--quiet",
                 "--log", str(log)]) == 0  # fmt: skip
    cap = capsys.readouterr()
    assert cap.out.startswith("wrote ") and cap.err == ""  # the warning is not shown ...
    text = log.read_text()
    assert "RADIANS" in text and "wrote " in text  # ... but logged, with the result
    assert main(["headpath", "convert", str(src), "-o", str(tmp_path / "b.csv")]) == 0
    cap = capsys.readouterr()
    assert "RADIANS" in cap.err and "RADIANS" not in cap.out and cap.out.startswith("wrote ")


def test_log_naming_an_input_is_refused(tmp_path, capsys):
    src = _radians_csv(tmp_path / "rad.csv")
    before = src.read_bytes()
    assert main(["headpath", "convert", str(src), "-o", str(tmp_path / "a.csv"),
                 "--log", str(src)]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "--log" in err and err.count("\n") == 1
    assert src.read_bytes() == before and not (tmp_path / "a.csv").exists()


def test_progress_only_on_a_terminal(monkeypatch):
    class Term(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr("sys.stderr", io.StringIO())  # a pipe or a file
    assert progress_stream() is None
    with progress_bar("x", enabled=False) as bar:  # --no-progress: nothing at all
        assert bar is None
    term = Term()
    monkeypatch.setattr("sys.stderr", term)
    with progress_bar("x") as bar:  # a terminal and no log: the bar alone
        bar(1, 2)
        bar(2, 2)
    assert "vimsim x:" not in term.getvalue()
    term = Term()
    monkeypatch.setattr("sys.stderr", term)
    assert progress_stream() is term
    monkeypatch.setattr("sys.stderr", Tee(term, io.StringIO(), quiet=True))
    assert progress_stream() is None  # --quiet
    log = io.StringIO()
    monkeypatch.setattr("sys.stderr", Tee(term, log))
    assert progress_stream() is term  # the bar on the terminal, never in the log


def test_progress_lines_without_a_terminal():
    """stderr a pipe or a file (nohup, a cluster job): plain 'k/n, elapsed, eta' lines at
    most every interval, and a last one at the end when any was written."""
    from simulator.commands._progress import ProgressLines

    now = [0.0]
    out = io.StringIO()
    p = ProgressLines("study", "task", out, interval_s=10.0, clock=lambda: now[0])
    for k, t in [(1, 3.0), (2, 9.9), (3, 10.0), (4, 12.0), (5, 25.0), (8, 26.0)]:
        now[0] = t
        p(k, 8)
    p(8, 8)  # the end reported twice: one last line
    assert out.getvalue().splitlines() == [
        "vimsim study: 3/8 tasks, elapsed 10 s, eta 17 s",
        "vimsim study: 5/8 tasks, elapsed 25 s, eta 15 s",
        "vimsim study: 8/8 tasks, elapsed 26 s, eta 0 s",
    ]
    quick = io.StringIO()
    q = ProgressLines("render", "frame", quick, clock=lambda: 1.0)
    q(1, 2, failed=1)  # done within the interval: no line at all
    assert quick.getvalue() == ""


def test_progress_lines_reach_the_log_and_the_pipe(monkeypatch):
    import simulator.commands._progress as P

    class Term(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(P, "LINE_INTERVAL_S", 0.0)
    monkeypatch.setattr(P.ProgressLines.__init__, "__kwdefaults__",
                        {"interval_s": 0.0, "clock": P.time.monotonic})  # fmt: skip
    for term in (io.StringIO(), Term()):  # a pipe, then a terminal: the log gets lines in both
        log = io.StringIO()
        monkeypatch.setattr("sys.stderr", Tee(term, log))
        with progress_bar("screen", unit="task") as bar:
            bar(1, 3)
            bar(3, 3)
        assert "vimsim screen: 1/3 tasks" in log.getvalue()
        assert ("vimsim screen: 1/3 tasks" in term.getvalue()) == (not term.isatty())


def test_quiet_keeps_error_lines():
    term = io.StringIO()
    t = Tee(term, None, quiet=True)
    t.write("vimsim x: warning: something\nvimsim x: error: bad\n")
    assert term.getvalue() == "vimsim x: error: bad\n"


@pytest.mark.parametrize("env, want_note", [
    ({"VIMSIM_CACHE_DIR": "new"}, False),
    ({"VIMSIM_CACHE": "old"}, True),
])  # fmt: skip
def test_one_cache_variable(env, want_note, monkeypatch, tmp_path, capsys):
    from simulator.core.mapcache import cache_dir
    from simulator.study import default_cache_dir

    for k in ("VIMSIM_CACHE_DIR", "VIMSIM_CACHE"):
        monkeypatch.delenv(k, raising=False)
    for k, v in env.items():
        monkeypatch.setenv(k, str(tmp_path / v))
    assert cache_dir() == default_cache_dir() == tmp_path / next(iter(env.values()))
    main(["headpath", "synth", "static", "-o", str(tmp_path / "p.csv"), "--seconds", "1"])
    err = capsys.readouterr().err
    assert ("VIMSIM_CACHE is deprecated" in err) == want_note
