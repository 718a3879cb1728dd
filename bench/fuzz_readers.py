"""The long fuzz run of every reader (tests/test_fuzz.py): inputs tried per reader and
failures (any exception but InputError), with ``VIMSIM_FUZZ_EXAMPLES`` examples per test
(default 2000; hypothesis may stop a test earlier when it has tried every input it can
make), against the default CI run (15 each) as the reference.

Run: .venv/bin/python bench/fuzz_readers.py [--examples N]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run(examples: int) -> tuple[dict[str, int], float, str]:
    """``{reader: inputs tried}``, seconds, pytest's last line (its failures)."""
    with tempfile.TemporaryDirectory() as t:
        counts = Path(t) / "counts.json"
        env = dict(os.environ, VIMSIM_FUZZ_EXAMPLES=str(examples), MPLBACKEND="Agg",
                   VIMSIM_FUZZ_COUNTS=str(counts))  # fmt: skip
        t0 = time.monotonic()
        r = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_fuzz.py"],
            cwd=REPO, env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        dt = time.monotonic() - t0
        stats = json.loads(counts.read_text()) if counts.is_file() else {}
    fails = [ln for ln in r.stdout.splitlines() if ln.startswith("FAILED")]
    last = (r.stdout.strip().splitlines() or [""])[-1]
    return stats, dt, "; ".join([last, *fails])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--examples", type=int, default=2000)
    args = ap.parse_args()
    _, t_ref, _ = run(15)
    stats, dt, last = run(args.examples)
    print(f"{'reader':30s} {'inputs':>7s}")
    for name in sorted(stats):
        print(f"{name:30s} {stats[name]:7d}")
    total = sum(stats.values())
    print(f"total inputs {total} in {dt:.0f} s; pytest: {last}")
    print(f"ratio (long run / CI run wall time): {dt / t_ref:.1f} (CI run {t_ref:.1f} s)")


if __name__ == "__main__":
    main()
