"""The projection guard: a dual-fisheye file read as equirect is refused naming
``--projection dfisheye --lens-fov``; a genuine equirect is never flagged; every aspect
refusal lists the projections whose layout fits."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from simulator.cli import main
from simulator.core.errors import InputError
from simulator.media.guard import fitting_projections, looks_dual_fisheye
from simulator.media.source import Source

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "real" / "equirect"
if not REAL.is_dir():
    REAL = Path("/work/shared/data/real/equirect")
STEREO = {"dolphins_stereo_tb.jpg": ("top-bottom", "tb"), "MaryOculus.mp4": ("side-by-side", "sbs")}


def _ffmpeg() -> str:
    import imageio_ffmpeg

    return imageio_ffmpeg.get_ffmpeg_exe()


def to_dfisheye(src: Path, dst: Path, *, stereo: str = "2d", frames: int = 8, size=(512, 256)):
    """``src`` (equirect) as ffmpeg v360's 190-degree dual fisheye (H.264, or one PNG)."""
    vf = (f"v360=input=e:output=dfisheye:in_stereo={stereo}:out_stereo=2d:h_fov=190:v_fov=190:"
          f"w={size[0]}:h={size[1]},setsar=1")  # fmt: skip
    out = (["-frames:v", "1"] if dst.suffix == ".png"
           else ["-frames:v", str(frames), "-c:v", "libx264", "-pix_fmt", "yuv420p", "-an"])  # fmt: skip
    subprocess.run([_ffmpeg(), "-v", "error", "-y", "-i", str(src), "-vf", vf, *out, str(dst)],
                   check=True)  # fmt: skip


def _lens_circles(h: int = 128) -> np.ndarray:
    """A camera's dual fisheye: two textured discs, black outside them."""
    rng = np.random.default_rng(0)
    img = rng.integers(60, 220, (h, 2 * h, 3), dtype=np.uint8)
    y, x = np.mgrid[0:h, 0 : 2 * h]
    r = np.hypot((x % h) - (h - 1) / 2, y - (h - 1) / 2) / (h / 2)
    img[r > 0.98] = 0
    return img


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> Path:
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("guard")
    synthesize(SynthConfig("coaster", seconds=0.5, fps=10, size=(512, 256)), d / "eq.mp4")
    return d / "eq.mp4"


def test_lens_circles_and_dark_frames():
    assert looks_dual_fisheye(_lens_circles()) is True
    assert looks_dual_fisheye(np.zeros((128, 256), np.uint8)) is None  # a dark frame: no verdict
    assert looks_dual_fisheye(np.zeros((100, 300), np.uint8)) is None  # not 2:1
    # An equirect with black pole bands (night sky, a nadir patch): dark corners, not circles.
    eq = _lens_circles()
    eq[:] = 150
    eq[:30], eq[-30:] = 0, 0
    assert looks_dual_fisheye(eq) is False


def test_half_covered_equirect_is_not_flagged():
    """A VR180 source's equirect copy (the back half black) is not two lenses: black on
    both sides of an overlap pair tells nothing."""
    pano = Path(__file__).resolve().parents[2] / "simulator" / "data" / "panorama.jpg"
    eq = np.asarray(Image.open(pano).convert("RGB").resize((512, 256)))
    assert looks_dual_fisheye(eq) is False
    half = eq.copy()
    half[:, :128], half[:, 384:] = 0, 0
    assert looks_dual_fisheye(half) is False
    # the same with a mirror-symmetric picture in the covered half: still no
    sym = half.copy()
    sym[:, 128:256] = sym[:, 256:384][:, ::-1]
    assert looks_dual_fisheye(sym) is not True


def test_v360_dual_fisheye_refused_equirect_not(clip, tmp_path, capsys):
    assert Source.open(clip).projection == "equirect"  # the genuine equirect opens
    fe = tmp_path / "fe.mp4"
    to_dfisheye(clip, fe)
    with pytest.raises(InputError) as e:
        Source.open(fe)
    msg = str(e.value)
    assert str(fe) in msg and "--projection dfisheye --lens-fov" in msg and "\n" not in msg
    assert Source.open(fe, projection="dfisheye").projection == "dfisheye"
    assert Source.open(fe, projection="equirect").projection == "equirect"  # the user's word wins
    # Through a command: exit 2, one line, nothing written.
    out = tmp_path / "v.png"
    assert main(["viewport", str(fe), "-o", str(out), "--yaw", "0", "--pitch", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--projection dfisheye --lens-fov" in err[0] and not out.exists()


def test_aspect_refusals_list_the_projections_that_fit(tmp_path):
    assert fitting_projections(3072, 2048) == ["c3x2", "eac"]
    assert fitting_projections(6144, 1024) == ["c6x1"]
    assert fitting_projections(2048, 1024) == ["equirect", "dfisheye"]
    assert fitting_projections(1920, 1080) == []
    for size, want in (((192, 128), "--projection c3x2, --projection eac"),
                       ((384, 64), "--projection c6x1")):  # fmt: skip
        p = tmp_path / f"{size[0]}x{size[1]}.png"
        Image.fromarray(np.full((size[1], size[0], 3), 128, np.uint8)).save(p)
        with pytest.raises(InputError) as e:
            Source.open(p, still=(None, None))
        assert str(p) in str(e.value) and f"its layout fits {want}" in str(e.value)
    # A projection given that does not fit: the ones that do.
    p = tmp_path / "192x128.png"
    with pytest.raises(InputError) as e:
        Source.open(p, projection="dfisheye", still=(None, None))
    assert str(e.value).startswith(str(p)) and "--projection eac" in str(e.value)


@pytest.mark.real_data
@pytest.mark.slow
def test_real_equirect_never_flagged_its_dual_fisheye_always(tmp_path):
    """Every 2:1 file of the real data opens as equirect; its v360 dual fisheye is refused.
    (bench/projection_guard.py measures every frame.)"""
    files = sorted(
        p for p in REAL.rglob("*") if p.suffix.lower() in (".mp4", ".webm", ".jpg", ".png")
    )
    assert len(files) >= 8, files
    opened = refused = 0
    for f in files:
        layout, stereo = STEREO.get(f.name, ("mono", "2d"))
        try:
            Source.open(f, layout=layout, still=(None, None))
        except InputError as e:
            assert "looks like dual fisheye" not in str(e), e  # only the 16:9 stills are refused
            continue
        opened += 1
        fe = tmp_path / (f.stem + (".png" if f.suffix in (".jpg", ".png") else ".mp4"))
        to_dfisheye(f, fe, stereo=stereo)
        with pytest.raises(InputError, match="--projection dfisheye --lens-fov"):
            Source.open(fe, still=(None, None))
        refused += 1
    assert opened == refused >= 8
