"""Lab logs: JSON keyed by timestamps (SIT-VR shape), clock times, skipped and zero rows."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.traces.readers import load_columns
from simulator.traces.readers.columns import ClockTimeWarning

SIT_FORMAT = "%Y%m%dZ-%H%M%S_%fZ"
SIT_MAP = "time=key,yaw=HMD.rot.y,pitch=-HMD.rot.x,roll=-HMD.rot.z"


def sit_log(path, n=40):
    """A SIT-VR-shaped log: keys like 20210510Z-200400_686Z (every 50 ms), Unity Euler
    degrees in [0, 360), the first sample all zero (before the headset reports)."""
    log = {}
    for k in range(n):
        ms = 686 + 50 * k
        key = f"20210510Z-2004{ms // 1000:02d}_{ms % 1000:03d}Z"
        yaw = (3.0 * k) % 360.0 if k else 0.0
        x = (360.0 - 2.0 * k) % 360.0 if k else 0.0  # Unity x + down: looks up by 2 deg/step
        log[key] = {"HMD": {"rot": {"x": x, "y": (yaw - 10.0) % 360.0 if k else 0.0, "z": 0.0}},
                    "scene": "sandwich"}  # fmt: skip
    path.write_text(json.dumps(log, indent=1))
    return path


def test_sit_json_log_times_from_keys_first_zero_dropped(tmp_path):
    p = sit_log(tmp_path / "sit.json")
    hp = load_columns(p, SIT_MAP, time_format=SIT_FORMAT, drop_zero_rows=True)
    assert hp.n == 39  # the zero sample is gone
    assert np.allclose(hp.times_s, 0.05 * np.arange(39), atol=1e-9)  # from the keys
    y, pi, r = hp.sample_angles_deg(hp.times_s)
    k = np.arange(1, 40)
    assert np.allclose(y, 3.0 * k - 10.0, atol=1e-6)  # 350 deg -> -10
    assert np.allclose(pi, 2.0 * k, atol=1e-6)
    assert np.allclose(r, 0.0, atol=1e-6)


def test_skip_rows_and_zero_rows_in_a_csv(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("t,y,x\n0,5,5\n0.1,0,0\n0.2,10,0\n0.3,20,0\n")
    hp = load_columns(p, "time=t,yaw=y,pitch=x", skip_rows=1, drop_zero_rows=True)
    assert np.allclose(hp.times_s, [0.2, 0.3])


def test_clock_timestamps_warn(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("t,y,x\n" + "".join(f"{1620676800 + k * 0.1:.1f},{k},0\n" for k in range(5)))
    with pytest.warns(ClockTimeWarning, match="--time-from-first"):
        load_columns(p, "time=t,yaw=y,pitch=x")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        hp = load_columns(p, "time=t,yaw=y,pitch=x", time_from_first=True)
    assert hp.times_s[0] == 0.0


def test_bad_time_format_names_the_entry(tmp_path):
    p = sit_log(tmp_path / "sit.json", n=3)
    with pytest.raises(InputError, match=r"entry 1: time .* does not match --time-format"):
        load_columns(p, SIT_MAP, time_format="%H:%M:%S")


def test_cli_convert_and_epof_take_the_column_map(tmp_path, capsys):
    p = sit_log(tmp_path / "sit.json")
    out = tmp_path / "path.csv"
    args = ["--columns", SIT_MAP, "--time-format", SIT_FORMAT, "--drop-zero-rows"]
    assert main(["headpath", "convert", str(p), "-o", str(out), *args]) == 0
    assert out.read_text().count("\n") == 40  # header + 39 samples
    bad = tmp_path / "bad.csv"
    assert main(["headpath", "convert", str(p), "-o", str(bad), "--columns", SIT_MAP,
                 "--time-format", "%Y"]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "does not match --time-format" in err and err.count("\n") == 1
    assert not bad.exists()
    from simulator.cli import build_parser
    from simulator.commands.headpath import load_headpath_args

    for cmd in (["epof", "g.npz", str(p), "-o", "e.csv"], ["render", "v.mp4", str(p), "-o", "d"]):
        ns = build_parser().parse_args([*cmd, *args])
        assert ns.columns == SIT_MAP and ns.time_format == SIT_FORMAT and ns.drop_zero_rows
        assert load_headpath_args(ns, str(p), "vimsim x").n == 39
    from simulator.commands.render import view_from_args

    # render and frames read the head path through the same column options
    for cmd in ("render", "frames"):
        ns = build_parser().parse_args([cmd, "v.mp4", str(p), "-o", "d", "--at", "1", *args]
                                       if cmd == "frames" else [cmd, "v.mp4", str(p), "-o", "d",
                                                                *args])  # fmt: skip
        assert view_from_args(ns, cmd)[0].n == 39


def real_sit_log(path, n=40):
    """The real SIT-VR Unity log's shape: one wrapper key over time-keyed samples of flat
    Unity fields (Ex, Ey, Ez Euler degrees; Rx.. and Px.. other channels)."""
    log = {}
    for k in range(n):
        ms = 686 + 50 * k
        key = f"20210510Z-2004{ms // 1000:02d}_{ms % 1000:03d}Z"
        e = (360.0 - 2.0 * k) % 360.0 if k else 0.0, (3.0 * k) % 360.0 if k else 0.0, 0.0
        log[key] = {"Ex": e[0], "Ey": e[1], "Ez": e[2], "Rx": 0.1, "Ry": 0.2, "Rz": 0.3,
                    "Px": 0.0, "Py": 1.6, "Pz": 0.0}  # fmt: skip
    path.write_text(json.dumps({"1-SubheadPosition": log}))
    return path


REAL_SIT_MAP = "time=key,yaw=Ey,pitch=-Ex,roll=-Ez"


def test_real_sit_shape_descends_the_wrapper_key(tmp_path, capsys):
    p = real_sit_log(tmp_path / "sit.json")
    out = tmp_path / "path.csv"
    args = ["--columns", REAL_SIT_MAP, "--time-format", SIT_FORMAT, "--drop-zero-rows"]
    assert main(["headpath", "convert", str(p), "-o", str(out), *args]) == 0
    hp = load_columns(p, REAL_SIT_MAP, time_format=SIT_FORMAT, drop_zero_rows=True)
    y, pitch, _ = hp.angles_deg()
    assert hp.n == 39 and hp.times_s[-1] == pytest.approx(1.9)
    assert y[-1] == pytest.approx(3.0 * 39) and pitch[-1] == pytest.approx(2.0 * 39)
    # a single sample (its values are not objects) is not a wrapper: nothing descended
    one = tmp_path / "one.json"
    one.write_text(json.dumps({"20210510Z-200400_686Z": {"Ex": 1.0, "Ey": 2.0, "Ez": 0.0}}))
    assert load_columns(one, REAL_SIT_MAP, time_format=SIT_FORMAT).n == 1


def test_unknown_column_lists_the_closest_fields_of_one_sample(tmp_path):
    p = real_sit_log(tmp_path / "sit.json")
    with pytest.raises(InputError) as e:
        load_columns(p, "time=key,yaw=EY,pitch=-Ex", time_format=SIT_FORMAT)
    msg = str(e.value)
    assert "no column 'EY'" in msg and "closest fields of one sample" in msg
    assert "'Ey'" in msg and "13357" not in msg and len(msg.splitlines()) == 1
    with pytest.raises(InputError, match=r"none of the 10 fields of one sample \(entry 1\) is close$"):
        load_columns(p, "time=key,yaw=qqqqqq,pitch=-Ex", time_format=SIT_FORMAT)  # names kept


def test_every_auto_detect_failure_shows_a_columns_example(tmp_path, capsys):
    sit = real_sit_log(tmp_path / "sit.json")
    txt = tmp_path / "log.txt"
    txt.write_text("stamp;head_yaw;head_pitch;head_roll\n0;1;2;3\n1;2;3;4\n")
    expect = {sit: "--columns time=key,yaw=Ey,pitch=Ex,roll=Ez --time-format FMT",
              txt: "--columns time=stamp,yaw=head_yaw,pitch=head_pitch,roll=head_roll"}  # fmt: skip
    for src, example in expect.items():
        assert main(["headpath", "convert", str(src), "-o", str(tmp_path / "o.csv")]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and example in err, err
        assert not (tmp_path / "o.csv").exists()
    # the example, copied with its signs and time format filled in, reads the file
    assert main(["headpath", "convert", str(sit), "-o", str(tmp_path / "o.csv"), "--columns",
                 REAL_SIT_MAP, "--time-format", SIT_FORMAT, "--drop-zero-rows"]) == 0  # fmt: skip
