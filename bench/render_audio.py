"""Cost of carrying the source's audio into ``render``'s outputs, against the same render with ``--no-audio``.

Input: three.js ``pano.mp4`` (real hand-held 360 video, 1920x1080, 25 fps, 188 frames;
it has no audio) with a 7.5 s AAC track added here (its video packets copied, a
440 Hz tone encoded by FFmpeg's AAC encoder; cached in ``outputs/bench15/``), the
AVTrack360 subject-2 trace of video 6, its default grid (made here if missing), the
comfort opacity rule, eye ``--eye-size`` (default 720), one eye file (mono source).
Figures, best of ``--repeat`` (3) interleaved runs, each a ratio to the silent render
measured in the same run:

* audio copied (packets) / ``--no-audio``, full video and a quarter range;
* audio re-encoded to AAC (the same tone as PCM in a Matroska copy: what a codec MP4
  cannot hold costs) / ``--no-audio``;
* ``--review`` with audio / plain render with audio (goal <= 1.3, as without audio).

Usage: ``.venv/bin/python bench/render_audio.py [--eye-size 1440]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _pano import CACHE, TRACES, VIDEO, pano_grid  # bench/_pano.py: the clip, its cached grid

TRACE = TRACES / "2.json"


def with_tone(src: Path, dst: Path, codec: str, fmt: str) -> None:
    """``src``'s video packets (copied) plus a 440 Hz stereo tone as long as the video."""
    import av

    rate = 48000
    with av.open(str(src)) as ic, av.open(str(dst), "w", format=fmt) as oc:
        iv = ic.streams.video[0]
        ov = oc.add_stream_from_template(iv)
        oa = oc.add_stream(codec, rate=rate)
        oa.layout = "stereo"
        oa.format = "fltp" if codec == "aac" else "s16"
        dur = float(iv.frames or 188) / float(iv.guessed_rate or 25)
        t = np.arange(int(rate * dur)) / rate
        x = 0.3 * np.sin(2 * np.pi * 440 * t)
        for k in range(0, len(x), 1024):
            seg = np.stack([x[k : k + 1024]] * 2)
            if codec == "aac":
                af = av.AudioFrame.from_ndarray(
                    seg.astype(np.float32), format="fltp", layout="stereo"
                )
            else:
                inter = (seg.T.reshape(1, -1) * 32767).astype(np.int16)
                af = av.AudioFrame.from_ndarray(inter, format="s16", layout="stereo")
            af.sample_rate, af.pts = rate, k
            for p in oa.encode(af):
                oc.mux(p)
        for p in oa.encode(None):
            oc.mux(p)
        for pkt in ic.demux(iv):
            if pkt.dts is None:
                continue
            pkt.stream = ov
            oc.mux(pkt)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--eye-size", type=int, default=720)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from simulator.media.gridfile import load_grid
    from simulator.mitigation.grf import GrfConfig, comfort_rule
    from simulator.render import RenderConfig, create_context
    from simulator.traces.readers import load_headpath
    from simulator.viewing.job import render_viewing

    gp = pano_grid()
    aac, pcm = CACHE / "pano_tone.mp4", CACHE / "pano_tone_pcm.mkv"
    if not aac.exists():
        with_tone(VIDEO, aac, "aac", "mp4")
    if not pcm.exists():
        with_tone(VIDEO, pcm, "pcm_s16le", "matroska")
    grid = load_grid(gp)
    grid.meta["video"].pop("content_hash", None)  # the same frames, in another file
    hp = load_headpath(TRACE, video="6.mp4")
    ctx = create_context()
    cfg = RenderConfig(eye_size=(args.eye_size, args.eye_size), grf=GrfConfig())
    quarter = round(grid.n_frames / 4) / grid.fps

    def run(video, **kw):
        with tempfile.TemporaryDirectory() as d:
            t0 = time.perf_counter()
            s = render_viewing(video, hp, d, grid=grid, config=cfg, rule=comfort_rule(),
                               progress=False, ctx=ctx, hold=True, **kw)  # fmt: skip
            return time.perf_counter() - t0, s["audio"]

    run(aac, end_s=0.4)  # warm-up
    cases = {
        "silent": {"video": aac, "audio": False},
        "copied": {"video": aac},
        "silent_q": {"video": aac, "audio": False, "end_s": quarter},
        "copied_q": {"video": aac, "end_s": quarter},
        "pcm_silent": {"video": pcm, "audio": False},
        "reencoded": {"video": pcm},
        "review": {"video": aac, "review": True},
    }
    runs: dict[str, list] = {k: [] for k in cases}
    for _ in range(args.repeat):
        for k, kw in cases.items():
            runs[k].append(run(**kw)[0])
    best = {k: min(v) for k, v in runs.items()}
    a = run(aac, end_s=0.4)[1]
    assert a["copied"] and a["mode"] == "packets copied", a
    r = run(pcm, end_s=0.4)[1]
    assert r["copied"] and r["mode"] == "re-encoded to AAC", r
    print(
        f"{VIDEO.name} + tone, eye {args.eye_size}x{args.eye_size}, renderer {ctx.info.get('GL_RENDERER')}"
    )
    print(f"render --no-audio (reference):  {best['silent']:.2f} s")
    print(
        f"render, AAC packets copied:     {best['copied']:.2f} s  ratio {best['copied'] / best['silent']:.3f}"
    )
    print(f"quarter range, --no-audio:      {best['silent_q']:.2f} s")
    print(
        f"quarter range, audio copied:    {best['copied_q']:.2f} s  ratio {best['copied_q'] / best['silent_q']:.3f}"
    )
    print(f"PCM source, --no-audio:         {best['pcm_silent']:.2f} s")
    print(
        f"PCM source, re-encoded to AAC:  {best['reencoded']:.2f} s  ratio {best['reencoded'] / best['pcm_silent']:.3f}"
    )
    print(
        f"render --review, with audio:    {best['review']:.2f} s  ratio {best['review'] / best['copied']:.3f} (goal <= 1.3)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
