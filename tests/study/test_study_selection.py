"""Studies as labs run them: user lists and ranges, a render subset with its own
range, --dry-run, warnings attributed to the right viewing and kept on resume."""

from __future__ import annotations

import csv
import json
import time
from pathlib import Path

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.study import load_manifest
from simulator.traces.path import save_headpath_csv, synth


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A tiny clip; a 5-user 360VidStr-format file whose user 4 turns 120 deg between two
    samples (a CoarseSamplingWarning, its own); a single trace in radians (RadiansWarning)."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("sel")
    synthesize(SynthConfig("rotate", seconds=1.5, fps=10, size=(128, 64)), d / "clip.mp4")
    t = np.arange(0, 2.01, 0.1)
    lines = [" ".join(f"{v:.3f}" for v in t)]
    for u in range(1, 6):
        yaw = 0.05 * u + 0.02 * np.arange(len(t))
        if u == 4:
            yaw[10:] += np.radians(120.0)
        lines += [" ".join("0.0" for _ in t), " ".join(f"{v:.4f}" for v in yaw)]
    (d / "multi.txt").write_text("\n".join(lines) + "\n")
    hp = synth("sine", 2.0, rate_hz=30, yaw_amp=120.0, yaw_freq=0.5)
    y, p, _ = hp.sample_angles_deg(hp.times_s)
    (d / "rad.csv").write_text("time_s,yaw_deg,pitch_deg,roll_deg\n" + "".join(
        f"{a:.4f},{np.radians(b):.5f},{np.radians(c):.5f},0\n" for a, b, c in zip(hp.times_s, y, p)))  # fmt: skip
    save_headpath_csv(d / "P1.csv", synth("look-around", 2.0, rate_hz=30, seed=1))
    return d


def _manifest(d: Path, viewings: str, render: str = "") -> Path:
    m = d / "study.toml"
    m.write_text(f"""
[[videos]]
id = "clip"
path = "clip.mp4"
method = "sphere"
window_size = 64

{viewings}

[render]
eye_size = "64x64"
{render}
""")
    return m


MULTI = """
[[viewings]]
video = "clip"
trace = "multi.txt"
user = "{users}"
condition = "NR"
render = {render}
"""


def test_user_lists_and_ranges(base):
    def users(spec):
        m = load_manifest(_manifest(base, MULTI.replace('"{users}"', spec).format(render="false")))
        return [w.user for w in m.viewings]

    assert users('"all"') == [1, 2, 3, 4, 5]
    assert users('"2-4"') == [2, 3, 4]
    assert users('"1-2,5"') == [1, 2, 5]
    assert users("[5, 1]") == [5, 1]
    assert users('[1, "3-4"]') == [1, 3, 4]
    assert users("3") == [3]


