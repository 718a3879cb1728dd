"""The CLI's default for OpenBLAS threads (set before numpy loads; the user's value wins)."""

from __future__ import annotations

import os
import subprocess
import sys

CHILD = (
    "import os, sys; from simulator.cli import _set_blas_threads; _set_blas_threads(); "
    "import numpy; print(os.environ.get('OPENBLAS_NUM_THREADS'), 'numpy' in sys.modules)"
)


def _child(**env_extra) -> str:
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env.update(env_extra)
    r = subprocess.run(
        [sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True
    )
    return r.stdout.strip()


def test_blas_threads_default_to_one_unless_the_user_sets_them():
    assert _child() == "1 True"
    assert _child(OPENBLAS_NUM_THREADS="3") == "3 True"


def test_cli_module_loads_no_numpy():
    """The default can only work while numpy is not loaded yet: importing the CLI must not load it."""
    r = subprocess.run(
        [sys.executable, "-c", "import sys, simulator.cli; print('numpy' in sys.modules)"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert r.stdout.strip() == "False"
