"""Frame folders compared with goldens: PSNR, mean absolute difference and SSIM per frame, diff images, updating goldens.

Frames are matched by file name (``*.png`` in the folder; ``frames.json`` and
subfolders are not frames). SSIM is scikit-image's
(:func:`skimage.metrics.structural_similarity`, 7 x 7 window, per channel, data range
255); PSNR is ``10 log10(255^2 / MSE)`` (infinite for identical frames); the mean
absolute difference is in 8-bit levels over all channels. A frame passes when its PSNR
is at least ``psnr_db`` and its mean absolute difference at most ``max_diff``.
"""

from __future__ import annotations

import datetime
import json
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, check_output_dir, json_text
from simulator.viewing.frames import FRAMES_JSON

__all__ = [
    "DEFAULT_MAX_DIFF",
    "DEFAULT_PSNR_DB",
    "CompareReport",
    "FrameScore",
    "backup_folder",
    "compare_dirs",
    "update_goldens",
]

#: Default thresholds, from bench/frames_tolerance.py (docs/frames.md): llvmpipe against
#: itself is byte-identical (PSNR inf); 1 deg of yaw (18.1 dB), grain 1.5 -> 2 deg (16.4 dB)
#: and red + 8 levels (37.6 dB, MAD 1.74) fail; red + 4 levels (43.6 dB, MAD 0.87) passes.
#: The margin is for other GL drivers (not measured: no GPU was lent).
DEFAULT_PSNR_DB = 40.0
DEFAULT_MAX_DIFF = 1.0
_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
REPORT_JSON = "compare.json"


@dataclass(frozen=True)
class FrameScore:
    """One frame's measures. ``diff`` / ``side_by_side``: files written when it fails."""

    name: str
    psnr_db: float
    mean_abs_diff: float
    ssim: float
    passed: bool
    diff: str | None = None
    side_by_side: str | None = None

    def why(self, psnr_db: float, max_diff: float) -> str:
        """One line naming the frame, the failing measures and the diff file."""
        parts = []
        if self.psnr_db < psnr_db:
            parts.append(f"PSNR {self.psnr_db:.2f} dB < {psnr_db:g} dB")
        if self.mean_abs_diff > max_diff:
            parts.append(f"mean abs diff {self.mean_abs_diff:.3f} > {max_diff:g}")
        s = f"frame {self.name}: " + ", ".join(parts) + f" (SSIM {self.ssim:.4f})"
        if self.diff:
            s += f"; diff {self.diff}, side by side {self.side_by_side}"
        return s


@dataclass(frozen=True)
class CompareReport:
    """All frames' scores, the thresholds and where the report went; ``changes``: what
    differs between the two ``frames.json`` (:func:`frames_json_changes`), first the cause."""

    scores: tuple[FrameScore, ...]
    psnr_db: float
    max_diff: float
    report_dir: str | None
    changes: tuple[str, ...] = ()

    @property
    def failures(self) -> tuple[FrameScore, ...]:
        return tuple(s for s in self.scores if not s.passed)

    @property
    def passed(self) -> bool:
        return not self.failures


#: Pose and opacity differences below these are equal (degrees; opacity 0..1).
POSE_TOL_DEG = 1e-6
OPACITY_TOL = 1e-6


def _index(folder: Path) -> dict | None:
    try:
        d = json.loads((folder / FRAMES_JSON).read_text())
    except (OSError, ValueError, RecursionError):
        return None
    return d if isinstance(d, dict) and isinstance(d.get("frames"), list) else None


def _differs(a, b) -> list[str]:
    """``key: a -> b`` for each differing key of two flat-ish dicts."""
    keys = sorted(set(a) | set(b))
    return [f"{k} {a.get(k)!r} -> {b.get(k)!r}" for k in keys if a.get(k) != b.get(k)]


