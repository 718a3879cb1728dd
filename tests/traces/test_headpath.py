"""Head paths: HeadPath sampling, readers (real datasets), synth kinds, CLI, bad input."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.sphere.geometry import head_rotation
from simulator.traces.path import (
    CoarseSamplingWarning,
    HeadPath,
    RadiansWarning,
    save_headpath_csv,
    synth,
)
from simulator.traces.readers import detect_format, load_headpath, load_keyframes

HT = "headtraces"


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


# ------------------------------------------------------------------ HeadPath basics
def test_from_angles_roundtrip_and_shapes():
    t = np.linspace(0, 2, 21)
    hp = HeadPath.from_angles_deg(t, 30 * t, 10.0, -5.0, source="x")
    y, p, r = hp.angles_deg()
    assert y.shape == p.shape == r.shape == (21,)
    np.testing.assert_allclose(y, 30 * t, atol=1e-9)
    np.testing.assert_allclose(p, 10.0, atol=1e-9)
    np.testing.assert_allclose(r, -5.0, atol=1e-9)


def test_slerp_yaw_wraparound_takes_short_way():
    hp = HeadPath.from_angles_deg([0.0, 1.0], [170.0, -170.0], 0.0, 0.0)
    y, p, _ = hp.sample_angles_deg([0.5])
    assert abs(abs(y[0]) - 180.0) < 1e-6  # through the seam, not through 0
    assert abs(p[0]) < 1e-9


def test_sample_irregular_and_gap_is_great_arc():
    t = np.array([0.0, 0.013, 0.03, 0.3])  # irregular with a 0.27 s gap
    hp = HeadPath.from_angles_deg(t, [0, 1, 2, 20], 0, 0)
    y, _, _ = hp.sample_angles_deg([0.165])
    assert abs(y[0] - 11.0) < 1e-6  # linear in angle along the yaw arc


def test_sample_outside_raises_unless_hold():
    hp = HeadPath.from_angles_deg([0.0, 1.0], [0, 10], 0, 0, source="p.csv")
    with pytest.raises(InputError, match="hold"):
        hp.sample([1.5])
    y, _, _ = hp.sample_angles_deg([-1.0, 1.5], hold=True)
    np.testing.assert_allclose(y, [0, 10], atol=1e-9)


def test_check_covers_message():
    hp = HeadPath.from_angles_deg(np.linspace(0, 4.2, 10), 0, 0, 0, source="p.csv")
    with pytest.raises(
        InputError, match=r"p.csv ends at 4.200 s; video v.mp4 lasts 7.500 s.*--hold-last"
    ):
        hp.check_covers(7.5, video="v.mp4")
    hp.check_covers(7.5, hold=True)
    hp.check_covers(4.2)


@pytest.mark.parametrize("t", [[0.0, 0.0], [1.0, 0.5], [0.0, np.nan]])
def test_headpath_rejects_bad_times(t):
    with pytest.raises(InputError):
        HeadPath.from_angles_deg(t, 0, 0, 0)


def test_save_and_load_canonical(tmp_path):
    hp = synth("sine", 3.0, rate_hz=20)
    p = tmp_path / "s.csv"
    save_headpath_csv(p, hp)
    assert p.read_text().splitlines()[0] == "time_s,yaw_deg,pitch_deg,roll_deg"
    back = load_headpath(p)
    assert (back.rotations.inv() * hp.rotations).magnitude().max() < 1e-7
    np.testing.assert_allclose(back.times_s, hp.times_s)


def test_quat_csv_matches_head_rotation(tmp_path):
    t = np.array([0.0, 0.5, 1.0])
    yaw, pitch, roll = (
        np.array([10, -100, 170.0]),
        np.array([20, -45, 80.0]),
        np.array([5, 0, -30.0]),
    )
    q = head_rotation(yaw, pitch, roll).as_quat()  # x, y, z, w
    rows = "\n".join(f"{ti},{qq[3]},{qq[0]},{qq[1]},{qq[2]}" for ti, qq in zip(t, q))
    p = _write(tmp_path, "q.csv", "time_s,qw,qx,qy,qz\n" + rows + "\n")
    assert detect_format(p) == "quat"
    y, pi, r = load_headpath(p).angles_deg()
    np.testing.assert_allclose(y, yaw, atol=1e-6)
    np.testing.assert_allclose(pi, pitch, atol=1e-6)
    np.testing.assert_allclose(r, roll, atol=1e-6)


# ------------------------------------------------------------------ synth
def test_synth_kinds(tmp_path):
    st = synth("static", 2.0, rate_hz=10, pitch=-70)
    assert st.n == 21 and np.allclose(st.angles_deg()[1], -70)
    sw = synth("sweep", 4.0, rate_hz=10, yaw_rate=30)
    sp = sw.angular_speed_dps()
    np.testing.assert_allclose(sp, 30.0, rtol=1e-6)
    si = synth("sine", 10.0, rate_hz=50, yaw_amp=40, yaw_freq=0.2)
    assert abs(np.max(si.angles_deg()[0]) - 40) < 0.1
    kf = _write(
        tmp_path,
        "k.json",
        json.dumps(
            [
                {"time_s": 0, "yaw_deg": 0, "pitch_deg": 0},
                {"time_s": 2, "yaw_deg": 90, "pitch_deg": 0},
            ]
        ),
    )
    k = synth("keyframes", 0, rate_hz=10, keyframes=load_keyframes(kf))
    assert k.end_s == pytest.approx(2.0)
    assert k.sample_angles_deg([1.0])[0][0] == pytest.approx(45.0)


def test_look_around_seeded_and_realistic():
    a = synth("look-around", 60.0, rate_hz=30, seed=3)
    b = synth("look-around", 60.0, rate_hz=30, seed=3)
    c = synth("look-around", 60.0, rate_hz=30, seed=4)
    assert np.array_equal(a.rotations.as_quat(), b.rotations.as_quat())
    assert not np.allclose(a.rotations.as_quat(), c.rotations.as_quat())
    r = a.resample(np.arange(0, 60, 0.1))
    sp = r.angular_speed_dps()
    # Real viewers (bench/headtrace_stats.py, pooled, 10 Hz): median 11 deg/s, p90 57.
    assert 4 < np.median(sp) < 25
    assert 30 < np.percentile(sp, 90) < 100
    assert np.mean(np.abs(r.angles_deg()[1]) <= 30) > 0.7


# ------------------------------------------------------------------ real datasets
def test_corbillon_quaternion_matches_euler_file(real_dir):
    d = real_dir / HT / "corbillon_mmsys18_multiviewpoint"
    q = load_headpath(d / "user1_quaternion.txt")
    e = load_headpath(d / "user1_euler.txt")
    assert detect_format(d / "user1_quaternion.txt") == "corbillon"
    assert detect_format(d / "user1_euler.txt") == "corbillon-euler"
    np.testing.assert_array_equal(q.times_s, e.times_s)
    assert np.degrees((q.rotations.inv() * e.rotations).magnitude()).max() < 1e-6
    # SOURCES.md: the euler column named 'pitch' is the azimuth atan2(f_y, f_x) = our yaw.
    raw = np.loadtxt(d / "user1_euler.txt", skiprows=1)
    yaw, pitch, _ = q.angles_deg()
    dy = (yaw - np.degrees(raw[:, 3]) + 180) % 360 - 180
    assert np.median(np.abs(dy)) < 0.5
    # ... and the head stays near upright with |pitch| mostly small.
    assert np.mean(np.abs(pitch) <= 30) > 0.9


def test_corbillon_forward_is_first_column(real_dir):
    p = real_dir / HT / "corbillon_mmsys18_multiviewpoint" / "user2_quaternion.txt"
    raw = np.loadtxt(p, skiprows=1)
    hp = load_headpath(p)
    f = Rotation.from_quat(raw[:, [3, 4, 5, 2]]).as_matrix()[:, :, 0]
    yaw, pitch, _ = hp.angles_deg()
    np.testing.assert_allclose(yaw, np.degrees(np.arctan2(f[:, 1], f[:, 0])), atol=1e-6)
    np.testing.assert_allclose(pitch, np.degrees(np.arcsin(f[:, 2])), atol=1e-6)


def test_salient360_dyn_fused_columns_and_signs(real_dir):
    p = real_dir / HT / "salient360_toolbox_raw" / "rawDataDyn1.csv"
    assert detect_format(p) == "salient360-dyn"
    hp = load_headpath(p)
    assert 1800 < hp.n < 1900  # one row per head update (unityTS), not per eye sample
    assert hp.end_s == pytest.approx(20.586, abs=0.01)
    rows = [ln.split(",") for ln in p.read_text().splitlines()[1:]]
    assert len(rows[0]) == 29 and rows[0][27].endswith("True")  # the fused field is there
    cp, cy, cr, sy = (float(rows[0][i]) for i in (7, 8, 9, 10))
    y, pi, r = hp.angles_deg()
    assert pi[0] == pytest.approx(-((cp + 180) % 360 - 180), abs=1e-6)  # Unity + = down
    assert r[0] == pytest.approx(-((cr + 180) % 360 - 180), abs=1e-6)
    assert y[0] == pytest.approx((cy - sy + 180) % 360 - 180, abs=1e-6)


def test_salient360_static_forward(real_dir):
    p = real_dir / HT / "salient360_toolbox_raw" / "rawDataStatic1.csv"
    assert detect_format(p) == "salient360-static"
    hp = load_headpath(p)
    q = np.array([float(v) for v in p.read_text().splitlines()[1].split(",")[9:13]])
    f = Rotation.from_quat(q).apply([0, 0, 1.0])
    y, pi, _ = hp.angles_deg()
    assert y[0] == pytest.approx(np.degrees(np.arctan2(f[0], f[2])), abs=1e-6)
    assert pi[0] == pytest.approx(np.degrees(np.arcsin(f[1])), abs=1e-6)


def test_avtrack360_signs_and_video_choice(real_dir):
    p = real_dir / HT / "avtrack360" / "Head_rotation" / "2.json"
    assert detect_format(p) == "avtrack360"
    with pytest.raises(InputError, match="--video.*6.mp4"):
        load_headpath(p)
    with pytest.raises(InputError, match="available"):
        load_headpath(p, video="99.mp4")
    hp = load_headpath(p, video="6")
    raw = json.loads(p.read_text())["data"]
    s = next(e for e in raw if e["filename"] == "6.mp4")["pitch_yaw_roll_data_hmd"]
    y, pi, _r = hp.angles_deg()
    k = int(np.argmax([abs(x["pitch"]) for x in s]))  # a sample looking clearly up or down
    assert pi[k] == pytest.approx(-s[k]["pitch"], abs=1e-6)  # their pitch + = down
    j = int(np.argmax([abs(x["yaw"]) if abs(x["yaw"]) < 170 else 0 for x in s]))
    assert np.sign(y[j]) == np.sign(s[j]["yaw"])  # their yaw + = right, as ours
    assert hp.start_s == pytest.approx(s[0]["sec"])


def test_360vidstr_user_and_short_lines(real_dir):
    p = real_dir / HT / "aggregated_360vidstr" / "AggregatedDataset" / "0.txt"
    assert detect_format(p) == "360vidstr"
    with pytest.raises(InputError, match="--user 1..58"):
        load_headpath(p)
    lines = p.read_text().splitlines()
    hp = load_headpath(p, user=2)
    n = min(len(lines[3].split()), len(lines[4].split()))
    assert hp.n == n  # the user's lines are shorter than the time line
    assert len(lines[0].split()) > n
    _y, pi, _ = hp.angles_deg()
    assert pi[5] == pytest.approx(np.degrees(float(lines[3].split()[5])), abs=1e-6)


def test_cli_convert_and_show(real_dir, tmp_path, capsys):
    src = real_dir / HT / "avtrack360" / "Head_rotation" / "3.json"
    out = tmp_path / "a.csv"
    assert main(["headpath", "convert", str(src), "-o", str(out), "--video", "1.mp4"]) == 0
    assert load_headpath(out).n > 250
    png = tmp_path / "a.png"
    assert main(["headpath", "show", str(out), "-o", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert (
        main(["headpath", "synth", "look-around", "-o", str(tmp_path / "l.csv"), "--seconds", "3"])
        == 0
    )
    assert load_headpath(tmp_path / "l.csv").end_s == pytest.approx(3.0)


# ------------------------------------------------------------------ bad input
BAD = {
    "empty.csv": ("", "empty"),
    "header.csv": ("time_s,yaw_deg,pitch_deg,roll_deg\n", "no data rows"),
    "cols.csv": ("t,yaw,pitch\n0,1,2\n", "expected a CSV with header time_s,yaw_deg,pitch_deg.* e.g. --columns time=t,yaw=yaw,pitch=pitch "),
    "miss.csv": ("time_s,yaw_deg\n0,1\n", r"expected time_s,yaw_deg,pitch_deg,roll_deg \(missing"),
    "extra.csv": ("time_s,yaw_deg,pitch_deg,roll_deg,foo\n0,1,2,3,4\n", "unknown"),
    "nan.csv": (
        "time_s,yaw_deg,pitch_deg,roll_deg\n0,1,2,3\n1,nan,2,3\n",
        "line 3: yaw_deg is nan",
    ),
    "inf.csv": ("time_s,yaw_deg,pitch_deg,roll_deg\n0,1,2,3\n1,1,inf,3\n", "pitch_deg is inf"),
    "order.csv": (
        "time_s,yaw_deg,pitch_deg,roll_deg\n0,1,2,3\n2,1,2,3\n1,1,2,3\n",
        "not strictly increasing at line 4",
    ),
    "text.csv": ("time_s,yaw_deg,pitch_deg,roll_deg\n0,a,2,3\n", "non-numeric"),
    "zeroq.csv": ("time_s,qw,qx,qy,qz\n0,1,0,0,0\n1,0,0,0,0\n", "zero length"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_files_one_line_exit_2(tmp_path, capsys, name):
    text, msg = BAD[name]
    p = _write(tmp_path, name, text)
    with pytest.raises(InputError, match=msg):
        load_headpath(p)
    out = tmp_path / "out.csv"
    assert main(["headpath", "convert", str(p), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(p) in err
    assert not out.exists()


def test_radians_warning(tmp_path, capsys):
    # strong evidence: 20 samples all within +-2*pi, yaw sweeping 5.6 units (radians: 320 deg)
    rows = "".join(
        f"{k * 0.1:.1f},{-2.8 + k * 0.3:.2f},{0.2 * (-1) ** k:.1f},0\n" for k in range(20)
    )
    p = _write(tmp_path, "rad.csv", "time_s,yaw_deg,pitch_deg,roll_deg\n" + rows)
    with pytest.warns(RadiansWarning, match="RADIANS"):
        load_headpath(p)
    assert main(["headpath", "convert", str(p), "-o", str(tmp_path / "o.csv")]) == 0
    assert "warning" in capsys.readouterr().err
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_headpath(_write(tmp_path, "deg.csv", "time_s,yaw_deg,pitch_deg\n0,10,5\n1,40,-20\n"))
        # small degree values of a still viewer are not evidence of radians
        load_headpath(
            _write(tmp_path, "small.csv", "time_s,yaw_deg,pitch_deg\n0,0.5,0.2\n1,1.5,-0.3\n")
        )


# ------------------------------------------------------------------ review fixes
def test_synth_refuses_sampling_that_turns_the_wrong_way(tmp_path, capsys):
    # yaw 0, 200, 400, 600 would be written as 0, -160, 40, -120: Slerp turns left.
    with pytest.raises(InputError, match=r"200 deg between two samples.*raise --rate above 1.11"):
        synth("sweep", 3.0, rate_hz=1, yaw_rate=200)
    with pytest.raises(InputError, match="raise --rate"):
        synth("sweep", 3.0, rate_hz=1, yaw_rate=-180)
    with pytest.raises(InputError, match="raise --rate"):  # samples all at sin(k pi) = 0
        synth("sine", 3.0, rate_hz=1, yaw_amp=170, yaw_freq=0.5)
    ok = synth("sweep", 3.0, rate_hz=2, yaw_rate=200)  # 100 deg steps: still the short way
    y = np.unwrap(np.radians(ok.sample_angles_deg(np.linspace(0, 3, 61))[0]))
    assert np.all(np.diff(y) > 0)
    out = tmp_path / "s.csv"
    args = ["headpath", "synth", "sweep", "-o", str(out), "--seconds", "3", "--rate", "1"]
    assert main([*args, "--yaw-rate", "200"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--rate" in err and not out.exists()


@pytest.mark.parametrize(
    "extra, msg",
    [
        (["look-around", "--seconds", "1", "--seed", "-1"], "--seed: expected an integer >= 0"),
        (["sweep", "--seconds", "1e308"], "samples; at most 10,000,000"),
        (["sweep", "--seconds", "1e7", "--rate", "1000"], "1e\\+10 samples; at most"),
    ],
)
def test_synth_cli_bad_numbers_one_line_exit_2(tmp_path, capsys, extra, msg):
    out = tmp_path / "s.csv"
    try:
        rc = main(["headpath", "synth", extra[0], "-o", str(out), *extra[1:]])
    except SystemExit as e:  # usage errors exit from argparse
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert re.search(msg, err), err
    assert not out.exists()


def test_synth_api_refuses_negative_seed_and_too_many_samples(tmp_path):
    with pytest.raises(InputError, match="seed"):
        synth("look-around", 1.0, seed=-1)
    with pytest.raises(InputError, match="at most"):
        synth("static", 1e308)
    kf = _write(tmp_path, "k.csv", "time_s,yaw_deg,pitch_deg\n0,0,0\n1,10,0\n")
    with pytest.raises(InputError, match="at most"):
        synth("keyframes", 1e9, rate_hz=100, keyframes=load_keyframes(kf))


def test_loaders_warn_when_poses_are_more_than_90_deg_apart(tmp_path, capsys):
    p = _write(tmp_path, "c.csv", "time_s,yaw_deg,pitch_deg\n0,0,0\n1,-160,0\n2,40,0\n")
    with pytest.warns(CoarseSamplingWarning, match="sampling too coarse; interpolation takes"):
        load_headpath(p)
    assert main(["headpath", "convert", str(p), "-o", str(tmp_path / "o.csv")]) == 0
    err = capsys.readouterr().err
    assert "vimsim headpath: warning:" in err and "differ by 160 deg (2 such steps)" in err
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_headpath(_write(tmp_path, "f.csv", "time_s,yaw_deg,pitch_deg\n0,0,0\n1,89,0\n"))


def _avtrack(tmp_path, samples, key="pitch_yaw_roll_data_hmd"):
    entry = {"filename": "1.mp4", key: samples}
    return _write(tmp_path, "av.json", json.dumps({"data": [entry]}))


def test_avtrack360_entry_without_samples_is_one_line(tmp_path, capsys):
    one = {
        "filename": "1.mp4",
        "pitch_yaw_roll_data_hmd": [{"sec": 0, "yaw": 0, "pitch": 0, "roll": 0}],
    }
    p = _write(tmp_path, "av.json", json.dumps({"data": [one, {"filename": "2.mp4", "x": []}]}))
    out = tmp_path / "o.csv"
    args = ["headpath", "convert", str(p), "-o", str(out), "--format", "avtrack360"]
    assert main([*args, "--video", "2.mp4"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(p) in err and "2.mp4" in err
    assert "pitch_yaw_roll_data_hmd" in err and not out.exists()


def test_avtrack360_errors_name_1_based_samples_after_dedupe(tmp_path):
    s = [{"sec": t, "yaw": 0, "pitch": 0, "roll": 0} for t in (0.1, 0.1, 0.2, 0.3, 0.25)]
    p = _avtrack(tmp_path, s)
    # samples 1 and 2 share a time (2 is dropped); sample 5 goes back in time
    with pytest.raises(
        InputError, match=r"video 1.mp4: time is not strictly increasing at sample 5 "
    ):
        load_headpath(p, "avtrack360")
    s[3]["yaw"] = float("nan")
    p.write_text(json.dumps({"data": [{"filename": "1.mp4", "pitch_yaw_roll_data_hmd": s}]}))
    with pytest.raises(InputError, match="sample 4: yaw is nan"):
        load_headpath(p, "avtrack360")
