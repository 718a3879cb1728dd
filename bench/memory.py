"""Peak memory of the long-running commands against video length (streaming check).

Usage: .venv/bin/python bench/memory.py [--frames 60] [--factor 8] [--only sphere]
(docs/reliability.md quotes ``--frames 300 --factor 10``: 300 and 3000 frames)

Makes two 1024x512 H.264 clips of the same content (petra.jpg panning), one ``--factor``
times longer than the other, and runs each command on both in a fresh process:
``preprocess`` (paper mode, 128 px windows to keep it short; sphere mode), ``epof``,
``render`` (stereo output, 480x480 eyes, GRF on), and ``epof`` / ``render`` on the
sphere-mode grid (its field read lazily from the grid file, chunk by chunk). Prints the peak resident memory
(``ru_maxrss`` of the child) for the short and the long clip and their ratio. Goal
(DEVELOPERS.md: "memory must not grow with video length"): the long clip's peak within
10% of the short one's; what does grow by design is the output held until written
(the grid matrix: 264 floats x 2 per frame, about 2 KB a frame).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

from simulator.media import video

REAL = REPO.parent / "shared" / "data" / "real" / "equirect"
VIMSIM = [sys.executable, "-m", "simulator"]
GOAL_RATIO = 1.10

#: Run one command, print the child's peak RSS in KiB (Linux ru_maxrss unit).
_WRAP = (
    "import resource, subprocess, sys\n"
    "r = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)\n"
    "if r.returncode:\n"
    "    sys.exit(r.stderr.decode()[-2000:])\n"
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
)


def peak_mib(cmd: list[str]) -> float:
    out = subprocess.run(
        [sys.executable, "-c", _WRAP, *cmd], check=True, capture_output=True, text=True
    )
    return int(out.stdout.strip()) / 1024.0


def make_video(path: Path, n: int) -> None:
    from PIL import Image

    img = np.asarray(
        Image.fromarray(video.read_frame(REAL / "vrview/petra.jpg")).resize((1024, 512))
    )
    with video.VideoWriter(path, 30, (1024, 512), preset="ultrafast", crf=23) as w:
        for i in range(n):
            w.write(np.roll(img, 2 * i, axis=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60, help="frames of the short clip")
    ap.add_argument("--factor", type=int, default=8, help="long clip = factor x short")
    ap.add_argument(
        "--only",
        default="",
        help="run only the commands whose name contains this text (e.g. sphere)",
    )
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        clips = {"short": d / "short.mp4", "long": d / "long.mp4"}
        make_video(clips["short"], a.frames)
        make_video(clips["long"], a.frames * a.factor)
        n_long = a.frames * a.factor
        path = d / "path.csv"
        subprocess.run(
            [*VIMSIM, "headpath", "synth", "look-around", "-o", str(path),
             "--seconds", str(n_long / 30 + 1)],
            check=True, capture_output=True,
        )  # fmt: skip

        def jobs(tag: str, clip: Path) -> dict[str, list[str]]:
            grid, sgrid = d / f"{tag}.npz", d / f"{tag}_sphere.npz"
            return {
                "preprocess (paper, 128 px)": [
                    *VIMSIM, "preprocess", str(clip), "-o", str(grid),
                    "--window-size", "128", "--method", "paper", "--no-progress",
                ],
                "preprocess --method sphere": [
                    *VIMSIM, "preprocess", str(clip), "-o", str(sgrid), "--method", "sphere",
                    "--no-progress",
                ],
                "epof": [*VIMSIM, "epof", str(grid), str(path), "-o", str(d / f"{tag}.csv")],
                "render (stereo out, 480 px, GRF)": [
                    *VIMSIM, "render", str(clip), str(path), "-o", str(d / f"r_{tag}"),
                    "--grid", str(grid), "--eye-size", "480x480", "--no-progress",
                ],
                # sphere grids: the field is read lazily, chunk by chunk (lazyfield)
                "epof on a sphere grid": [
                    *VIMSIM, "epof", str(sgrid), str(path), "-o", str(d / f"{tag}_s.csv"),
                ],
                "render with the sphere grid (480 px, GRF)": [
                    *VIMSIM, "render", str(clip), str(path), "-o", str(d / f"rs_{tag}"),
                    "--grid", str(sgrid), "--eye-size", "480x480", "--no-progress",
                ],
            }  # fmt: skip

        print(
            f"1024x512 H.264 clips: {a.frames} and {n_long} frames (x{a.factor}); peak RSS per "
            f"command in a fresh process"
        )
        short, long_ = jobs("short", clips["short"]), jobs("long", clips["long"])
        worst = 0.0
        for name in short:
            if a.only not in name and not (a.only and "preprocess --method sphere" in name):
                continue  # the sphere grid's rows need it made first
            ms, ml = peak_mib(short[name]), peak_mib(long_[name])
            worst = max(worst, ml / ms)
            print(
                f"  {name:34s} {ms:7.1f} MiB -> {ml:7.1f} MiB  ratio {ml / ms:.3f} "
                f"(goal <= {GOAL_RATIO:.2f}: {'met' if ml / ms <= GOAL_RATIO else 'NOT met'})",
                flush=True,
            )
        print(f"largest ratio {worst:.3f} for {a.factor}x the frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