def frames_json_changes(golden: dict | None, new: dict | None, pixels_differ: bool) -> list[str]:
    """What changed between the golden and the new ``frames.json``, the likely cause
    first: ``the head path changed`` (a frame's pose), ``the opacity changed``, ``the
    input files differ`` (video, head path, grid names), ``the render settings changed``,
    then versions; ``the renderer changed`` when the frames differ though all of those
    are the same. Empty when nothing differs
    (or a ``frames.json`` is missing: then one line says so)."""
    if golden is None or new is None:
        return ["no frames.json in " + ("the goldens" if golden is None else "the new frames")
                + ": cannot tell what changed"] if pixels_differ else []  # fmt: skip
    out: list[str] = []
    old_rows = {r.get("file"): r for r in golden["frames"] if isinstance(r, dict)}
    pose, opac = [], []
    for r in new["frames"]:
        g = old_rows.get(r.get("file"))
        if not isinstance(r, dict) or g is None:
            continue
        d = max(abs(float(r.get(k, 0)) - float(g.get(k, 0)))
                for k in ("yaw_deg", "pitch_deg", "roll_deg"))  # fmt: skip
        if d > POSE_TOL_DEG:
            pose.append((r["file"], d))
        if abs(float(r.get("opacity", 0)) - float(g.get("opacity", 0))) > OPACITY_TOL:
            opac.append(r["file"])
    if pose:
        f, d = max(pose, key=lambda x: x[1])
        out.append(f"the head path changed: {len(pose)} frame(s) have another pose (up to "
                   f"{d:.3g} deg, {f})")  # fmt: skip
    if opac:
        out.append(f"the opacity changed in {len(opac)} frame(s) ({opac[0]}): EPOF, grid or rule")
    inputs = _differs({k: golden.get(k) for k in ("video", "headpath", "grid")},
                      {k: new.get(k) for k in ("video", "headpath", "grid")})  # fmt: skip
    if inputs:
        out.append("the input files differ: " + "; ".join(inputs))
    settings = _differs(golden.get("renderer") or {}, new.get("renderer") or {})
    settings += _differs({k: golden.get(k) for k in ("layout", "hold", "video_size", "fps")},
                         {k: new.get(k) for k in ("layout", "hold", "video_size", "fps")})  # fmt: skip
    if settings:
        out.append("the render settings changed: " + "; ".join(settings))
    versions = _differs(golden.get("versions") or {}, new.get("versions") or {})
    if pixels_differ and not (pose or opac or settings or inputs):
        out.insert(0, "the renderer changed: same poses, opacity and settings, other pixels"
                   + (f" ({'; '.join(versions)})" if versions else ""))  # fmt: skip
    elif versions:
        out.append("versions: " + "; ".join(versions))
    return out


def _frame_files(folder: Path, what: str) -> dict[str, Path]:
    """``{name: path}`` of the frames (PNG files) in ``folder``; InputError for any other
    file (``frames.json`` and subfolders aside) and for a ``.png`` that is not a PNG."""
    if not folder.is_dir():
        raise InputError(f"{folder}: {what} folder not found")
    out = {}
    for p in sorted(folder.iterdir()):
        if p.is_dir() or p.name == FRAMES_JSON or p.name.startswith("."):
            continue
        with open(p, "rb") as f:
            head = f.read(8)
        if not p.name.lower().endswith(".png") or head != _PNG_MAGIC:
            raise InputError(
                f"{p}: not a PNG; a {what} folder holds only frames (PNG) and frames.json"
            )
        out[p.name] = p
    if not out:
        raise InputError(f"{folder}: {what} folder has no frames (*.png)")
    return out


def _read_png(p: Path) -> NDArray[np.uint8]:
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(p) as im:
            if im.format != "PNG":
                raise InputError(f"{p}: not a PNG (a {im.format} image)")
            return np.asarray(im.convert("RGB"))
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError) as e:
        raise InputError(f"{p}: not a readable PNG ({e})") from None


def _measures(a: NDArray[np.uint8], b: NDArray[np.uint8]) -> tuple[float, float, float]:
    from skimage.metrics import structural_similarity

    d = a.astype(np.float64) - b.astype(np.float64)
    mse = float(np.mean(d * d))
    psnr = math.inf if mse == 0 else 10.0 * math.log10(255.0**2 / mse)
    mad = float(np.mean(np.abs(d)))
    win = min(7, min(a.shape[:2]) - (1 - min(a.shape[:2]) % 2))
    ssim = float(structural_similarity(a, b, channel_axis=2, data_range=255, win_size=win))
    return psnr, mad, ssim


