"""The EPOF split into the camera's rotation and translation, and the weighted EPOF of ``--flow-weights``.

How a speed is split. At every cell and frame a sphere-mode grid recording the camera's rotation
holds the measured speed ``s`` (``field_dps``), the speed with the fitted camera
rotation removed ``s_t`` (``field_trans_dps``: the translation's parallax plus anything
moving on its own; where the fit finds no translation, its flow noise is discounted: a
pure rotation's residual is flow error alone, whose length would otherwise count as
translation, :func:`simulator.preprocess.ego.residual_speed`) and the camera's angular velocity ``omega`` (``ego_omega_dps``),
whose speed at the cell's direction ``d`` alone is ``s_r = |omega x d|``. The measured
speed is shared between the two in proportion to the speed each would give alone::

    rot part   = s * s_r / (s_r + s_t)        trans part = s * s_t / (s_r + s_t)

(half each where both are 0). The parts add up to ``s`` exactly, so over any viewport
``epof_rot_dps + epof_trans_dps = epof_dps`` (viewport means are linear), and a pure
rotation (``s_t = 0``) is all rotation, a pure translation all translation. The
weighted EPOF of ``--flow-weights rot=A,trans=B`` is ``A * epof_rot_dps + B *
epof_trans_dps``; the default ``A = B = 1`` is the EPOF itself.

The truth of ``vimsim synth`` is split the same way (``speed_rot_dps``,
``speed_trans_dps``: each motion alone, noise-free), so estimate and truth compare part by
part.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.epof.exact import shared_query
from simulator.media.gridfile import require_field
from simulator.media.lazyfield import LazyField, spool, spool_name, take_rows
from simulator.sphere.cells import CellGrid, Frustum
from simulator.sphere.geometry import lonlat_to_dir

__all__ = [
    "DEFAULT_WEIGHTS",
    "has_parts",
    "keep_parts_in",
    "parse_flow_weights",
    "require_parts",
    "rotation_share",
    "viewport_parts",
    "viewport_parts_total",
]

#: ``--flow-weights`` default: the EPOF itself.
DEFAULT_WEIGHTS: tuple[float, float] = (1.0, 1.0)

#: How to make a grid with the parts; quoted by the error for a grid without them.
MAKE_PARTS_HINT = "re-run vimsim preprocess VIDEO -o GRID.npz --method sphere"


def parse_flow_weights(text: str) -> tuple[float, float]:
    """``"rot=A,trans=B"`` (either part may be left out: weight 1) -> ``(A, B)``.

    InputError (one line naming ``--flow-weights``) for an unknown part, a repeated one,
    a weight that is not a finite number >= 0, or both weights 0."""
    out = {"rot": 1.0, "trans": 1.0}
    seen = set()
    for item in str(text).split(","):
        key, sep, val = item.strip().partition("=")
        key = key.strip().lower()
        if not sep or key not in out:
            raise InputError(
                f"--flow-weights: unknown part {item.strip()!r}; expected rot=A,trans=B "
                "(weights >= 0, e.g. rot=1,trans=0.5)"
            )
        if key in seen:
            raise InputError(f"--flow-weights: {key} given twice")
        seen.add(key)
        try:
            v = float(val)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or v < 0:
            raise InputError(
                f"--flow-weights: {key} must be a finite number >= 0; got {val.strip()!r}"
            )
        out[key] = v
    if out["rot"] == 0 and out["trans"] == 0:
        raise InputError("--flow-weights: rot and trans are both 0; give at least one weight > 0")
    return out["rot"], out["trans"]


def has_parts(grid) -> bool:
    """True when a grid holds the per-frame camera rotation and translational field."""
    return bool(getattr(grid, "extras", {})) and getattr(grid, "field_trans_dps", None) is not None


def require_parts(grid) -> None:
    """InputError (naming the grid and the fix) unless the grid has the parts."""
    if not has_parts(grid):
        src = getattr(grid, "path", "") or "grid"
        raise InputError(
            f"{src}: grid has no per-frame camera rotation (made before vimsim split the "
            f"flow into rotation and translation, or in paper mode); {MAKE_PARTS_HINT}"
        )


def rotation_share(
    field: NDArray, trans: NDArray, omega_dps: NDArray, cells: CellGrid
) -> NDArray[np.float32]:
    """The rotation's share ``s_r / (s_r + s_t)`` of each cell's speed, ``(T, n_lat,
    n_lon)`` float32, for fields ``field``/``trans`` (T, n_lat, n_lon) and the camera's
    angular velocity ``omega_dps`` (T, 3) (module docstring; ``field`` unused but for
    its shape)."""
    lon, lat = cells.centres_lonlat()
    d = lonlat_to_dir(*np.meshgrid(lon, lat)).reshape(-1, 3)  # (cells, 3)
    om = np.asarray(omega_dps, np.float64).reshape(-1, 3)
    # |omega x d| = sqrt(|omega|^2 - (omega . d)^2) for unit d: one matrix product
    dot = om @ d.T  # (T, cells)
    sr = np.sqrt(np.maximum((om * om).sum(axis=1)[:, None] - dot * dot, 0.0))
    sr = sr.astype(np.float32).reshape(np.shape(field))
    tot = sr + np.asarray(trans, np.float32)
    share = np.divide(sr, tot, out=np.full_like(sr, 0.5), where=tot > 0)
    return share.astype(np.float32, copy=False)


#: The rotational part of the last field asked for (a study worker asks for it once per
#: viewing of the same grid): ``(field, trans, part)``.
_HELD: list = []
#: The folder where the rotational part of a lazy field is kept as a raw file (None: it is
#: computed chunk by chunk at each call): :func:`keep_parts_in`.
_SPOOL: list = [None]


def keep_parts_in(folder) -> None:
    """Keep the rotational part of lazy fields (long videos) as raw float32 files in
    ``folder`` (None: compute it at each call), so that a process serving many viewings
    of one grid computes it once, memory flat in the video's length."""
    _SPOOL[0] = None if folder is None else Path(folder)


