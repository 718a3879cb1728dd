"""Every real head trace converts; yaw/pitch statistics next to the look-around synth's.

Usage: python bench/headtrace_stats.py [--shared ../shared]

All traces (and the synth) are first resampled to 10 Hz with Slerp (the coarsest rate in
the data: AVTrack360 and 360VidStr), so speeds are comparable across datasets. Printed
per trace: duration, share of time with |pitch| <= 30 deg, pitch 5/50/95th percentiles,
share of time with angular speed < 10 deg/s ("still"), and angular speed percentiles
(deg/s, 50/75/90/95). The look-around synth (10 seeds x 120 s) is printed below the
pooled real statistics with the ratio synth/real of each number matched.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from simulator.traces.path import CoarseSamplingWarning, synth
from simulator.traces.readers import detect_format, load_headpath

RATE = 10.0
SPEED_PCT = (50, 75, 90, 95)


def stats(hp):
    t = np.arange(hp.start_s, hp.end_s, 1.0 / RATE)
    r = hp.resample(t)
    _, pitch, _ = r.angles_deg()
    sp = r.angular_speed_dps()
    return {
        "dur": hp.end_s - hp.start_s,
        "pitch30": float(np.mean(np.abs(pitch) <= 30)),
        "pitch_pct": np.percentile(pitch, [5, 50, 95]),
        "still": float(np.mean(sp < 10)),
        "speed": np.percentile(sp, SPEED_PCT),
        "_pitch": pitch,
        "_speed": sp,
    }


def line(name, s):
    pp = "/".join(f"{v:.0f}" for v in s["pitch_pct"])
    spd = "/".join(f"{v:.0f}" for v in s["speed"])
    return (
        f"{name:44s} {s['dur']:7.1f} {100 * s['pitch30']:6.1f}% {pp:>14s} "
        f"{100 * s['still']:6.1f}% {spd:>16s}"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--shared", default=str(Path(__file__).resolve().parents[1].parent / "shared"))
    a = ap.parse_args(argv)
    root = Path(a.shared) / "data" / "real" / "headtraces"
    if not root.is_dir():
        print(f"no real head traces at {root}", file=sys.stderr)
        return 2
    hdr = f"{'trace':44s} {'dur s':>7s} {'|p|<=30':>7s} {'pitch 5/50/95':>14s} {'still':>7s} {'speed 50/75/90/95':>16s}"
    print(hdr)
    t0 = time.perf_counter()
    pooled_p, pooled_s, n_ok = [], [], 0
    coarse: list[str] = []
    for f in sorted(root.rglob("*")):
        if not f.is_file() or f.suffix not in (".txt", ".csv", ".json"):
            continue
        if f.name == "readMe.txt" or "SRC_info" in f.parts:
            continue
        fmt = detect_format(f)
        if fmt == "avtrack360":
            import json

            names = [e["filename"] for e in json.loads(f.read_text())["data"]]
            jobs = [(f"{f.parent.name}/{f.name}:{v}", {"video": v}) for v in names]
        elif fmt == "360vidstr":
            n_users = (sum(1 for ln in f.read_text().splitlines() if ln.strip()) - 1) // 2
            jobs = [(f"{f.name}:user{u}", {"user": u}) for u in range(1, n_users + 1)]
        else:
            jobs = [(f"{f.parent.name[:16]}/{f.name}", {})]
        per_file = []
        for name, kw in jobs:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                hp = load_headpath(f, **kw)
            # The readers' coarse-sampling warnings are facts of the data: listed below.
            # Any other warning is a problem of ours.
            other = [w for w in caught if not issubclass(w.category, CoarseSamplingWarning)]
            if other:
                sys.exit(f"{name}: unexpected warning: {other[0].message}")
            coarse += [str(w.message) for w in caught]
            s = stats(hp)
            n_ok += 1
            per_file.append(s)
            if fmt == "corbillon-euler":
                continue  # same rows as the quaternion file; counted once
            pooled_p.append(s["_pitch"])
            pooled_s.append(s["_speed"])
        if len(per_file) == 1:
            print(line(f"{jobs[0][0]} [{fmt}]", per_file[0]))
        else:  # one line per file: medians over its users/videos
            agg = {
                "dur": float(np.median([s["dur"] for s in per_file])),
                "pitch30": float(np.median([s["pitch30"] for s in per_file])),
                "pitch_pct": np.median([s["pitch_pct"] for s in per_file], axis=0),
                "still": float(np.median([s["still"] for s in per_file])),
                "speed": np.median([s["speed"] for s in per_file], axis=0),
            }
            print(line(f"{f.parent.name[:14]}/{f.name} x{len(per_file)} (median) [{fmt}]", agg))
    print(f"{n_ok} traces converted in {time.perf_counter() - t0:.1f} s")
    print(
        f"{len(coarse)} coarse-sampling warnings (a step over 90 deg between two samples; "
        "interpolation takes the shortest arc there)" + "".join(f"\n  {m}" for m in coarse)
    )
    rp, rs = np.concatenate(pooled_p), np.concatenate(pooled_s)
    real = {
        "dur": len(rp) / RATE,
        "pitch30": float(np.mean(np.abs(rp) <= 30)),
        "pitch_pct": np.percentile(rp, [5, 50, 95]),
        "still": float(np.mean(rs < 10)),
        "speed": np.percentile(rs, SPEED_PCT),
    }
    sims = [stats(synth("look-around", 120.0, rate_hz=60.0, seed=s)) for s in range(10)]
    sp_ = np.concatenate([s["_pitch"] for s in sims])
    ss_ = np.concatenate([s["_speed"] for s in sims])
    sim = {
        "dur": len(sp_) / RATE,
        "pitch30": float(np.mean(np.abs(sp_) <= 30)),
        "pitch_pct": np.percentile(sp_, [5, 50, 95]),
        "still": float(np.mean(ss_ < 10)),
        "speed": np.percentile(ss_, SPEED_PCT),
    }
    print("-" * len(hdr))
    print(line("ALL REAL (pooled, 10 Hz)", real))
    print(line("look-around synth (10 seeds x 120 s)", sim))
    ratios = [sim["pitch30"] / real["pitch30"], sim["still"] / real["still"]]
    ratios += list(sim["speed"] / real["speed"])
    names = ["|p|<=30", "still"] + [f"speed p{q}" for q in SPEED_PCT]
    print("ratio synth/real: " + ", ".join(f"{n} {r:.2f}" for n, r in zip(names, ratios)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