def _check_sets(new: dict, gold: dict, new_dir: Path, golden_dir: Path) -> None:
    missing = sorted(set(gold) - set(new))
    extra = sorted(set(new) - set(gold))
    if missing:
        raise InputError(
            f"{new_dir}: frame {missing[0]} of {golden_dir} is missing ({len(missing)} missing)"
        )
    if extra:
        raise InputError(
            f"{new_dir}: frame {extra[0]} has no golden in {golden_dir} ({len(extra)} extra)"
        )


def compare_dirs(
    new_dir,
    golden_dir,
    *,
    psnr_db: float = DEFAULT_PSNR_DB,
    max_diff: float = DEFAULT_MAX_DIFF,
    report_dir=None,
) -> CompareReport:
    """Compare every frame of ``new_dir`` with the same-named one in ``golden_dir``.

    Every input is checked before anything is written (InputError: a folder missing or
    the same as the other, a non-PNG file, missing or extra frames, another size). Then
    ``report_dir`` (default ``new_dir/compare``) gets, per failing frame,
    ``<name>.diff.png`` (absolute difference x 8, clipped) and ``<name>.side.png``
    (golden | new | diff), and ``compare.json`` with every frame's measures.
    """
    new_dir, golden_dir = Path(new_dir), Path(golden_dir)
    if not (psnr_db >= 0 and max_diff >= 0):
        raise InputError(f"thresholds must be >= 0; got --psnr {psnr_db} --max-diff {max_diff}")
    if new_dir.resolve() == golden_dir.resolve():
        raise InputError(f"{new_dir}: the frames and the golden folder are the same folder")
    new = _frame_files(new_dir, "frames")
    gold = _frame_files(golden_dir, "golden")
    _check_sets(new, gold, new_dir, golden_dir)
    pairs = {}
    for name in new:
        a, b = _read_png(new[name]), _read_png(gold[name])
        if a.shape != b.shape:
            raise InputError(
                f"{gold[name]}: golden is {b.shape[1]}x{b.shape[0]}, the new frame "
                f"{a.shape[1]}x{a.shape[0]}; render the frames at the goldens' size"
            )
        pairs[name] = (a, b)
    rep = Path(report_dir) if report_dir is not None else new_dir / "compare"
    if rep.resolve() == golden_dir.resolve() or golden_dir.resolve() in rep.resolve().parents:
        raise InputError(f"{rep}: the report must not go into the golden folder")
    if rep.resolve() == new_dir.resolve():
        raise InputError(
            f"{rep}: the report must not go into the frames folder (its diffs would be frames)"
        )

    scores = []
    for name, (a, b) in pairs.items():
        psnr, mad, ssim = _measures(a, b)
        ok = psnr >= psnr_db and mad <= max_diff
        scores.append(FrameScore(name, psnr, mad, ssim, ok))
    names = [
        f"{s.name.removesuffix('.png')}.{kind}.png" for s in scores if not s.passed
        for kind in ("diff", "side")
    ]  # fmt: skip
    # The one folder rule: a file of a report name that no earlier compare wrote is refused.
    rep = OutputFolder(rep, [*names, REPORT_JSON], "compare").prepare(
        [*new.values(), *gold.values()]
    )
    from PIL import Image

    final = []
    for s in scores:
        if not s.passed:
            a, b = pairs[s.name]
            diff = np.clip(np.abs(a.astype(np.int16) - b.astype(np.int16)) * 8, 0, 255).astype(
                np.uint8
            )
            stem = s.name.removesuffix(".png")
            dpath, spath = rep / f"{stem}.diff.png", rep / f"{stem}.side.png"
            for path, img in ((dpath, diff), (spath, np.concatenate([b, a, diff], axis=1))):
                with atomic_output(path) as tmp:
                    Image.fromarray(img).save(tmp, format="PNG")
            s = FrameScore(
                s.name, s.psnr_db, s.mean_abs_diff, s.ssim, False, str(dpath), str(spath)
            )
        final.append(s)
    changes = frames_json_changes(
        _index(golden_dir), _index(new_dir), any(s.psnr_db != math.inf for s in final)
    )
    report = CompareReport(tuple(final), float(psnr_db), float(max_diff), str(rep), tuple(changes))
    doc = {
        "changes": changes,
        "frames_dir": str(new_dir),
        "golden_dir": str(golden_dir),
        "psnr_db_min": psnr_db,
        "max_mean_abs_diff": max_diff,
        "passed": report.passed,
        "frames": [s.__dict__ for s in final],
    }
    with atomic_output(rep / REPORT_JSON) as tmp:
        Path(tmp).write_text(json_text(doc) + "\n")
    OutputFolder(rep, [*names, REPORT_JSON], "compare").complete()
    return report


