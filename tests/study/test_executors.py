"""The study executors' set-up: the local pool's fork-server preload names real modules."""

from __future__ import annotations

import subprocess
import sys


def test_every_worker_preload_name_imports():
    """multiprocessing skips a preload name that does not import, silently: each name of
    the list imports in a fresh interpreter."""
    from simulator.study.executors import WORKER_PRELOAD

    assert "simulator.study.tasks" in WORKER_PRELOAD
    code = "import importlib, sys; [importlib.import_module(m) for m in sys.argv[1:]]"
    out = subprocess.run(
        [sys.executable, "-c", code, *WORKER_PRELOAD], capture_output=True, text=True, check=False
    )
    assert out.returncode == 0, out.stderr
    bad = subprocess.run(
        [sys.executable, "-c", code, "simulator.no_such_stage"], capture_output=True, check=False
    )
    assert bad.returncode != 0  # the check can fail
