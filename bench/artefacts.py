"""Artefact detection on clips made with ffmpeg from textured synthetic scenes: recall and
false alarms per kind, and false alarms on the clean clips.

Scenes (``vimsim synth``, 512x256, 30 fps, 6 s, CRF 10): ``coaster`` (fast), ``rotate``
at 20 deg/s and at 3 and 6 deg/s (calm), ``forward``, and a 40 s ``coaster`` (clean). Artefacts made with ffmpeg
(imageio-ffmpeg's binary): keyframe pumping (x264, constant QP 42 or 36, GOP 15, no
B-frames, no scene-cut keyframes; truth: the decoder's key frames), a hard cut (coaster
then rotate at frame 90), a fade to black (from 3 s over 1.5 s; truth: every frame from
91 on), a static overlay (SMPTE bars 160x48) fading in from 2 s to 3 s (truth: frames
61-90). Real: three.js's MaryOculus.mp4 (../shared/data/real, side-by-side stereo, a
static camera: a calm clip) clean and re-encoded with pumping (GOP 24). Each clip is preprocessed in sphere mode, then :func:`detect_artefacts`.
Recall = truth frames labelled with the right kind / truth frames; false alarms = frames
labelled outside the truth. The reference ratio: detection time / preprocess time.

Run: .venv/bin/python bench/artefacts.py
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import av
import numpy as np

from simulator.media.gridfile import load_grid
from simulator.preprocess.artefacts import detect_artefacts, frame_signals
from simulator.preprocess.sphere import preprocess_sphere
from simulator.sphere.windows import grid_preset
from simulator.testing.reference import ffmpeg_exe


def ff(*args: str) -> None:
    subprocess.run([ffmpeg_exe(), "-loglevel", "error", "-y", *args], check=True)


def synth(out: Path, *args: str) -> None:
    secs = () if "--seconds" in args else ("--seconds", "6")
    subprocess.run([sys.executable, "-m", "simulator", "synth", str(out), *secs,
                    "--size", "512x256", "--crf", "10", *args], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip


def keyframes(path: Path) -> set[int]:
    with av.open(str(path)) as c:
        return {i for i, f in enumerate(c.decode(video=0)) if f.key_frame and i > 0}


REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "equirect"
MARY = REAL / "threejs" / "MaryOculus.mp4"  # real CG stereo clip, static camera (calm)


def measure(path: Path, d: Path) -> tuple:
    layout = "side-by-side" if "mary" in path.stem.lower() else "mono"
    t0 = time.perf_counter()
    preprocess_sphere(path, d / (path.stem + ".npz"), grid=grid_preset("default"), layout=layout)
    t1 = time.perf_counter()
    g = load_grid(d / (path.stem + ".npz"))
    a = detect_artefacts(frame_signals(path, layout=layout), g.pof_dps)
    return a, time.perf_counter() - t1, t1 - t0


def main() -> None:
    x264 = "keyint=15:min-keyint=15:scenecut=0:bframes=0"
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        synth(d / "coaster.mp4", "--scene", "coaster")
        synth(d / "rotate.mp4", "--scene", "rotate", "--omega", "20")
        synth(d / "calm3.mp4", "--scene", "rotate", "--omega", "3")
        synth(d / "calm6.mp4", "--scene", "rotate", "--omega", "6")
        synth(d / "forward.mp4", "--scene", "forward")
        synth(d / "coaster40.mp4", "--scene", "coaster", "--seconds", "40")  # a long clean ride
        cases = []  # (name, file, kind, truth frames)
        for base in ("calm3", "calm6", "coaster"):
            for qp in ("42", "36"):
                out = d / f"kf_{base}_qp{qp}.mp4"
                ff("-i", str(d / f"{base}.mp4"), "-c:v", "libx264", "-x264-params", x264, "-qp", qp,
                   "-pix_fmt", "yuv420p", str(out))  # fmt: skip
                cases.append((out.stem, out, "keyframe", keyframes(out)))
        if MARY.is_file():  # the real calm clip, re-encoded with keyframe pumping (GOP 24)
            for qp in ("42", "36"):
                out = d / f"kf_mary_qp{qp}.mp4"
                ff("-i", str(MARY), "-c:v", "libx264", "-x264-params", x264.replace("15", "24"),
                   "-qp", qp, "-pix_fmt", "yuv420p", str(out))  # fmt: skip
                cases.append((out.stem, out, "keyframe", keyframes(out)))
            cases.append(("clean_real_mary", MARY, None, set()))
        ff("-i", str(d / "coaster.mp4"), "-i", str(d / "rotate.mp4"), "-filter_complex",
           "[0:v]trim=end_frame=90,setpts=PTS-STARTPTS[a];[1:v]trim=start_frame=90,"
           "setpts=PTS-STARTPTS[b];[a][b]concat=n=2:v=1[v]", "-map", "[v]", "-c:v", "libx264",
           "-crf", "12", "-pix_fmt", "yuv420p", str(d / "cut.mp4"))  # fmt: skip
        cases.append(("cut", d / "cut.mp4", "cut", {90}))
        ff("-i", str(d / "coaster.mp4"), "-vf", "fade=t=out:st=3:d=1.5", "-c:v", "libx264",
           "-crf", "12", "-pix_fmt", "yuv420p", str(d / "fade.mp4"))  # fmt: skip
        cases.append(("fade", d / "fade.mp4", "fade", set(range(91, 180))))
        ff("-i", str(d / "coaster.mp4"), "-f", "lavfi", "-i", "smptehdbars=s=160x48:d=6,format=rgba",
           "-filter_complex", "[1:v]fade=t=in:st=2:d=1:alpha=1[o];[0:v][o]overlay=x=180:y=100:shortest=1",
           "-c:v", "libx264", "-crf", "12", "-pix_fmt", "yuv420p", str(d / "overlay.mp4"))  # fmt: skip
        cases.append(("overlay", d / "overlay.mp4", "overlay", set(range(61, 91))))
        for name in ("coaster", "rotate", "calm3", "calm6", "forward", "coaster40"):
            cases.append((f"clean_{name}", d / f"{name}.mp4", None, set()))
        t_det = t_pre = 0.0
        print(
            f"{'clip':22s} {'kind':9s} {'truth':>5s} {'found':>5s} {'recall':>6s} {'false':>5s}  period"
        )
        for name, path, kind, truth in cases:
            a, td, tp = measure(path, d)
            t_det, t_pre = t_det + td, t_pre + tp
            lab = np.array(a.kind)
            hit = sum(lab[t] == kind for t in truth if t < lab.size)
            false = sum(1 for t in np.flatnonzero(lab != "") if int(t) not in truth)
            rec = f"{hit / len(truth):.2f}" if truth else "-"
            print(f"{name:22s} {kind or 'clean':9s} {len(truth):5d} {hit:5d} {rec:>6s} {false:5d}  "
                  f"{a.keyframe_period}")  # fmt: skip
        print(
            f"\ndetection {t_det:.1f} s against sphere preprocess {t_pre:.1f} s: "
            f"ratio {t_det / t_pre:.2f}"
        )


if __name__ == "__main__":
    main()
