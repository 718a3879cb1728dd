"""Manifest = CLI for traces: [traces] defaults and per-viewing trace keys, keys refused where they have no effect, errors in the manifest's terms, hold_last reaching the EPOF."""

from __future__ import annotations

import json

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.core.traceopts import TRACE_OPTIONS
from simulator.study.manifest import load_manifest
from simulator.study.plan import dry_run
from simulator.study.traces import TRACE_KEYS, VIEWING_TRACE_KEYS
from simulator.traces.path import save_headpath_csv, synth

SIT_FORMAT = "%Y%m%dZ-%H%M%S_%fZ"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A 1.5 s clip; a trace covering it, a short one, a 370 s one and a SIT-VR log."""
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("traces")
    synthesize(SynthConfig("rotate", seconds=1.5, fps=10, size=(128, 64)), d / "clip.mp4")
    save_headpath_csv(d / "ok.csv", synth("look-around", 1.6, rate_hz=30, seed=1))
    save_headpath_csv(d / "short.csv", synth("static", 0.5, rate_hz=30))
    save_headpath_csv(d / "long.csv", synth("sweep", 370.0, rate_hz=2))
    log = {}
    for k in range(40):  # every 50 ms: 1.95 s, the first sample zero
        ms = 686 + 50 * k
        log[f"20210510Z-2004{ms // 1000:02d}_{ms % 1000:03d}Z"] = {
            "Ex": (360.0 - k) % 360.0 if k else 0.0, "Ey": 2.0 * k, "Ez": 0.0, "Rx": 0.5}  # fmt: skip
    (d / "sit.json").write_text(json.dumps({"1-SubheadPosition": log}))
    return d


def _write(d, name: str, viewings: str, extra: str = "") -> object:
    m = d / f"{name}.toml"
    m.write_text(
        f'[[videos]]\nid = "clip"\npath = "clip.mp4"\nwindow_size = 64\n{viewings}\n{extra}\n'
    )
    return m


def test_every_trace_option_is_a_manifest_key():
    assert TRACE_KEYS == tuple(o.key for o in TRACE_OPTIONS)
    assert set(VIEWING_TRACE_KEYS) == (set(TRACE_KEYS) - {"video"}) | {"trace_video"}


def test_traces_defaults_and_viewing_keys_reach_the_viewing(base):
    m = _write(base, "good", '[[viewings]]\nvideo = "clip"\ntrace = "sit.json"\n'
               'columns = "time=key,yaw=Ey,pitch=-Ex,roll=-Ez"\ndrop_zero_rows = true\n'
               'time_offset = -0.1\nrender = true\n'
               '[[viewings]]\nvideo = "clip"\ntrace = "short.csv"\nhold_last = true\nformat = "canonical"\n',
               f'[traces]\ntime_format = "{SIT_FORMAT}"\nallow_long_trace = true\n'
               '[render]\neye_size = "64x64"\n')  # fmt: skip
    with pytest.raises(InputError, match=r"\[traces\]: time_format = \.\.\. has no effect without"):
        load_manifest(m)  # a [traces] time_format needs a column map in [traces] too
    m.write_text(
        m.read_text().replace("[traces]\n", '[traces]\ncolumns = "time=key,yaw=Ey,pitch=-Ex"\n')
    )
    man = load_manifest(m)
    sit, short = man.viewings
    o = sit.trace_opts
    assert o.columns == "time=key,yaw=Ey,pitch=-Ex,roll=-Ez" and o.time_format == SIT_FORMAT
    assert o.drop_zero_rows and o.time_offset == -0.1 and o.allow_long_trace
    assert sit.render_opts["view"].get("hold_last") is not True
    # its own format replaces the [traces] column map and the keys that go with it
    assert short.trace_opts.hold_last and short.trace_opts.columns is None
    assert short.trace_opts.time_format is None and short.render_opts is None
    plan = dry_run(man, base / "o_good", cache_dir=base / "c")
    assert plan["problems"] == []  # short.csv held; the SIT log read through its map


BAD = {
    "columns-only key": ('[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\ntime_format = "%S"\n',
                         "time_format = ... has no effect without a column map; add columns = "),
    "scripted": ('[[viewings]]\nvideo = "clip"\nviewers = { n = 2 }\nhold_last = true\n',
                 "hold_last has no effect on scripted viewers"),
    "user with columns": (('[[viewings]]\nvideo = "clip"\ntrace = "sit.json"\ncolumns = "time=key,yaw=Ey,pitch=Ex"\n'
                          'time_format = "%S"\nuser = 2\n'), "user has no effect with a column map"),
    "trace_video on a csv": ('[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\ntrace_video = "6.mp4"\n',
                             "trace_video = '6.mp4' belongs on an AVTrack360 trace"),
    "unknown in traces": ('[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\n[traces]\nhold = true\n',
                          "[traces]: unknown key 'hold'"),
    "bad scale": ('[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\ntime_scale = 0\n',
                  "time_scale = 0: expected a number in (0.0, inf]"),
    "format and columns": (('[[viewings]]\nvideo = "clip"\ntrace = "sit.json"\nformat = "canonical"\n'
                           'columns = "time=key,yaw=Ey,pitch=Ex"\n'), "columns = ... and format = ... exclude"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_key_without_effect_is_refused_saying_where_it_belongs(case, base, tmp_path, capsys):
    text, want = BAD[case]
    m = _write(base, f"bad_{case.replace(' ', '_')}", text)
    out = tmp_path / "o"
    assert main(["study", str(m), "-o", str(out), "--cache-dir", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and want in err[0] and "--" not in err[0].split(": ", 2)[-1], err
    assert not out.exists()


def test_dry_run_errors_name_the_manifest_keys(base, tmp_path):
    m = _write(base, "dry", '[[viewings]]\nvideo = "clip"\ntrace = "short.csv"\n'
               '[[viewings]]\nvideo = "clip"\ntrace = "long.csv"\n')  # fmt: skip
    probs = dry_run(load_manifest(m), tmp_path / "o", cache_dir=tmp_path / "c")["problems"]
    short = next(p for p in probs if "short" in p)
    long_ = next(p for p in probs if "long" in p)
    assert "hold_last = true" in short and "--hold-last" not in short
    assert "span 370 s is implausible" in long_ and "time_scale = 0.001" in long_
    assert "allow_long_trace = true" in long_ and "--" not in long_
    m.write_text(m.read_text() + "\n[traces]\nhold_last = true\nallow_long_trace = true\n")
    plan = dry_run(load_manifest(m), tmp_path / "o", cache_dir=tmp_path / "c")
    assert plan["problems"] == []
    assert any("spans 370 s" in w for w in plan["warnings"]["clip-long"])


@pytest.mark.real_data
def test_avtrack360_error_says_the_manifest_key(base, real_dir, tmp_path):
    src = real_dir / "headtraces" / "avtrack360" / "Head_rotation" / "2.json"
    m = _write(base, "avt", f'[[viewings]]\nvideo = "clip"\ntrace = "{src}"\n')
    probs = dry_run(load_manifest(m), tmp_path / "o", cache_dir=tmp_path / "c")["problems"]
    assert len(probs) == 1 and "trace_video = ..." in probs[0] and "--video" not in probs[0], probs
    m.write_text(m.read_text().replace('trace = "', 'trace_video = "2.mp4"\ntrace = "'))
    # the viewing's choice reads the trace; the span of another video's trace then warns
    plan = dry_run(load_manifest(m), tmp_path / "o", cache_dir=tmp_path / "c")
    assert not [p for p in plan["problems"] if "video" in p and "choose" in p], plan["problems"]


def test_hold_last_of_a_viewing_reaches_its_render_view(base):
    m = _write(base, "held_render", '[[viewings]]\nvideo = "clip"\ntrace = "short.csv"\n'
               'hold_last = true\nrender = true\nid = "held"\n'
               '[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\nrender = true\nid = "free"\n',
               '[render]\neye_size = "64x64"\n')  # fmt: skip
    held, free = load_manifest(m).viewings
    assert held.render_opts["hold_last"] and held.render_opts["view"]["hold_last"] is True
    assert not free.render_opts["hold_last"] and "hold_last" not in free.render_opts["view"]
    from simulator.viewing.spec import ViewSpec

    assert ViewSpec.from_options(held.render_opts["view"]).hold is True


def test_a_traces_default_video_choice_is_not_refused_on_other_files(base, tmp_path):
    m = _write(
        base,
        "tv",
        '[[viewings]]\nvideo = "clip"\ntrace = "ok.csv"\n',
        '[traces]\nvideo = "6.mp4"\n',
    )
    assert load_manifest(m).viewings[0].trace_opts.video == "6.mp4"


@pytest.mark.slow
def test_hold_last_of_a_viewing_reaches_the_epof(base, tmp_path, capsys):
    m = _write(base, "run", '[[viewings]]\nvideo = "clip"\ntrace = "short.csv"\nid = "held"\n'
               'hold_last = true\n[[viewings]]\nvideo = "clip"\ntrace = "short.csv"\nid = "not"\n')  # fmt: skip
    out = tmp_path / "o"
    main(["study", str(m), "-o", str(out), "--cache-dir", str(base / "c"), "--workers", "1",
          "--no-progress"])  # fmt: skip
    capsys.readouterr()
    rows = {r["viewing"]: r for r in _csv(out / "viewings.csv")}
    assert rows["held"]["status"] == "ok" and (out / "epof" / "held.csv").is_file()
    assert (
        "hold_last = true" in rows["not"]["status"] and "--hold-last" not in rows["not"]["status"]
    )
    lines = [ln for ln in (out / "epof" / "held.csv").read_text().splitlines() if ln[0].isdigit()]
    assert len(lines) == 15 and np.isfinite([float(ln.split(",")[5]) for ln in lines]).all()


def _csv(p):
    import csv

    with open(p, newline="") as fh:
        return list(csv.DictReader(fh))
