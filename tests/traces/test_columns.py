"""headpath convert --columns: any lab's head log through a column map."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.core.errors import InputError
from simulator.traces.readers import load_columns, load_headpath, parse_column_map


def test_parse_column_map():
    m = parse_column_map("time=t, yaw=Y,pitch=-X")
    assert m == {"time": ("t", 1.0), "yaw": ("Y", 1.0), "pitch": ("X", -1.0)}
    for bad in (
        "time=t,yaw=a",
        "time=t,yaw=a,pitch=b,tilt=c",
        "time=-t,yaw=a,pitch=b",
        "time=t,yaw=a,yaw=b,pitch=c",
    ):
        with pytest.raises(InputError, match="--columns"):
            parse_column_map(bad)


def test_ms_radians_wrap_and_sign(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("ms;az;el;tilt\n0;0;0;0\n500;4.71238898;-0.5;6.0\n1000;3.0;0.1;0.2\n")
    hp = load_columns(p, "time=ms,yaw=az,pitch=-el,roll=tilt", angles="rad", time_scale=0.001)
    assert np.allclose(hp.times_s, [0, 0.5, 1.0])
    y, pi, r = hp.sample_angles_deg(hp.times_s)
    assert np.allclose(y, [0, -90, np.degrees(3.0)], atol=1e-6)  # 270 deg -> -90
    assert np.allclose(pi, [0, np.degrees(0.5), -np.degrees(0.1)], atol=1e-6)
    assert np.allclose(r, [0, np.degrees(6.0) - 360, np.degrees(0.2)], atol=1e-6)


def test_unity_log_forward_matches_unity_formula(real_dir):
    """Salient360 raw (Unity eulerAngles, [0, 360), pitch + down, roll + left ear down):
    with a column map only, the forward vector equals Unity's own
    Quaternion.Euler(x, y, z) * Vector3.forward = (sin y cos x, -sin x, cos y cos x)."""
    f = real_dir / "headtraces" / "salient360_toolbox_raw" / "rawDataDyn1.csv"
    hp = load_columns(f, "time=unityTS,yaw=cam_yaw,pitch=-cam_pitch,roll=-cam_roll",
                      time_scale=0.001, time_from_first=True)  # fmt: skip
    lines = f.read_text().splitlines()
    cols = lines[0].split(",")
    ix = [cols.index(c) for c in ("unityTS", "cam_pitch", "cam_yaw", "cam_roll", "sphere_yaw")]
    raw = np.array([[float(ln.split(",")[i]) for i in ix] for ln in lines[1:]])
    _, first = np.unique(raw[:, 0], return_index=True)
    raw = raw[np.sort(first)]
    assert hp.n == len(raw) and hp.n > 1000
    x, y = np.radians(raw[:, 1]), np.radians(raw[:, 2])
    want = np.stack([np.sin(y) * np.cos(x), -np.sin(x), np.cos(y) * np.cos(x)], -1)
    got = hp.rotations.apply([0.0, 0.0, 1.0])
    assert np.abs(got - want).max() < 1e-9
    # and the whole pose (roll included) is the dedicated reader's before its sphere_yaw offset
    from scipy.spatial.transform import Rotation

    ref = load_headpath(f, "salient360-dyn")
    undo = Rotation.from_euler("Y", raw[:, 4:5], degrees=True) * ref.rotations
    assert np.degrees((undo.inv() * hp.rotations).magnitude()).max() < 1e-6


def test_errors_name_the_column(tmp_path, capsys):
    from simulator.cli import main

    p = tmp_path / "log.csv"
    p.write_text("t,yaw,pitch\n0,1,2\n1,x,3\n")
    out = tmp_path / "o.csv"

    def convert(columns: str) -> int:
        return main(["headpath", "convert", str(p), "-o", str(out), "--columns", columns])

    assert convert("time=t,yaw=yaw,pitch=elev") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'elev'" in err and "none of the 3 fields of one sample" in err
    assert "t, yaw, pitch" not in err  # the header is not echoed (docs/reliability.md)
    assert convert("time=t,yaw=yaw,pitch=pitch") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "line 3" in err and "'yaw'" in err and "non-numeric" in err
    assert not out.exists()
    p.write_text("t,yaw,pitch\n0,350,2\n1,10,3\n")
    assert convert("time=t,yaw=yaw,pitch=pitch") == 0
    rows = out.read_text().splitlines()
    assert rows[0] == "time_s,yaw_deg,pitch_deg,roll_deg" and float(
        rows[1].split(",")[1]
    ) == pytest.approx(-10)
