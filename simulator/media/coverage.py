"""What a source's projection covers, per field cell and per window, as a grid file records it (VR180's back half, no flow measured there).

A projection that does not cover the whole sphere (``hequirect``) leaves directions with
no content: no flow is measured there. Preprocessing records which field cells and which
windows are covered (:data:`COVERED_SHARE` of their area inside the projection) in the
grid file's ``meta["coverage"]`` and writes 0 deg/s for the others; EPOF then averages
over the covered part of the viewport only and reports its share per frame (the
``coverage`` column, :func:`simulator.epof.viewing.compute_epof`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from simulator.sphere.cells import CellGrid
from simulator.sphere.geometry import equirect_pixel_lonlat
from simulator.sphere.windows import WindowExtractor, WindowGrid

__all__ = [
    "COVERED_SHARE",
    "MIN_COVERAGE",
    "cell_coverage",
    "coverage_masks",
    "coverage_meta",
    "fade",
    "window_coverage",
]

#: A cell or window counts as covered when at least this share of its area lies inside
#: the projection (one that straddles the edge holds the content/black border: no flow).
COVERED_SHARE = 0.99
#: Below this covered share of the viewport, EPOF fades linearly to 0 (the viewer sees
#: mostly no content): ``epof = covered mean * min(1, coverage / MIN_COVERAGE)``.
MIN_COVERAGE = 0.25


def cell_coverage(covered: NDArray[np.bool_], cell_deg: float) -> NDArray[np.float64]:
    """Share of each field cell's solid angle inside the projection, ``(n_lat, n_lon)``,
    from the equirect working frame's ``(H, W)`` covered mask."""
    H, W = covered.shape
    cells = CellGrid(cell_deg)
    lon, lat = equirect_pixel_lonlat(W, H)
    idx = cells.index(lon[None, :], lat[:, None]).ravel()
    w = np.broadcast_to(np.cos(lat)[:, None], (H, W)).ravel()
    tot = np.bincount(idx, w, minlength=cells.n_cells)
    cov = np.bincount(idx, w * covered.ravel(), minlength=cells.n_cells)
    return (cov / np.maximum(tot, 1e-300)).reshape(cells.shape)


def window_coverage(covered: NDArray[np.bool_], grid: WindowGrid) -> NDArray[np.float64]:
    """Share of each window's pixels inside the projection, ``(P, Y)`` (sampled on 32 x 32
    rays per window: a share, not an image)."""
    H, W = covered.shape
    ext = WindowExtractor(replace(grid, size=(32, 32)), (W, H), cache=False)
    win = ext(np.where(covered, 255, 0).astype(np.uint8), interp="linear")
    return win.reshape(*grid.shape, -1).mean(axis=-1) / 255.0


def _pack(mask: NDArray[np.bool_]) -> str:
    return np.packbits(mask.astype(bool).ravel()).tobytes().hex()


def _unpack(text: str, shape) -> NDArray[np.bool_]:
    n = int(np.prod(shape))
    bits = np.unpackbits(np.frombuffer(bytes.fromhex(text), np.uint8))[:n]
    return bits.astype(bool).reshape(shape)


def coverage_meta(covered, grid: WindowGrid, cell_deg: float | None = None) -> dict | None:
    """``meta["coverage"]`` of a grid file (None when the projection covers the sphere):
    the covered windows and field cells (``cell_deg``, default 4: the viewport's covered
    share is measured on them in both modes) as packed bits, and the sphere's share."""
    if covered is None:
        return None
    wins = window_coverage(covered, grid) >= COVERED_SHARE
    w = np.cos(equirect_pixel_lonlat(covered.shape[1], covered.shape[0])[1])
    out = {
        "rule": f"covered = at least {COVERED_SHARE:g} of the area inside the projection; "
        f"EPOF over the covered part, faded to 0 below {MIN_COVERAGE:g} of the viewport",
        "sphere_share": float((covered * w[:, None]).sum() / (w.sum() * covered.shape[1])),
        "windows": _pack(wins),
        "windows_shape": list(wins.shape),
    }  # fmt: skip
    cell_deg = 4.0 if cell_deg is None else float(cell_deg)
    cells = cell_coverage(covered, cell_deg) >= COVERED_SHARE
    out.update(cells=_pack(cells), cells_shape=list(cells.shape), cell_deg=cell_deg)
    return out


def coverage_masks(meta: dict) -> tuple[NDArray | None, NDArray | None]:
    """``(windows (P, Y), cells (n_lat, n_lon))`` bool masks of a grid file's meta (None
    where the meta has no coverage: everything covered)."""
    c = meta.get("coverage") if isinstance(meta, dict) else None
    if not c:
        return None, None
    wins = _unpack(c["windows"], c["windows_shape"]) if "windows" in c else None
    cells = _unpack(c["cells"], c["cells_shape"]) if "cells" in c else None
    return wins, cells


def fade(coverage) -> NDArray[np.float64]:
    """The small-coverage rule's factor ``min(1, coverage / MIN_COVERAGE)``."""
    return np.minimum(1.0, np.asarray(coverage, float) / MIN_COVERAGE)
