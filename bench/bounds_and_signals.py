"""Bounds before work and signals (issue 41): time to refuse a huge user range, time to end after SIGTERM.

Usage: .venv/bin/python bench/bounds_and_signals.py [--viewers 3000]

1. A 50-user 360VidStr file and a study manifest naming ``user = "1-99999999999999999999"``:
   the seconds ``vimsim study --dry-run`` takes to refuse it (exit 2), beside the seconds
   of a dry run naming ``user = "1-5"`` (the command's own start-up) and their ratio,
   measured in the same run (it used to expand the range first: 7.3 GB after 2 min).
2. ``vimsim screen`` of a 10-frame clip with ``--viewers`` scripted viewers on 2 workers:
   SIGTERM once the first viewings are written; prints the seconds from the signal to the
   command's exit (goal < 2 s; it used to join the workers until they finished the chunks
   they held) and the EPOF files written after the signal.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
OUT = REPO / "bench" / "_out" / "bounds"
ENV = {**os.environ, "PYTHONPATH": str(REPO)}


def clip() -> Path:
    from simulator.synth import SynthConfig, synthesize

    c = OUT / "clip10.mp4"
    if not c.is_file():
        synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), c)
    return c


def dry_run_s(user: str) -> tuple[float, int]:
    t = " ".join(f"{k / 10:.1f}" for k in range(21))
    users = "".join(f"{' '.join(['0.0'] * 21)}\n{' '.join(['0.1'] * 21)}\n" for _ in range(50))
    (OUT / "multi.txt").write_text(t + "\n" + users)
    m = OUT / "range.toml"
    m.write_text(f'[[videos]]\nid = "clip"\npath = "{clip()}"\nwindow_size = 64\n\n'
                 f'[[viewings]]\nvideo = "clip"\ntrace = "multi.txt"\nuser = "{user}"\n')  # fmt: skip
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "simulator", "study", str(m), "-o", str(OUT / "never"),
                        "--dry-run"], env=ENV, capture_output=True, timeout=600, check=False)  # fmt: skip
    return time.perf_counter() - t0, r.returncode


def sigterm(viewers: int) -> tuple[float, int, int]:
    out = OUT / "screen"
    shutil.rmtree(out, ignore_errors=True)
    p = subprocess.Popen([sys.executable, "-m", "simulator", "screen", str(clip()), "-o", str(out),
                          "--viewers", str(viewers), "--workers", "2", "--cache-dir",
                          str(OUT / "cache"), "--no-progress"], env=ENV,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    epof = out / "epof"
    while not (epof.is_dir() and any(epof.iterdir())):
        if p.poll() is not None:
            raise SystemExit(f"screen ended before the signal (exit {p.returncode})")
        time.sleep(0.05)
    n0 = len(list(epof.iterdir()))
    t0 = time.perf_counter()
    p.send_signal(signal.SIGTERM)
    rc = p.wait()
    return time.perf_counter() - t0, rc, len(list(epof.iterdir())) - n0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--viewers", type=int, default=3000)
    a = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    ok_s, ok_rc = dry_run_s("1-5")
    huge_s, huge_rc = dry_run_s("1-99999999999999999999")
    assert (ok_rc, huge_rc) == (0, 2), (ok_rc, huge_rc)
    print(f"refuse user = 1-1e20 (50 users): {huge_s:.2f} s; a valid dry run {ok_s:.2f} s; "
          f"ratio {huge_s / ok_s:.2f}x (goal: under 1 s beyond start-up)")
    s, rc, more = sigterm(a.viewers)
    print(f"screen {a.viewers} viewers: exit {rc} {s:.2f} s after SIGTERM (goal < 2 s), "
          f"{more} EPOF files written after it")
    return 0


if __name__ == "__main__":
    sys.exit(main())
