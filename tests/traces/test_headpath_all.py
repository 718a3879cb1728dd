"""``load_all_users`` and ``vimsim headpath convert FILE --user all -o DIR``: every user of a
multi-user file (360VidStr aggregated), read once, equal to converting them one by one."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.traces.readers import load_all_users, load_headpath


@pytest.fixture(scope="module")
def vidstr(real_dir):
    return real_dir / "headtraces" / "aggregated_360vidstr" / "AggregatedDataset" / "0.txt"


def test_load_all_users_equals_one_by_one(vidstr):
    users = load_all_users(vidstr)
    assert sorted(users) == list(range(1, 59))  # 0.txt: 58 users (SOURCES.md)
    for u in (1, 17, 58):
        one = load_headpath(vidstr, user=u)
        np.testing.assert_array_equal(users[u].times_s, one.times_s)
        np.testing.assert_allclose(users[u].rotations.as_quat(), one.rotations.as_quat())
    # Users' lines are shorter than the time line in 0.txt (600..810 samples).
    assert {users[u].n for u in users} >= {600, 810}


def test_load_all_users_single_trace_file(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("time_s,yaw_deg,pitch_deg,roll_deg\n0,0,0,0\n1,10,0,0\n")
    users = load_all_users(p)
    assert list(users) == [1] and users[1].n == 2


def test_convert_all_cli(vidstr, tmp_path, capsys):
    out = tmp_path / "users"
    assert main(["headpath", "convert", str(vidstr), "--user", "all", "-o", str(out)]) == 0
    files = sorted(out.glob("*.csv"))
    assert len(files) == 58 and files[0].name == "0_user01.csv"
    single = tmp_path / "u17.csv"
    assert main(["headpath", "convert", str(vidstr), "--user", "17", "-o", str(single)]) == 0
    assert (out / "0_user17.csv").read_bytes() == single.read_bytes()


def test_convert_all_refuses_file_output_and_bad_user(vidstr, tmp_path, capsys):
    f = tmp_path / "x.csv"
    f.write_text("keep\n")
    assert main(["headpath", "convert", str(vidstr), "--user", "all", "-o", str(f)]) == 2
    assert f.read_text() == "keep\n"
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "existing file" in err[0]
    with pytest.raises(SystemExit) as e:
        main(["epof", "g.npz", str(vidstr), "-o", "e.csv", "--user", "all"])
    assert e.value.code == 2


def test_load_all_users_bad_file(tmp_path):
    p = tmp_path / "bad.txt"
    p.write_text("0 0.1 0.2\n0 0\n")  # 2 lines: not 2n+1
    with pytest.raises(InputError, match="2n\\+1"):
        load_all_users(p, "360vidstr")
