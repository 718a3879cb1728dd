"""One viewing as the authors' Unity runtime computes it (``--preset cao2021-code``): the nearest window's flow with their list indexing, and the fixed px/frame opacity.

The rule itself is :mod:`simulator.mitigation.cao2021`; here a head path is sampled at every
video frame of a grid (as :func:`simulator.epof.viewing.compute_epof` does) and the result
is an :class:`~simulator.epof.viewing.EpofResult`: ``opacity`` from the nearest window's
``pof_px`` (px/frame, the unit of their scale), ``epof_dps`` the same window and row of
``pof_dps`` (deg/s, for comparison with vimsim's EPOF), and :data:`FLOW_PX_COLUMN` the
px/frame value the opacity came from. Head angles in degrees (yaw + right, pitch + up).
"""

from __future__ import annotations

import math

import numpy as np

from simulator.core.errors import InputError
from simulator.epof.viewing import EpofResult, _select_frames
from simulator.media.gridfile import GridFile
from simulator.media.spherical import view_angles_deg
from simulator.mitigation.cao2021 import FixedPxRule, nearest_flow
from simulator.traces.path import HeadPath

__all__ = ["FLOW_PX_COLUMN", "grid_px_rule", "nearest_epof", "preset_pof_px"]

#: The extra EPOF CSV column of the preset: the nearest window's flow, window px/frame.
FLOW_PX_COLUMN = "flow_px"


def preset_pof_px(grid: GridFile):
    """The ``pof_px`` the preset reads: the grid's, with row 0 replaced by the authors'
    frame-0 defect (``meta["cao"]["row0_px"]``, :mod:`simulator.preprocess.cao2021`) when
    the grid was preprocessed on the ``cao2021`` grid; as stored otherwise (an imported
    folder holds their own row 0)."""
    row0 = (grid.meta.get("cao") or {}).get("row0_px")
    pof = grid.pof_px
    if row0 is None:
        return pof
    row0 = np.asarray(row0, np.float32)
    if row0.shape != pof.shape[1:] or not np.all(np.isfinite(row0)) or row0.min() < 0:
        raise InputError(
            f"{grid.path or 'grid'}: meta cao.row0_px must be finite >= 0, {pof.shape[1:]}"
        )
    out = np.array(pof)
    out[0] = row0
    return out


def grid_px_rule(grid: GridFile) -> FixedPxRule:
    """The preset's fixed px/frame scale for ``grid``: an imported percentile file's two
    numbers (``meta["cao"]["percentiles_px"]``, ``vimsim grid import``), else the authors'
    0.18..53.73."""
    pct = (grid.meta.get("cao") or {}).get("percentiles_px")
    return FixedPxRule(*pct) if pct else FixedPxRule()


def nearest_epof(
    grid: GridFile,
    hp: HeadPath,
    *,
    rule: FixedPxRule | None = None,
    hold: bool = False,
    frames: tuple[int, int] | None = None,
    orientation_deg="grid",
) -> EpofResult:
    """The authors' runtime over one viewing: per video frame ``k``, the nearest window
    (:func:`simulator.mitigation.cao2021.nearest_window`, steps = the grid's) and its row
    ``k - 2`` (0 before frame 2 and past the grid); opacity by ``rule`` (default
    :func:`grid_px_rule`: the authors' scale or the grid's imported one) from ``pof_px``
    (:func:`preset_pof_px`: with their frame-0 defect in row 0, which flashes at frame 2).

    ``result.meta["flow_px"]`` holds the px/frame flow of each row (the CSV's
    :data:`FLOW_PX_COLUMN`). The source's initial orientation turns each head pose, as in
    vimsim's EPOF (``orientation_deg``: yaw, pitch, roll in degrees, None: none, ``"grid"``:
    the grid's ``meta["source"]``); the head's roll is not used (their rule has none).
    """
    rule = grid_px_rule(grid) if rule is None else rule
    g = grid.grid
    frame, t, _rows = _select_frames(grid, frames)
    hp.check_covers(float(t[-1]), hold=hold,
                    video=grid.meta.get("video", {}).get("path", "") or grid.path,
                    start_s=float(t[0]))  # fmt: skip
    yaw, pitch, roll = hp.sample_angles_deg(t, hold=hold)
    pose = orientation_deg
    if isinstance(pose, str):
        pose = (grid.meta.get("source") or {}).get("orientation_deg")
    vy, vp, _ = view_angles_deg(pose, yaw, pitch, roll)
    steps = {"yaw_step_deg": g.yaw_step_deg, "pitch_step_deg": g.pitch_step_deg}
    try:
        px = nearest_flow(preset_pof_px(grid), frame, vy, vp, g.yaw_deg, g.pitch_deg, **steps)
        dps = nearest_flow(grid.pof_dps, frame, vy, vp, g.yaw_deg, g.pitch_deg, **steps)
    except InputError as e:
        raise InputError(f"{grid.path or 'grid'}: {e}") from None
    meta = {
        "hfov_deg": grid.hfov_deg,
        "vfov_deg": grid.vfov_deg,
        "frustum_deg": None,
        "top_k": None,
        "rule": rule,
        "fps": grid.fps,
        "method": "nearest (cao2021-code)",
        "flow_weights": None,
        "video_content_hash": (grid.meta.get("video") or {}).get("content_hash"),
        "orientation_deg": None if pose is None else [float(a) for a in pose],
        "flow_px": px,
        "preset": "cao2021-code",
    }
    return EpofResult(frame, t, yaw, pitch, roll, dps, rule(px), (math.nan, math.nan), meta)
