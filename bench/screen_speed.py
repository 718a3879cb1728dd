"""Screening a 40 s clip with 30 scripted viewers: wall time over sphere-mode preprocess alone,
and the comparison table of a calm and a provocative clip under the relative and absolute rules.

Clips: ``vimsim synth`` 512x256 at 30 fps, 40 s: ``coaster`` (provocative: a ride) and
``rotate --omega 3`` (calm: a panorama turning at 3 deg/s). Reference, measured in the same
run: ``vimsim preprocess --method sphere`` of the coaster clip. Figure: ``vimsim screen
coaster.mp4 --viewers 30`` (cold cache: it preprocesses too) / preprocess, medians of 2
alternating rounds (whole processes, start-up included).
Goal <= 2x. Then both clips screened (warm cache) with ``--opacity-rule comfort``
(relative) and ``--opacity-rule absolute`` (5-30 deg/s); the two comparison tables printed.

Run: .venv/bin/python bench/screen_speed.py [--seconds 40]
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def vimsim(*args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "simulator", *args], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip
    return time.perf_counter() - t0


def main() -> None:
    secs = sys.argv[sys.argv.index("--seconds") + 1] if "--seconds" in sys.argv else "40"
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        common = ("--seconds", secs, "--size", "512x256", "--fps", "30", "--crf", "12")
        vimsim("synth", str(d / "coaster.mp4"), "--scene", "coaster", *common)
        vimsim("synth", str(d / "calm.mp4"), "--scene", "rotate", "--omega", "3", *common)
        pre, scr = [], []
        for r in range(2):  # alternating, so that the machine's load hits both alike
            pre.append(vimsim("preprocess", str(d / "coaster.mp4"), "-o", str(d / f"g{r}.npz"),
                              "--method", "sphere", "--no-progress"))  # fmt: skip
            scr.append(vimsim("screen", str(d / "coaster.mp4"), "-o", str(d / f"s{r}"),
                              "--viewers", "30", "--cache-dir", str(d / f"cache{r}"),
                              "--no-progress"))  # fmt: skip
        t_pre, t_scr = float(np.median(pre)), float(np.median(scr))
        print(
            f"{secs} s clip, 30 viewers (cold cache): preprocess {pre} s, screen {scr} s; "
            f"medians {t_pre:.1f} / {t_scr:.1f} s, ratio {t_scr / t_pre:.2f}x (goal <= 2x)"
        )
        for rule in (("--opacity-rule", "comfort"), ("--opacity-rule", "absolute")):
            out = d / f"s-{rule[1]}"
            vimsim("screen", str(d / "calm.mp4"), str(d / "coaster.mp4"), "-o", str(out),
                   "--viewers", "30", "--cache-dir", str(d / "cache0"), "--no-progress", *rule)  # fmt: skip
            print(f"\n{rule[1]} rule: screen/comparison.csv")
            for ln in (out / "screen" / "comparison.csv").read_text().splitlines():
                if not ln.startswith("#"):
                    print("  " + ln)


if __name__ == "__main__":
    main()