def _held_rot_field(field, trans, omega, cells: CellGrid):
    """``field * rotation_share``, computed once and kept for the next call on the same
    fields: in memory for fields held in memory (both ndarrays), in a raw file of the
    :func:`keep_parts_in` folder for lazy ones (read chunk by chunk); None for lazy fields
    without that folder (computed chunk by chunk at each call)."""
    if _HELD and _HELD[0][0] is field and _HELD[0][1] is trans:
        return _HELD[0][2]
    if isinstance(field, np.ndarray) and isinstance(trans, np.ndarray):
        out = np.empty(field.shape, np.float32)
        for i0 in range(0, len(field), 256):
            f = np.asarray(field[i0 : i0 + 256], np.float32)
            out[i0 : i0 + 256] = f * rotation_share(f, trans[i0 : i0 + 256], omega[i0 : i0 + 256], cells)
    elif _SPOOL[0] is not None and isinstance(field, LazyField):
        name = spool_name(field, "rot")
        if name is None:
            return None

        def rot(i0: int, f):
            i1 = i0 + len(f)
            return f * rotation_share(f, _rows(trans, i0, i1), omega[i0:i1], cells)

        out = spool(field, _SPOOL[0] / name, rot)
    else:
        return None
    _HELD[:] = [(field, trans, out)]
    return out


def _rows(field, i0: int, i1: int) -> NDArray[np.float32]:
    """Rows ``i0 <= i < i1`` of a field, lazy or in memory, as float32."""
    if isinstance(field, LazyField):
        return field.block(i0, i1).astype(np.float32, copy=False)
    return np.asarray(field[i0:i1], np.float32)


def viewport_parts(grid, yaw_deg, pitch_deg, roll_deg=0.0, **kw):
    """``(epof_rot_dps, epof_trans_dps)`` (T,): :func:`viewport_parts_total` (same
    arguments) without the total."""
    return viewport_parts_total(grid, yaw_deg, pitch_deg, roll_deg, **kw)[:2]


def viewport_parts_total(
    grid,
    yaw_deg,
    pitch_deg,
    roll_deg=0.0,
    *,
    frustum: Frustum | None = None,
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    rows=None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(epof_rot_dps, epof_trans_dps, epof_dps)`` (T,) of a sphere-mode grid with the
    parts, for the head orientation of each frame (degrees; ``rows``: only these grid rows).

    Their sum is the exact EPOF :func:`simulator.epof.exact.viewport_epof` gives for the
    same viewport. InputError (naming the fix: re-run preprocess) for a grid without the
    per-frame rotation."""
    require_parts(grid)
    field, cells = require_field(grid)
    trans = grid.field_trans_dps
    omega = np.asarray(grid.extras["ego_omega_dps"], np.float64)
    if rows is not None:
        field, trans, omega = take_rows(field, rows), take_rows(trans, rows), omega[rows]
    fr = frustum or Frustum.symmetric(
        float(hfov_deg or grid.hfov_deg), float(vfov_deg or hfov_deg or grid.vfov_deg)
    )
    T = len(omega)
    yaw, pitch, roll = (
        np.broadcast_to(np.asarray(a, float), (T,)) for a in (yaw_deg, pitch_deg, roll_deg)
    )
    total = np.empty(T)
    rot = np.empty(T)
    query = shared_query(cells.cell_deg, fr)
    held = _held_rot_field(field, trans, omega, cells)  # fields in memory: once per grid
    # the same rows of both fields at a time (either may be lazy, the other in memory)
    n = min([x.chunk_rows for x in (field, trans) if isinstance(x, LazyField)] or [256])
    for i0 in range(0, T, n):
        i1 = min(T, i0 + n)
        f = _rows(field, i0, i1)
        if held is not None:
            part = _rows(held, i0, i1)
        else:
            part = f * rotation_share(f, _rows(trans, i0, i1), omega[i0:i1], cells)
        sl = slice(i0, i1)  # one integration of the viewport for the EPOF and its part
        total[sl], rot[sl] = query.many_stacked((f, part), yaw[sl], pitch[sl], roll[sl])
    return rot, total - rot, total
