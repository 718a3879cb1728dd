"""Studies: many videos x many viewings in one command (``vimsim study``), locally or on Ray.

:func:`load_manifest` reads and validates ``STUDY.toml`` (:mod:`.manifest`);
:func:`run_study` plans and runs the task graph (:mod:`.runner`) on an executor
(:mod:`.executors`: a local process pool, or Ray) with the task functions of
:mod:`.tasks`, and writes the outputs (:mod:`.outputs`). See ``docs/study.md``.
"""

from __future__ import annotations

from simulator.study.manifest import Manifest, VideoSpec, ViewingSpec, load_manifest
from simulator.study.runner import VIEWING_COLUMNS, default_cache_dir, run_study

__all__ = [
    "VIEWING_COLUMNS",
    "Manifest",
    "VideoSpec",
    "ViewingSpec",
    "default_cache_dir",
    "load_manifest",
    "run_study",
]
