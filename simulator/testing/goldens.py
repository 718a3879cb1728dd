"""A small pytest-friendly API for users' own visual regression tests: render frames, assert they match goldens.

Example (a user's ``tests/test_look.py``; full text in ``docs/frames.md``)::

    from simulator.testing.goldens import assert_frames_match, render_frames

    def test_grade_unchanged(tmp_path):
        render_frames("clip.mp4", "path.csv", tmp_path / "new", at=[1, 5, 10], opacity=0.8)
        assert_frames_match(tmp_path / "new", "tests/golden/clip")

Set ``VIMSIM_UPDATE_GOLDENS=1`` to write the new frames over the goldens instead (after
review), or to create them on the first run.
"""

from __future__ import annotations

import os
from pathlib import Path

from simulator.core.errors import InputError
from simulator.testing.compare import (
    DEFAULT_MAX_DIFF,
    DEFAULT_PSNR_DB,
    CompareReport,
    compare_dirs,
    update_goldens,
)
from simulator.viewing.frames import render_frames

__all__ = ["UPDATE_ENV", "assert_frames_match", "render_frames"]

#: Environment variable: when "1", :func:`assert_frames_match` updates the goldens.
UPDATE_ENV = "VIMSIM_UPDATE_GOLDENS"


def assert_frames_match(
    frames_dir,
    golden_dir,
    *,
    psnr_db: float = DEFAULT_PSNR_DB,
    max_diff: float = DEFAULT_MAX_DIFF,
    report_dir=None,
) -> CompareReport:
    """Assert every frame of ``frames_dir`` matches its golden (:func:`simulator.testing.compare.compare_dirs`).

    Raises AssertionError whose message has one line per failing frame, naming the
    frame, the measure against its threshold and the diff file; bad input (missing or
    extra frames, other sizes, no golden folder) is an AssertionError too, with the
    one-line reason. With ``VIMSIM_UPDATE_GOLDENS=1`` the goldens are updated instead.
    """
    if os.environ.get(UPDATE_ENV) == "1":
        update_goldens(frames_dir, golden_dir)
        return compare_dirs(
            frames_dir, golden_dir, psnr_db=psnr_db, max_diff=max_diff, report_dir=report_dir
        )
    if not Path(golden_dir).is_dir():
        raise AssertionError(
            f"no goldens at {golden_dir}; run once with {UPDATE_ENV}=1 to create them"
        )
    try:
        rep = compare_dirs(
            frames_dir, golden_dir, psnr_db=psnr_db, max_diff=max_diff, report_dir=report_dir
        )
    except InputError as e:
        raise AssertionError(str(e)) from None
    if not rep.passed:
        lines = [s.why(psnr_db, max_diff) for s in rep.failures]
        raise AssertionError(
            f"{len(lines)} of {len(rep.scores)} frames differ from {golden_dir}:\n"
            + "\n".join(lines)
        )
    return rep