@pytest.mark.parametrize("spec, want", [
    ('"1-9"', "no user 6"),
    ('"4-2"', "range '4-2' is empty"),
    ("[0]", "expected a number >= 1"),
    ('"x"', "expected a number >= 1"),
])  # fmt: skip
def test_bad_user_specs_name_the_entry(base, spec, want, capsys):
    m = _manifest(base, MULTI.replace('"{users}"', spec).format(render="false"))
    with pytest.raises(InputError, match=want):
        load_manifest(m)
    assert main(["study", str(m), "-o", str(base / "never"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert "[[viewings]] #1" in err and err.count("\n") == 1
    assert not (base / "never").exists()


def test_render_subset_and_its_options(base):
    v = MULTI.format(users="all", render='"2-3"') + 'start = 0.2\nend = 1.0\nreview = true\n'
    m = load_manifest(_manifest(base, v, 'eyes = "left"'))
    assert [w.render for w in m.viewings] == [False, True, True, False, False]
    r = m.viewings[1].render_opts
    assert (r["start_s"], r["end_s"], r["review"], r["eyes"]) == (0.2, 1.0, True, "left")
    assert m.viewings[0].render_opts is None
    bad = MULTI.format(users="1-2", render="[3]")
    with pytest.raises(InputError, match="user 3 is not among"):
        load_manifest(_manifest(base, bad))
    with pytest.raises(InputError, match=r"\[\[viewings\]\] #1.*start = 2 is not before end = 1"):
        load_manifest(_manifest(base, MULTI.format(users="1", render="true")
                                + "start = 2.0\nend = 1.0\n"))  # fmt: skip
    with pytest.raises(InputError, match=r"\[render\]: start = 1 is not before end = 1"):
        load_manifest(_manifest(base, MULTI.format(users="1", render="true"),
                                "start = 1.0\nend = 1.0"))  # fmt: skip


WARN = MULTI.format(users="all", render='"2"') + """start = 0.2
end = 0.8
review = true

[[viewings]]
video = "clip"
trace = "rad.csv"

[[viewings]]
video = "clip"
trace = "P1.csv"
condition = "GR"
"""


def _rows(path):
    with open(path, newline="") as fh:
        return {r["viewing"]: r for r in csv.DictReader(fh)}


@pytest.mark.gl
def test_dry_run_then_run_warnings_attributed_and_resumed(base, tmp_path, capsys):
    m = _manifest(base, WARN)
    out, cache = tmp_path / "o", tmp_path / "cache"
    args = ["study", str(m), "-o", str(out), "--cache-dir", str(cache), "--workers", "2"]
    t0 = time.perf_counter()
    assert main([*args, "--dry-run"]) == 0
    dry_s = time.perf_counter() - t0
    cap = capsys.readouterr()
    assert not out.exists() and not cache.exists()  # nothing written
    assert "7 viewings (7 to compute, 0 unchanged, 1 to render, 2 with warnings), 9 tasks" in cap.out
    assert "render 0.2..0.8 s +review" in cap.out
    assert dry_s < 10  # the figure is bench/study_lab.py's; this only catches a runaway
    assert main(args) == 0
    cap = capsys.readouterr()
    assert "7 ok, 2 with warnings, 0 failed (of 7 viewings" in cap.out
    rows = _rows(out / "viewings.csv")
    warned = {k: r["warnings"] for k, r in rows.items() if r["warnings"]}
    assert set(warned) == {"clip-multi_user4-NR", "clip-rad"}
    assert "differ by 12" in warned["clip-multi_user4-NR"]  # its own 120 deg step, only once
    assert warned["clip-multi_user4-NR"].count("sampling too coarse") == 1
    assert "RADIANS" in warned["clip-rad"]
    assert cap.err.count("sampling too coarse") == 1  # listed once on the console
    s = json.loads((out / "study.json").read_text())
    assert s["counts"]["with_warnings"] == 2 and len(s["warnings"]) == 2
    summary = json.loads((out / "render" / "clip-multi_user2-NR" / "summary.json").read_text())
    assert summary["frames_written"] == 6 and summary["review"]  # 0.2 .. 0.8 s at 10 fps
    assert (out / "render" / "clip-multi_user2-NR" / "review.mp4").is_file()
    assert not (out / "render" / "clip-multi_user1-NR").exists()
    # resume: nothing recomputed, warnings kept
    assert main(args) == 0
    cap = capsys.readouterr()
    assert "7 ok, 2 with warnings, 0 failed (of 7 viewings; 7 unchanged)" in cap.out
    assert _rows(out / "viewings.csv") == rows
    assert main([*args, "--dry-run"]) == 0
    assert "(0 to compute, 7 unchanged, 1 to render, 0 with warnings), 0 tasks" in capsys.readouterr().out


def test_dry_run_reports_a_trace_that_does_not_cover_its_video(base, tmp_path, capsys):
    save_headpath_csv(tmp_path / "short.csv", synth("static", 0.5, rate_hz=30))
    v = f'[[viewings]]\nvideo = "clip"\ntrace = "{tmp_path / "short.csv"}"\n'
    m = _manifest(base, v + MULTI.format(users="1", render="false"))
    assert main(["study", str(m), "-o", str(tmp_path / "o"), "--cache-dir",
                 str(tmp_path / "c"), "--dry-run"]) == 2  # fmt: skip
    cap = capsys.readouterr()
    assert "error: viewing clip-short: head path" in cap.err and "ends at 0.500 s" in cap.err
    assert "1 problems" in cap.out and not (tmp_path / "o").exists()


def test_per_viewing_view_options_go_through_the_one_builder(base):
    from simulator.viewing.spec import ViewSpec

    v = MULTI.format(users="1-2", render="true") + 'headset = "quest-2"\ngrain_size = 3.0\n'
    m = load_manifest(_manifest(base, v, "fov = 90\ncrf = 30"))
    r = m.viewings[0].render_opts
    assert r["crf"] == 30 and "fov" not in r["view"] and r["view"]["headset"] == "quest-2"
    spec = ViewSpec.from_options(r["view"])
    assert spec.frustum == ViewSpec.from_options({**r["view"], "fov": None}).frustum
    assert spec.grains.grain_deg == 3.0
    assert m.render["view"]["fov"] == 90  # the study's own [render] is unchanged
    bad = MULTI.format(users="1", render="true") + "density = 7\n"
    with pytest.raises(InputError, match=r"\[\[viewings\]\] #1 .*density"):
        load_manifest(_manifest(base, bad))


@pytest.mark.parametrize("spec, first", [
    ('"1-99999999999999999999"', "no user 6"),
    ('"1-100000,1-100000"', "no user 6"),
    ('[2, "7-99999999999999999999999"]', "no user 7"),
])  # fmt: skip
def test_huge_user_ranges_refused_without_expanding(base, spec, first, tmp_path):
    """A range is checked against the file's users before it is expanded: refused at
    once (exit 2, naming the entry and the file's users), not after building a list of
    1e20 users (it ran out of memory ignoring SIGTERM). The subprocess's generous limit
    only stops a regression from hanging the suite."""
    import os
    import subprocess
    import sys

    m = _manifest(base, MULTI.replace('"{users}"', spec).format(render="false"))
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    r = subprocess.run([sys.executable, "-m", "simulator", "study", str(m), "-o",
                        str(tmp_path / "never"), "--dry-run"], capture_output=True, text=True,
                       timeout=120, env=env, check=False)  # fmt: skip
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1
    assert "[[viewings]] #1" in r.stderr and first in r.stderr and "users 1-5" in r.stderr
    assert "multi.txt" in r.stderr
    assert not (tmp_path / "never").exists()


def test_user_spec_checked_as_ranges():
    """The spec is kept as ranges until checked; repeats are dropped in linear time."""
    from simulator.study.entry import Entry, user_numbers, user_spans

    e = Entry(Path("s.toml"), "[[viewings]] #1", {}, ())
    assert user_spans(e, "user", "1-99999999999999999999") == [(1, 99999999999999999999)]
    with pytest.raises(InputError, match="no user 51 .*the file holds users 1-50"):
        user_numbers(e, "user", "1-99999999999999999999", n_users=50)
    assert user_numbers(e, "user", "1-100000,1-100000", n_users=100_000) == list(range(1, 100_001))
    assert user_numbers(e, "user", ["3-4", 1, "2-3"], n_users=5) == [3, 4, 1, 2]
