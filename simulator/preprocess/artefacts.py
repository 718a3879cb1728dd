"""Frames whose flow is not motion: codec keyframes, hard cuts, fades and static overlays appearing.

Optical flow reads every change between two frames as motion. Four kinds of change are
not motion a viewer's vestibular system would dispute, yet they read as the largest
flow of a video:

``keyframe``
    the flow jumps in almost every direction at once for one frame (an encoder's
    keyframe after a run of blurry predicted frames, most visibly on a regular period).
``cut``
    a hard cut: one frame whose picture is unrelated to the previous one.
``fade``
    a fade to or from black (or any flat colour): the picture's contrast changes
    steadily for several frames; flat frames of the fade included.
``overlay``
    a static overlay (a title, a logo) appearing: a region that moved with the scene
    comes to rest while the rest of the picture keeps moving; the frames of its
    appearance.

Signals: one grayscale pass over the video at :data:`SIGNAL_SIZE` (frame mean, contrast,
correlation with the previous frame, mean absolute change per block of
:data:`BLOCKS`), and the window matrix ``pof_dps`` (T, P, Y) of the video's grid. Row
``t`` of both is the change from frame ``t - 1`` to ``t`` (row 0 repeats row 1, as in a
grid file). Thresholds are stated beside each detector and measured in
``bench/artefacts.py`` (docs/screen.md).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_input_file
from simulator.media.video import iter_frames, probe

__all__ = [
    "ARTEFACT_KINDS",
    "Artefacts",
    "FrameSignals",
    "SignalCollector",
    "artefacts_for_grid",
    "artefacts_from_meta",
    "artefacts_meta",
    "detect_artefacts",
    "frame_signals",
    "load_artefacts",
    "no_artefacts",
    "save_artefacts",
    "stored_artefacts",
]

#: The kinds, in the order a frame carrying two is labelled (the first wins).
ARTEFACT_KINDS: tuple[str, ...] = ("cut", "fade", "keyframe", "overlay")

#: Size (W, H) of the grayscale picture the signals are taken from.
SIGNAL_SIZE = (128, 64)
#: Blocks (columns, rows) of that picture for the per-block change.
BLOCKS = (32, 16)

# One-frame spikes: the frame against the median of its neighbours +-_NB frames.
_NB = 3
_SPREAD_RATIO = 1.5  # a window "jumps" when its flow exceeds 1.5x its neighbours' median
_SPREAD_FLOOR_DPS = 0.5  # ... plus this, so that a still scene's noise does not jump
_SPREAD_MIN = 0.6  # share of windows that jump at once (everywhere: keyframe or cut)
_DIFF_RATIO = 1.6  # picture change against the 90th percentile of the +-1 s around it
_DIFF_RATIO_PERIODIC = 1.25  # ... on a regular period (most of its frames reset)
_DIFF_FLOOR = 0.6  # gray levels (0..255)
_CUT_DECORR = 0.5  # a cut: 1 - correlation of the 16 x 8 pictures above this ...
_CUT_HIST = 0.3  # ... or the gray histogram changes by >= 0.3 (L1, of 2) ...
_CUT_HIST_RATIO = 4.0  # ... and >= 4x the 90th percentile of its changes within 1 s
_CUT_DECORR_RATIO = 4.0  # ... and this many times its neighbours'
# Fades: the contrast changes by >= _FADE_STEP (log) every frame for >= _FADE_MIN_FRAMES,
# by a factor >= exp(_FADE_TOTAL) in all; flat frames (contrast < _FLAT_STD) beside them.
_FADE_STEP = 0.01
_FADE_MIN_FRAMES = 5
_FADE_TOTAL = math.log(1.5)
_FADE_R2 = 0.8
_FADE_SHARE = 0.8  # share of the 16 x 8 cells that change the same way
_FLAT_STD = 2.0
# Overlays: a block at rest (change < _REST of the picture's median change, which must be
# >= _MOVING gray levels) for >= _REST_S seconds, moving (>= _MOVE of the median) for the
# _REST_S before its appearance; at least _MIN_BLOCKS such blocks appearing together.
_REST = 0.15
_REST_ABS = 0.35  # ... and below this many gray levels: still pixels, not a quiet part of the scene
_MOVE = 0.5
_MOVING = 0.8
_REST_S = 1.0
_MIN_BLOCKS = 2


@dataclass(frozen=True)
class FrameSignals:
    """Per-frame picture signals of a video (row t: frame t - 1 -> t; row 0 = row 1).

    mean, std : (T,) gray level 0..255 and its standard deviation (contrast)
    corr : (T,) correlation of frame t with frame t - 1 (1 = same picture)
    block_diff : (T, B) mean absolute change per block (gray levels)
    coarse : (T, 128) the picture at 16 x 8 (gray levels), for fades
    fps : frames per second
    hist : (T,) L1 distance between the 32-bin gray histograms of frames t - 1 and t
        (0..2; camera motion over a 360 picture hardly changes it, a cut does)
    """

    mean: NDArray[np.float64]
    std: NDArray[np.float64]
    corr: NDArray[np.float64]
    block_diff: NDArray[np.float32]
    coarse: NDArray[np.float32]
    fps: float
    hist: NDArray[np.float64] | None = None

    @property
    def n_frames(self) -> int:
        return int(self.mean.size)


@dataclass(frozen=True)
class Artefacts:
    """Artefact frames of a video: ``kind`` (T,) per frame (``""`` = none), ``events``
    (one dict per run of frames: kind, start_frame, end_frame inclusive, start_s, end_s),
    and ``keyframe_period`` (frames, or None when keyframes are not periodic)."""

    kind: tuple[str, ...]
    events: tuple[dict, ...] = ()
    keyframe_period: int | None = None
    meta: dict = field(default_factory=dict, compare=False)

    @property
    def mask(self) -> NDArray[np.bool_]:
        """(T,) True on an artefact frame."""
        return np.array([k != "" for k in self.kind], dtype=bool)

    def counts(self) -> dict[str, int]:
        """Frames per kind."""
        return {k: sum(x == k for x in self.kind) for k in ARTEFACT_KINDS}

    def rows(self, frames) -> list[str]:
        """The kind of each video frame number in ``frames`` (``""`` outside the video)."""
        n = len(self.kind)
        return [self.kind[int(f)] if 0 <= int(f) < n else "" for f in frames]


def no_artefacts(n_frames: int) -> Artefacts:
    """``n_frames`` clean frames (detection switched off)."""
    return Artefacts(("",) * int(n_frames), meta={"detected": False})


class SignalCollector:
    """Builds :class:`FrameSignals` one frame at a time (a decoding pass that does
    something else too, e.g. sphere preprocessing, feeds it): ``add(gray frame)``, then
    ``result(fps)``. Keeps a few numbers per frame, not the frames."""

    def __init__(self) -> None:
        self.means: list[float] = []
        self.stds: list[float] = []
        self.corrs: list[float] = []
        self.blocks: list[NDArray] = []
        self.coarse: list[NDArray] = []
        self.hists: list[float] = []
        self._prev: NDArray | None = None
        self._hist: NDArray | None = None

    def add(self, frame: NDArray[np.uint8]) -> None:
        """One gray frame (H, W) uint8 of the video, in order."""
        bw, bh = BLOCKS
        w, h = SIGNAL_SIZE
        g = cv2.resize(frame, SIGNAL_SIZE, interpolation=cv2.INTER_AREA).astype(np.float32)
        self.means.append(float(g.mean()))
        self.stds.append(float(g.std()))
        self.coarse.append(cv2.resize(g, (16, 8), interpolation=cv2.INTER_AREA).ravel())
        hist = np.bincount(np.clip(g, 0, 255).astype(np.uint8).ravel() // 8, minlength=32) / g.size
        self.hists.append(0.0 if self._hist is None else float(np.abs(hist - self._hist).sum()))
        self._hist = hist
        if self._prev is None:
            self.corrs.append(1.0)
            self.blocks.append(np.zeros(bw * bh, np.float32))
        else:
            a, b = (
                self.coarse[-2] - self.coarse[-2].mean(),
                self.coarse[-1] - self.coarse[-1].mean(),
            )
            den = float(np.sqrt((a * a).sum() * (b * b).sum()))
            self.corrs.append(float((a * b).sum() / den) if den > 1e-6 else 1.0)
            d = np.abs(g - self._prev).reshape(bh, h // bh, bw, w // bw).mean(axis=(1, 3))
            self.blocks.append(d.ravel().astype(np.float32))
        self._prev = g

    def result(self, fps: float, source: str = "video") -> FrameSignals:
        """The signals so far (InputError for fewer than 2 frames)."""
        if len(self.means) < 2:
            raise InputError(f"{source}: fewer than 2 frames; artefact detection needs a video")
        corr = np.array(self.corrs)
        corr[0] = corr[1]
        bd = np.stack(self.blocks)
        bd[0] = bd[1]
        hist = np.array(self.hists)
        hist[0] = hist[1]
        return FrameSignals(
            np.array(self.means),
            np.array(self.stds),
            corr,
            bd,
            np.stack(self.coarse),
            float(fps),
            hist,
        )


def frame_signals(
    video, *, layout: str = "mono", eye: str = "left", start: int = 0, end: int | None = None
) -> FrameSignals:
    """One grayscale decoding pass over frames ``start <= i < end`` of ``video``
    (InputError for a still image or fewer than 2 frames)."""
    info = probe(video)
    if not info.is_video:
        raise InputError(f"{video}: is a still image; artefact detection needs a video")
    col = SignalCollector()
    for f in iter_frames(video, fmt="gray", layout=layout, eye=eye, start=start, end=end):
        col.add(f)
    return col.result(info.fps, str(video))


def _neighbour_median(x: NDArray, nb: int = _NB) -> NDArray:
    """Per row, the median of rows t-nb..t+nb except t itself (rows along axis 0)."""
    T = x.shape[0]
    out = np.empty_like(x, dtype=np.float64)
    for t in range(T):
        idx = [i for i in range(max(0, t - nb), min(T, t + nb + 1)) if i != t]
        out[t] = np.median(x[idx], axis=0) if idx else x[t]
    return out


def _context_p90(x: NDArray, half: int) -> NDArray:
    """Per frame, the 90th percentile of ``x`` over +-``half`` frames, the frame itself left out."""
    T = x.size
    out = np.empty(T)
    for t in range(T):
        ctx = np.concatenate([x[max(0, t - half) : t], x[t + 1 : t + half + 1]])
        out[t] = np.percentile(ctx, 90) if ctx.size else x[t]
    return out


def _spikes(sig: FrameSignals | None, pof_dps) -> tuple[NDArray, NDArray, NDArray]:
    """``(flow spread, picture jump ratio, cut)`` per frame: the share of windows whose
    flow jumps, the picture's change over the 90th percentile of the changes within 1 s
    around it (a keyframe resets the picture), and whether the coarse picture is
    unrelated to the previous one (a cut)."""
    T = sig.n_frames if sig is not None else int(np.shape(pof_dps)[0])
    spread = np.zeros(T)
    if pof_dps is not None:
        flat = np.asarray(pof_dps, np.float64).reshape(np.shape(pof_dps)[0], -1)[:T]
        ref = _neighbour_median(flat)
        spread[: flat.shape[0]] = np.mean(flat > _SPREAD_RATIO * ref + _SPREAD_FLOOR_DPS, axis=1)
    if sig is None:
        return spread, np.zeros(T), np.zeros(T, bool)
    g = np.mean(sig.block_diff, axis=1, dtype=np.float64)
    jump = np.where(
        g >= _DIFF_FLOOR, g / np.maximum(_context_p90(g, max(_NB, round(sig.fps))), 1e-3), 0.0
    )
    dec = 1.0 - sig.corr
    cut = (dec > _CUT_DECORR) & (dec > _CUT_DECORR_RATIO * _neighbour_median(dec))
    if sig.hist is not None:  # the picture's histogram jumps (a fade's changes gradually)
        h = np.asarray(sig.hist, np.float64)
        cut |= (h >= _CUT_HIST) & (h >= _CUT_HIST_RATIO * _context_p90(h, max(_NB, round(sig.fps))))
    return spread, jump, cut


def _trend(y: NDArray, half: int) -> tuple[NDArray, NDArray]:
    """Per frame, the slope (per frame) and R^2 of a straight line through ``y`` over
    +-``half`` frames."""
    T = y.size
    slope, r2 = np.zeros(T), np.zeros(T)
    for t in range(T):
        seg = y[max(0, t - half) : t + half + 1]
        if seg.size < 3:
            continue
        x = np.arange(seg.size) - (seg.size - 1) / 2
        k = float((x * (seg - seg.mean())).sum() / (x * x).sum())
        res = seg - seg.mean() - k * x
        tot = float(((seg - seg.mean()) ** 2).sum())
        slope[t] = k
        r2[t] = 1.0 - float((res * res).sum()) / tot if tot > 1e-12 else 0.0
    return slope, r2


def _fades(sig: FrameSignals) -> NDArray[np.bool_]:
    """Frames of a steady change of contrast or brightness (a fade), and flat frames
    next to one: a straight-line trend over +-_FADE_MIN_FRAMES frames with slope >=
    _FADE_STEP (log per frame) and R^2 >= _FADE_R2, lasting until the picture changed by
    a factor >= exp(_FADE_TOTAL)."""
    T = sig.n_frames
    out = np.zeros(T, bool)
    c = sig.coarse.astype(np.float64)
    dev = np.abs(c - c.mean(axis=1, keepdims=True))
    for y, cells in (
        (np.log(np.maximum(sig.std, 0.5)), dev),
        (np.log(np.maximum(sig.mean, 0.5)), c),
    ):
        slope, r2 = _trend(y, _FADE_MIN_FRAMES)
        run = (np.abs(slope) >= _FADE_STEP) & (r2 >= _FADE_R2)
        t = 0
        while t < T:
            if not run[t]:
                t += 1
                continue
            e = t
            while e + 1 < T and run[e + 1] and np.sign(slope[e + 1]) == np.sign(slope[t]):
                e += 1
            # the whole picture takes part (an overlay appearing changes only its region)
            d = np.sign(y[e] - y[max(t - 1, 0)]) * (cells[e] - cells[max(t - 1, 0)])
            if abs(y[e] - y[max(t - 1, 0)]) >= _FADE_TOTAL and np.mean(d > 0) >= _FADE_SHARE:
                out[t : e + 1] = True
            t = e + 1
    flat = sig.std < _FLAT_STD
    if out.any():  # flat frames joined to a fade (the black of a fade to black)
        grow = out.copy()
        for t in range(1, T):
            grow[t] |= flat[t] and grow[t - 1]
        for t in range(T - 2, -1, -1):
            grow[t] |= flat[t] and grow[t + 1]
        out = grow
    return out


def _overlays(sig: FrameSignals) -> NDArray[np.bool_]:
    """Frames in which a static region appears over a moving picture."""
    T = sig.n_frames
    d = sig.block_diff.astype(np.float64)
    g = np.median(d, axis=1)
    moving = g >= _MOVING
    rel = d / np.maximum(g, 1e-6)[:, None]
    rest = (rel < _REST) & (d < _REST_ABS) & moving[:, None]
    n = max(2, round(_REST_S * sig.fps))
    out = np.zeros(T, bool)
    # start of a rest run of >= n frames, per block: rest[t..t+n) all true, rest[t-1] false
    csum = np.cumsum(np.vstack([np.zeros((1, d.shape[1])), rest]), axis=0)
    starts = []
    for t in range(n + 1, T - n + 1):
        full = (csum[t + n] - csum[t]) == n
        new = full & ~rest[t - 1]
        if new.sum() == 0:
            continue
        before = np.median(rel[t - n : t - 1][:, new], axis=0) >= _MOVE
        hit = np.flatnonzero(new)[before]
        if hit.size:
            starts.append((t, hit))
    for t, hit in starts:
        if sum(h.size for s, h in starts if abs(s - t) <= 2) < _MIN_BLOCKS:
            continue
        t0 = t - 1
        while t0 - 1 >= 0 and np.median(rel[t0 - 1, hit]) < 1.0 - _REST and moving[t0 - 1]:
            t0 -= 1
        out[t0:t] = True
    return out


def _on_period(strong: NDArray, weak: NDArray) -> NDArray[np.bool_]:
    """Weak resets that keep a regular period: the period of the strong ones (>= 3), else
    the commonest gap between weak ones, if >= 70 % of the frames on it (>= 4, >= 5 frames
    apart) are weak resets; those frames."""
    T = weak.size
    out = np.zeros(T, bool)
    for cand in (strong, weak):
        f = np.flatnonzero(cand[1:]) + 1
        if f.size < (3 if cand is strong else 4):
            continue
        vals, counts = np.unique(np.diff(f), return_counts=True)
        p = int(vals[np.argmax(counts)])
        on = np.zeros(T, bool)
        on[int(f[0]) % p :: p] = True
        on[0] = False
        if p >= 5 and on.sum() >= 4 and (weak[on]).mean() >= 0.7:
            return on & weak
    return out


def _periodic(frames: list[int]) -> int | None:
    """The keyframe period when most gaps between detected keyframes are one value (or
    multiples of it: a keyframe missed)."""
    if len(frames) < 3:
        return None
    gaps = np.diff(sorted(frames))
    g0 = int(gaps.min())
    if g0 >= 2 and np.mean(gaps % g0 == 0) >= 0.8:
        return g0
    vals, counts = np.unique(gaps, return_counts=True)
    k = int(np.argmax(counts))
    return int(vals[k]) if counts[k] >= max(2, 0.5 * gaps.size) else None


def detect_artefacts(
    sig: FrameSignals | None, pof_dps=None, *, fps: float | None = None
) -> Artefacts:
    """Artefact frames of a video from its picture signals and/or its grid's window
    matrix ``pof_dps`` (T, P, Y) deg/s (row t: frames t - 1 -> t).

    Without ``sig`` only the flow's one-frame spikes are seen (keyframes and cuts, all
    labelled ``keyframe``). The rules and thresholds are in the module's source, beside
    each detector; docs/screen.md gives the measured recall and false alarms.
    """
    if sig is None and pof_dps is None:
        raise InputError("artefact detection needs the video's signals or its flow")
    T = sig.n_frames if sig is not None else int(np.shape(pof_dps)[0])
    rate = float(sig.fps if sig is not None else (fps or 0.0))
    spread, jump, cut = _spikes(sig, pof_dps)
    everywhere = spread >= _SPREAD_MIN
    labels = {
        "cut": cut,
        "fade": _fades(sig) if sig is not None else np.zeros(T, bool),
        # with the picture: a whole-picture flow jump where the picture resets; flow only: the jump
        "keyframe": ((jump >= _DIFF_RATIO) if sig is not None else everywhere) & ~cut,
        "overlay": _overlays(sig) if sig is not None else np.zeros(T, bool),
    }
    labels["keyframe"][0] = labels["cut"][0] = False  # row 0 repeats row 1
    if sig is not None:  # weaker resets on a regular period count too
        labels["keyframe"] |= _on_period(labels["keyframe"], (jump >= _DIFF_RATIO_PERIODIC) & ~cut)
    period = _periodic(np.flatnonzero(labels["keyframe"]).tolist())
    kind = [""] * T
    for k in reversed(ARTEFACT_KINDS):  # the first kind in ARTEFACT_KINDS wins
        for t in np.flatnonzero(labels[k]):
            kind[t] = k
    events: list[dict] = []
    for t, k in enumerate(kind):
        if k and events and events[-1]["kind"] == k and events[-1]["end_frame"] == t - 1:
            events[-1]["end_frame"] = t
        elif k:
            events.append({"kind": k, "start_frame": t, "end_frame": t})
    for e in events:
        e["start_s"] = e["start_frame"] / rate if rate else math.nan
        e["end_s"] = e["end_frame"] / rate if rate else math.nan
    return Artefacts(tuple(kind), tuple(events), period, meta={"detected": True,
                     "signals": "picture+flow" if sig is not None else "flow"})  # fmt: skip


def artefacts_meta(art: Artefacts) -> dict:
    """``art`` as a grid file's ``meta["artefacts"]``: its runs (events), not one entry per
    frame, so that the meta stays small for long videos."""
    return {"n_frames": len(art.kind), "keyframe_period": art.keyframe_period,
            "signals": art.meta.get("signals", ""), "events": [dict(e) for e in art.events]}  # fmt: skip


def artefacts_from_meta(d: dict) -> Artefacts:
    """The :class:`Artefacts` of a grid file's ``meta["artefacts"]`` (InputError if malformed)."""
    try:
        kind = [""] * int(d["n_frames"])
        for e in d["events"]:
            if e["kind"] not in ARTEFACT_KINDS:
                raise ValueError(e["kind"])
            for t in range(int(e["start_frame"]), int(e["end_frame"]) + 1):
                kind[t] = e["kind"]
    except (KeyError, TypeError, ValueError, IndexError):
        raise InputError("grid meta artefacts: malformed; preprocess the video again") from None
    return Artefacts(tuple(kind), tuple(d["events"]), d.get("keyframe_period"),
                     meta={"detected": True, "signals": d.get("signals", ""), "stored": True})  # fmt: skip


