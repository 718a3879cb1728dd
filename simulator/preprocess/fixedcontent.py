"""Content fixed in the equirect frame (screen-fixed graphics, camera-fixed objects) and the decoder's key-frame flags.

Two kinds of picture content stay at one place of the equirect frame while the scene
moves, and both move the flow without being motion of the world:

``overlay`` (a screen-fixed graphic)
    a lower third, a logo, a title, an end card: composited onto the equirect picture,
    often animated (text typing, sliding, zooming). Left out of the opacity thresholds,
    statistics and moments from its appearance to its end, as the other artefacts.
``camera-fixed``
    a hand, a rig, a selfie stick, a thumb at the lens: physically attached to the camera,
    so it keeps its place in the equirect frame. Viewers *see* it, so its flow is kept in
    the EPOF (thresholds, statistics, opacity); only the frames in which it moves or
    enters are labelled, and never ranked as a provocative moment.

Both are found from the per-block signals of :mod:`simulator.preprocess.artefacts`
(128 x 64 gray picture, 32 x 16 blocks of 4 x 4 pixels: change per frame and spatial
contrast). A block is *fixed* at a frame when it is textured (contrast >=
:data:`TEXTURE`), still (change < :data:`STILL_REL` of the picture's median change and
< :data:`STILL_ABS` gray levels) and the picture moves (median change >= :data:`MOVING` gray levels), for
>= 60 % of the frames of the 1 s around it (``_fixed``). A group of >= :data:`MIN_BLOCKS`
fixed blocks for >= 0.5 s, whose neighbouring blocks change by >= 1.5 gray levels (median:
the scene moves right around it), is one piece of fixed content. It is a graphic when it
appears after the first second, away from the top and bottom block rows (zenith and nadir,
where rigs, sticks and hands are) and fills its bounding box as a panel does (>=
:data:`PANEL_FILL`); otherwise it is camera-fixed. An end card (a cut or fade to a mostly
flat, still picture whose rest animates) is a graphic too (``_cards``). The thresholds are
measured in ``bench/artefacts.py`` (docs/screen.md), with their limits.

Key frames: :func:`keyframe_flags` reads the container's packets (no decoding) and says
which frames the encoder marked as key frames (PyAV ``packet.is_keyframe``): a picture
reset is called a codec ``keyframe`` only on such a frame.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["MIN_BLOCKS", "MOVING", "PANEL_FILL", "STILL_ABS", "STILL_REL", "TEXTURE", "fixed_content",
           "keyframe_flags"]  # fmt: skip

#: A block with content: spatial standard deviation >= this many gray levels (a flat
#: block, e.g. clear sky, looks still whether or not it moves).
TEXTURE = 3.0
#: Still against the scene: the block's change below this share of the median change ...
STILL_REL = 0.25
#: ... and below this many gray levels (pixel-still: far content near the direction of
#: travel changes slowly too, but not this little)
STILL_ABS = 0.5
#: The picture moves: median block change >= this many gray levels (as artefacts' _MOVING).
MOVING = 0.8
#: Blocks of one piece of fixed content, at least.
MIN_BLOCKS = 3
#: A graphic fills at least this share of its bounding box (a panel, a box of text).
PANEL_FILL = 0.5
_RING = 1.5  # gray levels: the median change of the blocks around fixed content, at least
_FIXED_SHARE = 0.6  # share of the 1 s around a frame in which a block is fixed
_MIN_S = 0.5  # fixed content lasts at least this long
_ACTIVE = 1.5  # gray levels: a block of the content that changes (moves, animates)
_ACTIVE_SHARE = 0.1  # ... in this share of the content's box (>= 1 block): it moves / animates
_CARD_FLAT = 1.0  # an end card: blocks flatter than this (gray levels) ...
_CARD_SHARE = 0.5  # ... make up this share of the picture, still, while >= 2 blocks animate


def keyframe_flags(path, *, start: int = 0, end: int | None = None) -> NDArray[np.bool_] | None:
    """Per video frame ``start <= i < end`` (presentation order, as the decoder delivers
    them), whether its packet is marked as a key frame; None for a file without video
    packets or timestamps (a still image, an unreadable stream)."""
    import av

    try:
        with av.open(str(path)) as c:
            if not c.streams.video:
                return None
            s = c.streams.video[0]
            rows = [(pk.pts, bool(pk.is_keyframe)) for pk in c.demux(s)
                    if pk.size > 0 and not getattr(pk, "is_discard", False)]  # fmt: skip
    except (av.error.FFmpegError, OSError):
        return None
    if not rows or any(p is None for p, _ in rows):
        return None
    order = np.argsort(np.array([p for p, _ in rows], np.int64), kind="stable")
    flags = np.array([k for _, k in rows], bool)[order]
    return flags[start:end]


def _fixed(d: NDArray, s: NDArray, fps: float) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """``(fixed, now)``, (T, B) each: blocks fixed in the frame (textured, still against a
    moving scene, for most of the 1 s around each frame), and still at that frame."""
    g = np.median(d, axis=1)
    still = (d < STILL_REL * g[:, None]) & (d < STILL_ABS)
    now = (s >= TEXTURE) & still & (g >= MOVING)[:, None]
    n = max(3, round(fps))
    c = np.cumsum(np.vstack([np.zeros((1, d.shape[1])), now]), axis=0)
    T = d.shape[0]
    lo = np.clip(np.arange(T) - n // 2, 0, T)
    hi = np.clip(np.arange(T) + n // 2 + 1, 0, T)
    return (c[hi] - c[lo]) >= _FIXED_SHARE * (hi - lo)[:, None], now


def _ring(region: NDArray[np.bool_], shape) -> NDArray[np.bool_]:
    """The blocks next to ``region`` (8-neighbours; longitude wraps), not in it."""
    r = region.reshape(shape)
    p = np.pad(r, ((1, 1), (0, 0)))
    out = np.zeros_like(p)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            out |= np.roll(np.roll(p, dr, axis=0), dc, axis=1)
    return (out[1:-1] & ~r).ravel()


def _runs(x: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """``(first, last)`` of each run of True."""
    e = np.flatnonzero(np.diff(np.concatenate([[0], x.astype(np.int8), [0]])))
    return [(int(a), int(b) - 1) for a, b in zip(e[::2], e[1::2])]


def _active(d: NDArray, box: NDArray[np.bool_], first: int, last: int) -> NDArray[np.bool_]:
    """Frames first..last in which the content's box moves or animates (a share of its
    blocks change), as a (T,) mask."""
    T = d.shape[0]
    out = np.zeros(T, bool)
    need = max(1, round(_ACTIVE_SHARE * int(box.sum())))
    seg = np.sum(d[first : last + 1][:, box] >= _ACTIVE, axis=1) >= need
    out[first : last + 1] = seg
    return out


def _cards(d: NDArray, s: NDArray, fps: float, onset: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """End cards: from a cut or fade (``onset``), >= 0.5 s in which most blocks are flat
    and still while >= 2 blocks animate; those frames."""
    T = d.shape[0]
    card = (np.mean((s < _CARD_FLAT) & (d < 0.35), axis=1) >= _CARD_SHARE) & (
        np.sum(d >= _ACTIVE, axis=1) >= 2
    )
    out = np.zeros(T, bool)
    for a, b in _runs(card):
        if b - a + 1 >= _MIN_S * fps and onset[max(0, a - 3) : a + 1].any():
            out[a : b + 1] = True
    return out


def fixed_content(block_diff, block_std, fps: float, *, onset=None, shape=(16, 32)) -> dict:
    """Screen-fixed graphics and camera-fixed content of a video from its per-block
    signals (T, B) (change and contrast, gray levels; blocks row-major, ``shape`` =
    (rows, cols)). ``onset`` (T,) marks cuts and fades (end cards start at one).

    Returns ``{"overlay": (T,) bool, "camera-fixed": (T,) bool, "events": [...]}``: the
    frames in which a graphic appears or is on screen, the frames in which camera-fixed content
    enters or moves, and one event per piece of content (kind, first and last frame of its
    presence, its bounding box in blocks ``[row0, row1, col0, col1]`` and in degrees
    ``[lon0, lon1, lat0, lat1]``)."""
    d = np.asarray(block_diff, np.float64)
    s = np.asarray(block_std, np.float64)
    T = d.shape[0]
    rows, cols = shape
    fixed, now = _fixed(d, s, fps)
    n = max(3, round(fps))
    out = {"overlay": np.zeros(T, bool), "camera-fixed": np.zeros(T, bool), "events": []}
    for a, b in _runs(fixed.sum(axis=1) >= MIN_BLOCKS):
        if b - a + 1 < _MIN_S * fps:
            continue
        region = fixed[a : b + 1].mean(axis=0) >= 0.5
        if region.sum() < MIN_BLOCKS or np.median(d[a : b + 1][:, _ring(region, shape)]) < _RING:
            continue  # the scene right around it must move (a slow wall is no fixed content)
        rr, cc = np.divmod(np.flatnonzero(region), cols)
        r0, r1, c0, c1 = int(rr.min()), int(rr.max()), int(cc.min()), int(cc.max())
        box = np.zeros((rows, cols), bool)
        box[r0 : r1 + 1, c0 : c1 + 1] = True
        # its presence: from the first to the last frame its blocks are still, near the run
        still = np.flatnonzero(np.mean(now[:, region], axis=1) >= 0.5)
        a = int(still[(still >= a - n) & (still <= a)].min(initial=a))
        b = int(still[(still >= b) & (still <= b + n)].max(initial=b))
        fill = region.sum() / box.sum()
        graphic = a >= fps and 0 < r0 and r1 < rows - 1 and fill >= PANEL_FILL
        kind = "overlay" if graphic else "camera-fixed"
        # a graphic: from the quarter second before it is still (sliding, fading in) to its
        # end (its animation may lie in blocks its edges share with the scene); camera-fixed
        # content: the quarter second before it is still, then the frames in which it moves
        act = np.zeros(T, bool)
        act[a : b + 1] = True
        if not graphic:
            act = _active(d, region, a, b)
        act[max(0, a - round(fps / 4)) : a] = a >= fps
        out[kind] |= act
        out["events"].append({"kind": kind, "first": a, "last": b, "blocks": [r0, r1, c0, c1],
                              "region_deg": [c0 * 360 / cols - 180, (c1 + 1) * 360 / cols - 180,
                                             90 - (r1 + 1) * 180 / rows, 90 - r0 * 180 / rows]})  # fmt: skip
    if onset is not None:
        out["overlay"] |= _cards(d, s, fps, np.asarray(onset, bool))
    return out