def backup_folder(golden_dir: Path, now: datetime.datetime | None = None) -> Path:
    """A new dated folder beside ``golden_dir`` for the goldens an update replaces:
    ``GOLDEN.backup-YYYYMMDD-HHMMSS`` (UTC; ``-2``, ``-3`` ... when taken)."""
    now = now or datetime.datetime.now(datetime.UTC)
    base = golden_dir.parent / f"{golden_dir.name}.backup-{now:%Y%m%d-%H%M%S}"
    cand, k = base, 1
    while cand.exists() or cand.is_symlink():
        k += 1
        cand = base.with_name(f"{base.name}-{k}")
    return cand


def update_goldens(new_dir, golden_dir) -> tuple[list[str], Path | None]:
    """Copy the frames (and ``frames.json``) of ``new_dir`` over ``golden_dir`` (created),
    each atomically; golden frames with no new counterpart are removed only when the
    golden ``frames.json`` lists them (a ``frames`` run wrote them). The goldens replaced
    or removed (and the old ``frames.json``) are first copied to a dated backup folder
    beside ``golden_dir`` (:func:`backup_folder`). Returns the names copied and the
    backup folder (None when nothing was replaced)."""
    new_dir, golden_dir = Path(new_dir), Path(golden_dir)
    if new_dir.resolve() == golden_dir.resolve():
        raise InputError(f"{new_dir}: the frames and the golden folder are the same folder")
    new = _frame_files(new_dir, "frames")
    gold = (
        _frame_files(golden_dir, "golden")
        if golden_dir.is_dir() and any(p.suffix == ".png" for p in golden_dir.iterdir())
        else {}
    )
    listed = set()
    gj = golden_dir / FRAMES_JSON
    if gj.is_file():
        try:
            listed = {f["file"] for f in json.loads(gj.read_text())["frames"]}
        except (ValueError, KeyError, TypeError, RecursionError):
            raise InputError(f"{gj}: not a frames.json written by vimsim frames") from None
    stale = [n for n in gold if n not in new]
    unknown = [n for n in stale if n not in listed]
    if unknown:
        raise InputError(
            f"{gold[unknown[0]]}: golden frame has no new counterpart and was not written by "
            "vimsim frames; remove it by hand"
        )
    check_output_dir(golden_dir)
    old = [gold[n] for n in sorted(gold)] + ([gj] if gj.is_file() else [])
    backup = _backup(old, golden_dir) if old else None
    for name, p in new.items():
        with atomic_output(golden_dir / name) as tmp:
            shutil.copyfile(p, tmp)
    for n in stale:
        (golden_dir / n).unlink()
    if (new_dir / FRAMES_JSON).is_file():
        with atomic_output(gj) as tmp:
            shutil.copyfile(new_dir / FRAMES_JSON, tmp)
    return sorted(new), backup


def _backup(files: list[Path], golden_dir: Path) -> Path:
    """Copy ``files`` into a new :func:`backup_folder`, complete before it gets its name
    (a temporary folder renamed, so a half-made backup never looks like one)."""
    dest = backup_folder(golden_dir)
    tmp = dest.with_name(f".{dest.name}.tmp-{os.getpid()}")
    try:
        tmp.mkdir()
        for f in files:
            shutil.copy2(f, tmp / f.name)
        os.rename(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dest
