"""The EPOF CSV's columns when everything is known: the fixed ones, the EPOF's parts,
coverage, then the artefact kind; read back with the parts and the kinds."""

from __future__ import annotations

import numpy as np

from simulator.epof.viewing import EPOF_COLUMNS, EpofResult, read_epof_csv, write_epof_csv


def test_column_order_parts_coverage_artefact(tmp_path):
    n = 4
    res = EpofResult(
        np.arange(n), np.arange(n) / 30.0, np.zeros(n), np.zeros(n), np.zeros(n),
        np.array([1.0, 2.0, 9.0, 3.0]), np.array([0.0, 0.5, 0.5, 1.0]),
        coverage=np.array([1.0, 0.9, 0.8, 1.0]),
        epof_rot_dps=np.array([0.5, 1.0, 4.0, 1.0]), epof_trans_dps=np.array([0.5, 1.0, 5.0, 2.0]),
        artefact=("", "", "keyframe", ""),
    )  # fmt: skip
    p = tmp_path / "e.csv"
    write_epof_csv(p, res, extra={"visible_flow_dps": np.ones(n)})
    header = next(ln for ln in p.read_text().splitlines() if not ln.startswith("#"))
    cols = header.split(",")
    assert cols[: len(EPOF_COLUMNS)] == list(EPOF_COLUMNS)
    rest = cols[len(EPOF_COLUMNS) :]
    assert rest[:2] == ["epof_rot_dps", "epof_trans_dps"] and rest[-1] == "artefact"
    assert rest.index("coverage") < rest.index("artefact")
    back = read_epof_csv(p)
    assert back.artefact == res.artefact
    np.testing.assert_allclose(back.epof_trans_dps, res.epof_trans_dps)
    np.testing.assert_allclose(back.epof_dps, res.epof_dps)
