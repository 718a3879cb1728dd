"""Viewport weights: only the rows a view can reach are evaluated; the result equals the
full evaluation of every cell (``_weights_band`` over the whole sphere, one view at a time)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from simulator.sphere.cells import CellGrid, Frustum, _weights_band, viewport_weights


def test_banded_weights_equal_every_cell_evaluated():
    rng = np.random.default_rng(1)
    frusta = [
        Frustum.symmetric(107, 107),
        Frustum(10, 80, 5, 85),
        Frustum(89.5, 89.5, 89.5, 89.5),
        Frustum.symmetric(30, 20),
    ]
    poles = Rotation.from_euler(
        "YXZ", [[0, 90, 0], [40, -90, 15], [0, 89.9, 0], [180, 0, 0]], degrees=True
    )
    for cell in (2.0, 5.0):
        C = CellGrid(cell).n_cells
        for fr in frusta:
            R = np.concatenate(
                [Rotation.random(12, random_state=rng).as_matrix(), poles.as_matrix()]
            )
            got = viewport_weights(cell, R, fr)
            want = np.stack([_weights_band(cell, r, fr, 0, C) for r in R]).astype(np.float32)
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
            assert (got > 0).sum() < got.size  # a view covers part of the sphere
