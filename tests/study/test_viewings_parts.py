"""viewings.csv gains the means of the EPOF's rotational and translational parts (simulator/study/outputs.py)."""

from __future__ import annotations

import csv

import numpy as np

from simulator.epof.viewing import EpofResult, write_epof_csv
from simulator.study.outputs import PART_MEAN_COLUMNS, write_viewings_csv


def test_viewings_csv_has_part_means(tmp_path):
    (tmp_path / "epof").mkdir()
    n = 4
    z = np.zeros(n)
    rot, trans = np.array([1.0, 2.0, 3.0, 4.0]), np.array([0.5, 0.5, 1.5, 1.5])
    res = EpofResult(np.arange(n), z, z, z, z, rot + trans, z, epof_rot_dps=rot, epof_trans_dps=trans)
    write_epof_csv(tmp_path / "epof" / "a.csv", res)
    write_epof_csv(tmp_path / "epof" / "b.csv", EpofResult(np.arange(n), z, z, z, z, z, z))
    rows = [{"viewing": v, "status": "ok"} for v in ("a", "b")] + [{"viewing": "c", "status": "x"}]
    write_viewings_csv(tmp_path / "viewings.csv", rows, ("viewing", "status"))
    got = list(csv.DictReader((tmp_path / "viewings.csv").open()))
    assert list(got[0]) == ["viewing", "status", *PART_MEAN_COLUMNS]
    assert float(got[0]["epof_rot_mean_dps"]) == 2.5 and float(got[0]["epof_trans_mean_dps"]) == 1.0
    assert got[1]["epof_rot_mean_dps"] == "" and got[2]["epof_trans_mean_dps"] == ""
