"""Long head paths are built and measured in chunks (memory), bit for bit as in one piece."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from simulator.sphere.geometry import head_rotation
from simulator.traces.path import HeadPath


def test_chunked_rotations_and_speeds_are_bit_identical():
    rng = np.random.default_rng(7)
    n = (1 << 16) * 2 + 123  # three chunks
    y, p, r = rng.uniform(-180, 180, n), rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)
    whole = Rotation.from_euler("YXZ", np.stack([y, -p, -r], axis=-1), degrees=True)
    assert np.array_equal(head_rotation(y, p, r).as_quat(), whole.as_quat())
    t = np.arange(n) / 90.0
    hp = HeadPath(t, whole)
    want = np.degrees((whole[:-1].inv() * whole[1:]).magnitude()) / np.diff(t)
    assert np.array_equal(hp.angular_speed_dps(), want)
