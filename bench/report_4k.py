"""The study report of a 30 s 4K HEVC clip: its time beside the study's plots, and the browser copy's x264 preset.

Usage: .venv/bin/python bench/report_4k.py [--seconds 30]

The clip: petra.jpg (vrview) upscaled to 3840x1920 and panned, 30 fps, HEVC (libx265
ultrafast), made once into ``bench/_out/report_4k/``; one viewer (a look-around path);
its sphere grid made by the first (cold) study and cached. Figures, same run:

* ``vimsim report`` of the study / the plots and tables the study makes
  (``write_study_outputs``, made again here): goal: the report <= 20 s;
* the browser copy alone (2048 px wide, x264 ``BROWSER_PRESET``) / decoding the source
  alone (the floor any copy pays);
* for x264 ultrafast, superfast and veryfast at crf 20: the encode time and the PSNR of a
  100 x 56 deg view at 1280x720 (the report's replay window) taken from the copy, against
  the same view of the source scaled to the copy's width: the report's preset is the
  fastest within 0.5 dB of veryfast (crf 20 itself bounds the quality of all three).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
OUT = REPO / "bench" / "_out" / "report_4k"
PETRA = REPO.parent / "shared" / "data" / "real" / "equirect" / "vrview" / "petra.jpg"
VIMSIM = str(Path(sys.executable).with_name("vimsim"))
from report_speed import plots_seconds

GOAL_S = 20.0


def _clip(seconds: float) -> Path:
    from simulator.testing.reference import ffmpeg_exe

    OUT.mkdir(parents=True, exist_ok=True)
    p = OUT / f"petra_4k_{seconds:g}s.mkv"
    if not p.is_file():
        # a slow pan (10 deg/s) of the panorama at 3840x1920, HEVC 8-bit
        vf = ("scale=3840:1920:flags=bicubic,loop=loop=-1:size=1,"
              "scroll=horizontal=0.000926,format=yuv420p")  # fmt: skip
        subprocess.run([ffmpeg_exe(), "-y", "-v", "error", "-i", str(PETRA), "-vf", vf,
                        "-r", "30", "-t", str(seconds), "-c:v", "libx265", "-preset",
                        "ultrafast", "-x265-params", "log-level=error", str(p)],
                       check=True)  # fmt: skip
    return p


def _study(clip: Path, seconds: float) -> Path:
    from simulator.traces.path import save_headpath_csv, synth

    trace = OUT / "viewer.csv"
    save_headpath_csv(trace, synth("look-around", seconds + 1, rate_hz=30, seed=1))
    m = OUT / "study.toml"
    m.write_text(f'[[videos]]\nid = "petra4k"\npath = "{clip}"\nmethod = "sphere"\n\n'
                 f'[[viewings]]\nvideo = "petra4k"\ntrace = "{trace}"\n')  # fmt: skip
    out = OUT / "study"
    if not (out / "study.json").is_file():
        subprocess.run([VIMSIM, "study", str(m), "-o", str(out), "--cache-dir",
                        str(OUT / "cache"), "--no-progress", "--no-report"], check=True)  # fmt: skip
    return out


def _timed(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _decode_s(clip: Path) -> float:
    import av

    t0 = time.perf_counter()
    with av.open(str(clip)) as c:
        s = c.streams.video[0]
        s.thread_type = "AUTO"
        for _ in c.decode(s):
            pass
    return time.perf_counter() - t0


def _preset_table(clip: Path, n: int = 90) -> list[tuple[str, float, float]]:
    """(preset, encode s per frame, view PSNR dB) on the first ``n`` frames."""
    import av

    import simulator.report.build as B
    from simulator.sphere.geometry import extract_view
    from simulator.testing.reference import psnr

    part = OUT / "first.mkv"
    from simulator.testing.reference import ffmpeg_exe

    subprocess.run([ffmpeg_exe(), "-y", "-v", "error", "-i", str(clip), "-frames:v", str(n),
                    "-c", "copy", str(part)], check=True)  # fmt: skip
    with av.open(str(part)) as c:
        ref = [f.reformat(width=2048, height=1024, format="rgb24", interpolation="AREA")
               .to_ndarray() for f in c.decode(video=0)]  # fmt: skip
    rows = []
    for preset in ("ultrafast", "superfast", "veryfast"):
        B.BROWSER_PRESET = preset
        dst = OUT / f"copy-{preset}.mp4"
        dst.unlink(missing_ok=True)
        t0 = time.perf_counter()
        B.browser_copy(part, dst)
        dt = (time.perf_counter() - t0) / n
        with av.open(str(dst)) as c:
            got = [f.to_ndarray(format="rgb24") for f in c.decode(video=0)]
        vals = []
        for i in range(0, n, 15):
            for yaw in (0.0, 120.0, -120.0):
                a = extract_view(ref[i], yaw, 0.0, hfov_deg=100, vfov_deg=56.25, size=(1280, 720))
                b = extract_view(got[i], yaw, 0.0, hfov_deg=100, vfov_deg=56.25, size=(1280, 720))
                vals.append(psnr(a, b))
        rows.append((preset, dt, float(np.mean(vals))))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=30.0)
    a = ap.parse_args()
    clip = _clip(a.seconds)
    out = _study(clip, a.seconds)
    import shutil

    shutil.rmtree(out / "report", ignore_errors=True)
    report = _timed([VIMSIM, "report", str(out), "--no-progress"])
    plots = plots_seconds(out, OUT / "study.toml")
    decode = _decode_s(clip)
    copy = json.loads((out / "report" / ".vimsim-report.json").read_text())["copies"]
    how = next(iter(copy.values()))["copy"]["how"]
    print(f"{a.seconds:g} s 4K HEVC (3840x1920, 30 fps), one viewing; browser copy: {how}")
    print(f"  vimsim report          {report:7.1f} s   (goal <= {GOAL_S:g} s)")
    print(f"  the study's plots      {plots:7.1f} s   ratio report / plots {report / plots:.1f}x")
    print(f"  decoding the source    {decode:7.1f} s   ratio report / decode {report / decode:.2f}x")
    print("  browser copy presets (crf 20, 2048x1024; view 1280x720, 100 deg, vs the source):")
    for preset, dt, db in _preset_table(clip):
        print(f"    {preset:10s} {dt * 1e3:6.1f} ms/frame   view PSNR {db:5.1f} dB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