def artefacts_for_grid(grid, *, video=None) -> Artefacts:
    """The artefacts of a grid file's rows: those its preprocessing stored
    (``meta["artefacts"]``), else from its video's pictures and its flow when the video
    (``video``, else the path its meta records) is there (one decoding pass), else from
    its flow only (keyframes and cuts, labelled ``keyframe``)."""
    m = grid.meta
    if isinstance(m.get("artefacts"), dict) and video is None:
        art = artefacts_from_meta(m["artefacts"])
        if len(art.kind) == grid.n_frames:
            return art
    src = video or m.get("video", {}).get("path")
    if src and Path(src).is_file():
        sig = frame_signals(src, layout=m.get("layout", "mono"), eye=m.get("eye", "left"),
                            start=int(m.get("start_frame", 0)),
                            end=int(m.get("start_frame", 0)) + grid.n_frames)  # fmt: skip
        if sig.n_frames == grid.n_frames:
            return detect_artefacts(sig, grid.pof_dps)
    return detect_artefacts(None, grid.pof_dps, fps=grid.fps)


def save_artefacts(path, art: Artefacts) -> None:
    """``art`` as JSON (atomic): the kinds per frame, the events, the keyframe period."""
    d = {"format": "vimsim-artefacts", "version": 1, "kind": list(art.kind),
         "events": list(art.events), "keyframe_period": art.keyframe_period, "meta": art.meta}  # fmt: skip
    with atomic_output(path) as tmp:
        Path(tmp).write_text(json.dumps(d, allow_nan=False, default=float) + "\n")


def load_artefacts(path) -> Artefacts:
    """Read what :func:`save_artefacts` wrote (InputError if it is not that)."""
    p = check_input_file(path, "artefacts")
    try:
        d = json.loads(p.read_text())
        assert d.get("format") == "vimsim-artefacts"
        kind = tuple(str(k) for k in d["kind"])
        assert all(k in ("", *ARTEFACT_KINDS) for k in kind)
    except (ValueError, KeyError, AssertionError, TypeError, RecursionError):
        raise InputError(f"{p}: not a vimsim artefacts file") from None
    return Artefacts(kind, tuple(d.get("events", ())), d.get("keyframe_period"), d.get("meta", {}))


def stored_artefacts(grid) -> Artefacts | None:
    """The artefacts a grid file's preprocessing stored (``preprocess --artefacts``, a
    screening), or None: what ``render`` and ``frames`` hold the opacity through."""
    d = grid.meta.get("artefacts")
    if not isinstance(d, dict):
        return None
    art = artefacts_from_meta(d)
    return art if len(art.kind) == grid.n_frames else None
