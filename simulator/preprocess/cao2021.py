"""The frame-0 defect of the authors' preprocessing, measured for the ``cao2021-code`` preset only: frame 0's windows rendered at 88 deg instead of 107.

Their Unity preprocessing renders the first frame's windows with an 88 deg wide camera and
every later frame at 107 deg, so the flow of their row 0 (frame 0 -> 1) is the zoom between
the two FOVs: 7-350 x the later rows, and through their runtime's list indexing the grains
flash at video frame 2 (:mod:`simulator.mitigation.cao2021`). vimsim's own row 0 repeats
row 1; this module measures what theirs would hold, per window, in window px/frame, stored
in the grid's ``meta["cao"]["row0_px"]`` (P x Y) and used only by ``--preset cao2021-code``
(and the CSVs ``export --format cao-csv --preset cao2021-code`` writes).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from simulator.flow.base import FlowBackend
from simulator.sphere.windows import GRID_PRESETS, WindowExtractor, WindowGrid

__all__ = ["FRAME0_HFOV_DEG", "frame0_defect_meta", "frame0_defect_row", "is_cao2021_grid"]

#: The horizontal FOV of their frame 0 windows, degrees (vertical: linear, x h / w).
FRAME0_HFOV_DEG = 88.0


def is_cao2021_grid(grid: WindowGrid) -> bool:
    """True when ``grid`` has the ``cao2021`` preset's steps and pitch range (any size)."""
    pre = GRID_PRESETS["cao2021"]
    return all(getattr(grid, k) == pre[k] for k in
               ("yaw_step_deg", "pitch_step_deg", "pitch_min_deg", "pitch_max_deg"))  # fmt: skip


def frame0_defect_row(
    frame0: NDArray[np.uint8],
    frame1: NDArray[np.uint8],
    grid: WindowGrid,
    backend: FlowBackend,
    *,
    hfov0_deg: float = FRAME0_HFOV_DEG,
) -> NDArray[np.float32]:
    """Their row 0: per window, the mean flow magnitude (window px/frame) from frame 0's
    window at ``hfov0_deg`` (vertical FOV linear: ``hfov0 * h / w``, as their camera) to
    frame 1's at the grid's FOV.

    frame0, frame1 : ndarray, shape (H, W), uint8, gray equirect frames of one eye
    Returns : ndarray, shape (P, Y), float32
    """
    w, h = grid.size
    g0 = dataclasses.replace(grid, hfov_deg=hfov0_deg, vfov_deg=hfov0_deg * h / w)
    size = (frame0.shape[1], frame0.shape[0])
    a = WindowExtractor(g0, size, cache=False)(frame0, interp="linear")
    b = WindowExtractor(grid, size, cache=False)(frame1, interp="linear")
    P, Y = grid.shape
    out = np.empty((P, Y), np.float32)
    for i in range(P):
        for j in range(Y):
            f = backend(a[i, j][None], b[i, j][None])[0]
            out[i, j] = float(np.hypot(f[..., 0], f[..., 1]).mean())
    return out


def frame0_defect_meta(source, grid: WindowGrid, backend: FlowBackend, start_frame: int) -> dict:
    """``meta["cao"]`` of a ``cao2021`` grid: ``row0_px`` (P x Y lists) of
    :func:`frame0_defect_row` on the source's (a :class:`simulator.media.source.Source`)
    frames ``start_frame`` and the next, and ``row0_hfov_deg``."""
    frames = source.frames(fmt="gray", start=start_frame, end=start_frame + 2)
    try:
        f0, f1 = next(frames), next(frames)
    finally:
        close = getattr(frames, "close", None)
        if close is not None:
            close()
    row = frame0_defect_row(f0, f1, grid, backend)
    return {"row0_px": row.tolist(), "row0_hfov_deg": FRAME0_HFOV_DEG}
