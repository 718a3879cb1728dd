"""Screen-fixed graphics and camera-fixed content (:mod:`simulator.preprocess.fixedcontent`),
and keyframes confirmed by the decoder's flags: recall and false alarms on clips made with
ffmpeg, and false alarms on clean and real clips.

Base: ``vimsim synth --scene rotate --omega 20`` (the panorama turning at 20 deg/s,
512x256, 30 fps, 6 s, CRF 10). Made with ffmpeg (imageio-ffmpeg's binary):

- ``lower-third``: a grey panel 160x32 px in the lower front (lat -30 to -43 deg) from 2 s
  to 5 s: static "text" (a black grid, left half), a white bar growing over 3 s and a
  yellow box sliding across the right half once a second (animated); truth: overlay on
  frames 60-149.
- ``end-card``: the clip cut at 4 s to a navy card with a box sliding across it (animated);
  truth: cut on frame 120, overlay on 121-179.
- ``camera-fixed``: a "hand" (a textured crop of the panorama, 112x40 px, at the nadir,
  swaying 4 px once a second) for the whole clip, and a "thumb" (a darkened crop,
  120x110 px, at the left lens seam) from 3 s to 4 s; truth: camera-fixed on the thumb's
  frames 90-119 (recall), the hand reported as a camera-fixed event at the nadir (the
  ``labelled`` column lists the events and their regions, lon0, lon1, lat0, lat1 deg);
  camera-fixed on any frame is right (the hand never stops swaying), any other kind a
  false alarm.
- ``pumping``: rotate at 3 deg/s, x264 constant QP 42, GOP 15 (keyframe truth: the
  decoder's key frames), to check that the decoder's flags keep the keyframe recall.

Clean: rotate 20 deg/s, coaster; real (../shared/data/real): three.js ``pano.mp4`` and
``pano.webm`` (hand-held, moving camera), ``MaryOculus.mp4`` (side-by-side, static camera).
Recall = truth frames labelled with their kind / truth frames; false alarms = frames
labelled with a kind that is not their truth (outside the truth: any kind). Detection from
the picture signals only (``frame_signals`` + ``detect_artefacts``; the flow adds the
flow-only keyframe rule, not used here). Reference ratio: detection time / decoding time
of the same clips (one gray decoding pass, ``iter_frames``).

Run: .venv/bin/python bench/fixed_content.py [CLIPS_DIR]   (CLIPS_DIR: keep the clips, reuse them)
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import av

from simulator.media.video import iter_frames
from simulator.preprocess.artefacts import detect_artefacts, frame_signals
from simulator.testing.reference import ffmpeg_exe

PANO = Path(__file__).resolve().parents[1] / "simulator" / "data" / "panorama.jpg"
REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "equirect" / "threejs"


def ff(*args: str) -> None:
    out = Path(args[-1])
    if out.is_file():  # made by an earlier run into the same folder
        return
    tmp = out.with_name("tmp_" + out.name)
    subprocess.run([ffmpeg_exe(), "-loglevel", "error", "-y", *args[:-1], str(tmp)], check=True)
    tmp.rename(out)


def synth(out: Path, *args: str) -> None:
    if out.is_file():
        return
    subprocess.run([sys.executable, "-m", "simulator", "synth", str(out), "--seconds", "6",
                    "--size", "512x256", "--crf", "10", *args], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)  # fmt: skip


ENC = ("-c:v", "libx264", "-crf", "12", "-pix_fmt", "yuv420p", "-r", "30")


def make_clips(d: Path) -> dict[str, tuple[Path, dict[str, set[int]], str]]:
    base, calm = d / "rotate20.mp4", d / "rotate3.mp4"
    synth(base, "--scene", "rotate", "--omega", "20")
    synth(calm, "--scene", "rotate", "--omega", "3")
    synth(d / "coaster.mp4", "--scene", "coaster")
    clips = {"rotate 20 deg/s (clean)": (base, {}, "mono"),
             "coaster (clean)": (d / "coaster.mp4", {}, "mono")}  # fmt: skip
    # Lower third: a panel with a growing bar and a sliding box (overlay's x, w per frame), 2 s to 5 s.
    ff("-i", str(base), "-f", "lavfi", "-i", "color=c=gray:s=160x32:r=30:d=6",
       "-f", "lavfi", "-i", "color=c=white:s=120x6:r=30:d=6",
       "-f", "lavfi", "-i", "color=c=yellow:s=24x8:r=30:d=6", "-filter_complex",
       "[2:v]crop=w='8+112*min(max(t-2,0)/3,1)':h=6:x=0:y=0[bar];"
       "[1:v]drawgrid=x=8:y=18:w=6:h=4:t=2:c=black,drawbox=x=80:y=16:w=80:h=16:color=gray:t=fill[pg];"
       "[pg][bar]overlay=x=8:y=6[p1];[p1][3:v]overlay=x='80+60*mod(t,1)':y=20[panel];"
       "[0:v][panel]overlay=x=176:y=172:enable='between(t,2,4.999)'[v]",
       "-map", "[v]", "-t", "6", *ENC, str(d / "lower_third.mp4"))  # fmt: skip
    clips["lower third"] = (d / "lower_third.mp4", {"overlay": set(range(60, 150))}, "mono")
    # End card: cut at 4 s to a navy card with a box sliding across.
    ff("-i", str(base), "-f", "lavfi", "-i", "color=c=navy:s=512x256:r=30:d=2",
       "-f", "lavfi", "-i", "color=c=white:s=60x36:r=30:d=2", "-filter_complex",
       "[1:v][2:v]overlay=x='100+150*t':y=110[c];"
       "[0:v]trim=end_frame=120,setpts=PTS-STARTPTS[a];[a][c]concat=n=2:v=1[v]",
       "-map", "[v]", *ENC, str(d / "end_card.mp4"))  # fmt: skip
    clips["end card"] = (d / "end_card.mp4", {"cut": {120}, "overlay": set(range(121, 180))}, "mono")
    # Camera-fixed: a hand at the nadir swaying, a thumb at the left seam from 3 s to 4 s.
    ff("-i", str(base), "-loop", "1", "-i", str(PANO), "-filter_complex",
       "[1:v]scale=512:256,split[p1][p2];[p1]crop=112:40:300:120,gblur=sigma=1[h];"
       "[p2]crop=120:110:40:60,gblur=sigma=3,eq=brightness=-0.25[th];"
       "[0:v][h]overlay=x='200+4*sin(2*PI*t)':y=216:shortest=1[a];"
       "[a][th]overlay=x=0:y=70:enable='between(t,3,3.999)'[v]",
       "-map", "[v]", "-t", "6", *ENC, str(d / "camera_fixed.mp4"))  # fmt: skip
    clips["camera-fixed hand + thumb"] = (d / "camera_fixed.mp4",
                                          {"camera-fixed": set(range(90, 120))}, "mono")  # fmt: skip
    # Keyframe pumping, calm: the decoder's flags must keep the recall.
    ff("-i", str(calm), "-c:v", "libx264", "-qp", "42", "-g", "15", "-bf", "0",
       "-x264-params", "scenecut=0", "-pix_fmt", "yuv420p", str(d / "pumping.mp4"))  # fmt: skip
    with av.open(str(d / "pumping.mp4")) as c:
        keys = {i for i, f in enumerate(c.decode(video=0)) if f.key_frame and i > 0}
    clips["pumping, rotate 3 deg/s"] = (d / "pumping.mp4", {"keyframe": keys}, "mono")
    for name, lay in (("pano.mp4", "mono"), ("pano.webm", "mono"), ("MaryOculus.mp4", "side-by-side")):
        if (REAL / name).is_file():
            clips[f"real {name} (clean)"] = (REAL / name, {}, lay)
    return clips


def score(kinds: tuple[str, ...], truth: dict[str, set[int]]) -> tuple[dict, int, dict]:
    """Recall per truth kind, false alarms, and the kinds found."""
    rec = {k: (sum(kinds[f] == k for f in fr if f < len(kinds)), len(fr)) for k, fr in truth.items()}
    want = {f: k for k, fr in truth.items() for f in fr}
    # the hand sways all the time: camera-fixed is right on any frame of that clip
    ok = "camera-fixed" if "camera-fixed" in truth else None
    fa = sum(1 for f, k in enumerate(kinds) if k and want.get(f) != k and k != ok)
    found: dict[str, int] = {}
    for k in kinds:
        if k:
            found[k] = found.get(k, 0) + 1
    return rec, fa, found


def main(argv: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        keep = Path(argv[0]) if argv else None  # a folder: the clips made there once, reused
        if keep is not None:
            keep.mkdir(parents=True, exist_ok=True)
        clips = make_clips(keep or Path(tmp))
        t_det = t_dec = 0.0
        print("| clip | truth | recall | false alarms | labelled |")
        print("|---|---|---|---|---|")
        for name, (path, truth, layout) in clips.items():
            t0 = time.perf_counter()
            for _ in iter_frames(path, fmt="gray", layout=layout):
                pass
            t1 = time.perf_counter()
            art = detect_artefacts(frame_signals(path, layout=layout))
            t2 = time.perf_counter()
            t_dec, t_det = t_dec + t1 - t0, t_det + t2 - t1
            rec, fa, found = score(art.kind, truth)
            rs = ", ".join(f"{k} {a}/{n} = {a / n:.2f}" for k, (a, n) in rec.items()) or "-"
            tr = ", ".join(f"{k} {len(v)}" for k, v in truth.items()) or "none"
            fx = "; ".join(f"{e['kind']} frames {e['first']}-{e['last']} at {[round(x) for x in e['region_deg']]}"
                           for e in art.meta.get("fixed", []))  # fmt: skip
            print(f"| {name} | {tr} | {rs} | {fa} | {found or '-'} {fx} |")
        print(f"\ndetection (decode + signals + rules) {t_det:.1f} s; gray decoding alone {t_dec:.1f} s; "
              f"ratio {t_det / t_dec:.2f}")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
