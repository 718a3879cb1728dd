"""Rated synthetic clips for the discomfort tests: 12 tiny rotate clips in 4 groups, made once a session."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from discomfort_helpers import WEIGHTS, rotate_clip


@dataclass(frozen=True)
class RatedClips:
    folder: Path
    ratings: Path  # video,rating,group
    grids: Path  # the grid cache, filled by the first calibrate
    rates: np.ndarray  # (12, 3) true |yaw|, |pitch|, |roll| rates, deg/s


@pytest.fixture(scope="session")
def rated_clips(tmp_path_factory) -> RatedClips:
    d = tmp_path_factory.mktemp("rated")
    rng = np.random.default_rng(0)
    rates = rng.uniform(8.0, 40.0, (12, 3))
    lines = ["video,rating,group"]
    for i, (y, p, r) in enumerate(rates):
        rotate_clip(d / f"c{i}.mp4", y, p, r, seed=i // 3)
        rating = WEIGHTS["yaw"] * y + WEIGHTS["pitch"] * p + WEIGHTS["roll"] * r
        lines.append(f"c{i}.mp4,{rating:.4f},scene{i // 3}")
    (d / "ratings.csv").write_text("\n".join(lines) + "\n")
    return RatedClips(d, d / "ratings.csv", d / "grids", rates)
