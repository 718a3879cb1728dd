"""Projection guard: dual fisheye read as equirect refused, genuine equirect never flagged.

For every image and clip in ``../shared/data/real/equirect`` (the real third-party data,
SOURCES.md): the genuine equirect must open (``Source.open`` without ``--projection``) and
no frame may look like dual fisheye (:func:`simulator.media.guard.looks_dual_fisheye`);
a dual fisheye made from it with ffmpeg's ``v360`` (``e`` -> ``dfisheye``, 190 deg lenses)
must be refused when opened without ``--projection`` and open with ``--projection dfisheye``.

    PYTHONPATH=. python bench/projection_guard.py [--lens-fov 190] [--frames 60]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REAL = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "equirect"
if not REAL.is_dir():
    REAL = Path("/work/shared/data/real/equirect")
#: Stereo files of the real data and their layouts (the rest are mono).
LAYOUTS = {
    "dolphins_stereo_tb.jpg": ("top-bottom", "tb"),
    "MaryOculus.mp4": ("side-by-side", "sbs"),
}
MEDIA = (".mp4", ".webm", ".jpg", ".png")


def real_files() -> list[Path]:
    return sorted(p for p in REAL.rglob("*") if p.suffix.lower() in MEDIA)


def to_dfisheye(src: Path, dst: Path, lens_fov: float) -> None:
    """``src`` (equirect, its stereo layout's left eye) as a 2:1 dual fisheye, 1024x512."""
    import imageio_ffmpeg

    st = LAYOUTS.get(src.name, (None, "2d"))[1]
    vf = (f"v360=input=e:output=dfisheye:in_stereo={st}:out_stereo=2d:h_fov={lens_fov}:"
          f"v_fov={lens_fov}:w=1024:h=512,setsar=1")  # fmt: skip
    extra = (
        ["-frames:v", "1"]
        if dst.suffix == ".png"
        else ["-c:v", "libx264", "-pix_fmt", "yuv420p", "-an"]
    )
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-y", "-i", str(src), "-vf", vf,
                    *extra, str(dst)], check=True)  # fmt: skip


def frame_verdicts(path: Path, layout: str, n_max: int) -> list[bool | None]:
    """looks_dual_fisheye of up to ``n_max`` frames spread over the file (its left eye)."""
    from simulator.media.guard import looks_dual_fisheye
    from simulator.media.video import iter_frames, probe

    n = max(1, probe(path).n_frames)
    keep = set(np.linspace(0, n - 1, min(n, n_max)).round().astype(int).tolist())
    return [looks_dual_fisheye(f) for i, f in
            enumerate(iter_frames(path, fmt="gray", layout=layout)) if i in keep]  # fmt: skip


def opens(path: Path, layout: str, projection: str | None) -> str:
    """ "ok" or the refusal's line."""
    from simulator.core.errors import InputError
    from simulator.media.source import Source

    try:
        Source.open(path, layout=layout, projection=projection, still=(None, None))
        return "ok"
    except InputError as e:
        return str(e)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lens-fov", type=float, default=190.0)
    ap.add_argument("--frames", type=int, default=60, help="frames looked at per clip")
    a = ap.parse_args(argv)
    files = real_files()
    if not files:
        print(f"no real data under {REAL}", file=sys.stderr)
        return 2
    stats = {"genuine_files": 0, "genuine_refused": 0, "genuine_not_2to1": 0, "genuine_frames": 0, "genuine_flagged": 0,
             "fisheye_files": 0, "fisheye_refused": 0, "fisheye_frames": 0, "fisheye_flagged": 0,
             "fisheye_dark": 0, "fisheye_opens_as_dfisheye": 0}  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for f in files:
            layout = LAYOUTS.get(f.name, ("mono",))[0]
            v = frame_verdicts(f, layout, a.frames)
            got = opens(f, layout, None)
            stats["genuine_files"] += 1
            stats["genuine_refused"] += "looks like dual fisheye" in got
            stats["genuine_not_2to1"] += "expected an equirectangular image" in got
            if "expected an equirectangular image" in got:  # 16:9 thumbnails: not equirect
                print(
                    f"{f.relative_to(REAL)}: not 2:1, refused ({got.split(': ', 1)[1][:60]}..); skipped"
                )
                continue
            stats["genuine_frames"] += len(v)
            stats["genuine_flagged"] += sum(x is True for x in v)
            fe = Path(tmp) / (f.stem + (".png" if f.suffix in (".jpg", ".png") else ".mp4"))
            to_dfisheye(f, fe, a.lens_fov)
            w = frame_verdicts(fe, "mono", a.frames)
            refused = opens(fe, "mono", None)
            stats["fisheye_files"] += 1
            stats["fisheye_refused"] += "--projection dfisheye --lens-fov" in refused
            stats["fisheye_frames"] += len(w)
            stats["fisheye_flagged"] += sum(x is True for x in w)
            stats["fisheye_dark"] += sum(x is None for x in w)
            stats["fisheye_opens_as_dfisheye"] += opens(fe, "mono", "dfisheye") == "ok"
            print(f"{f.relative_to(REAL)}: genuine {got if got != 'ok' else 'opens'}, frames "
                  f"flagged {sum(x is True for x in v)}/{len(v)}; dual fisheye "
                  f"{'refused' if refused != 'ok' else 'NOT refused'}, frames flagged "
                  f"{sum(x is True for x in w)}/{len(w)}")  # fmt: skip
    s = stats
    print(f"dual fisheye {a.lens_fov:g} deg refused: {s['fisheye_refused']}/{s['fisheye_files']} files "
          f"({100 * s['fisheye_refused'] / s['fisheye_files']:.0f} %), frames flagged "
          f"{s['fisheye_flagged']}/{s['fisheye_frames']} ({s['fisheye_dark']} dark: no verdict); "
          f"genuine equirect refused as dual fisheye {s['genuine_refused']}/"
          f"{s['genuine_files'] - s['genuine_not_2to1']} files ({s['genuine_not_2to1']} not 2:1 "
          "skipped), frames flagged "
          f"{s['genuine_flagged']}/{s['genuine_frames']}")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
