"""Review outputs of a viewing: a video (equirect with the viewport outline, eye view, EPOF strip) and a contact sheet.

:class:`ReviewWriter` is fed by :func:`simulator.render.render_video` (its ``on_frame``
callback) with each decoded equirect frame and the left eye's rendered image, and writes
``review.mp4``: on top, the equirect frame with the true outline of the view frustum
(its four edges sampled densely, rotated by the head pose and mapped to longitude and
latitude, so the curves bend as they do on the sphere; a segment crossing the +-180 deg
seam is split, a pole inside the view shows as an outline spanning all longitudes)
beside the eye view; below, a strip of EPOF and opacity over the whole render with a
cursor and the current values. :meth:`ReviewWriter.close` also writes the contact sheet
(eye views at evenly spaced times, labelled with time, yaw, pitch, EPOF and opacity).
Both files are written to temporary names and renamed when complete.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.fileio import atomic_output
from simulator.media.video import VideoWriter
from simulator.sphere.geometry import dir_to_lonlat, head_rotation, lonlat_to_equirect_xy

__all__ = ["STILL_NO_FLOW", "ReviewWriter", "frustum_outline_xy"]

_WHITE = (255, 255, 255)
_EPOF_RGB = (80, 160, 255)
_OP_RGB = (255, 90, 70)
_OUTLINE_RGB = (255, 220, 0)


def frustum_outline_xy(
    yaw_deg: float,
    pitch_deg: float,
    roll_deg: float,
    hfov_deg: float,
    vfov_deg: float,
    width: int,
    height: int,
    *,
    per_edge: int = 64,
) -> list[NDArray[np.float64]]:
    """The view frustum's outline in equirect pixel coordinates, as polylines.

    The four edges of the image rectangle (``tan`` of half the FOVs, head frame +x right,
    +y up, +z forward) are sampled with ``per_edge`` points each, rotated to the world
    by :func:`simulator.sphere.geometry.head_rotation` and mapped with
    :func:`simulator.sphere.geometry.lonlat_to_equirect_xy`. Returns a list of ``(n, 2)`` arrays
    (x, y in pixels, pixel centres at +0.5): the closed outline cut wherever it crosses
    the +-180 deg seam (a jump of more than half the width between neighbours).
    """
    tx, ty = math.tan(math.radians(hfov_deg) / 2), math.tan(math.radians(vfov_deg) / 2)
    s = np.linspace(-1.0, 1.0, per_edge, endpoint=False)
    edges = [
        np.stack([s * tx, np.full_like(s, ty)], -1),  # top, left to right
        np.stack([np.full_like(s, tx), -s * ty], -1),  # right, top to bottom
        np.stack([-s * tx, np.full_like(s, -ty)], -1),  # bottom, right to left
        np.stack([np.full_like(s, -tx), s * ty], -1),  # left, bottom to top
    ]
    p = np.concatenate([*edges, edges[0][:1]])  # closed
    rays = np.concatenate([p, np.ones((len(p), 1))], axis=1)
    world = head_rotation(yaw_deg, pitch_deg, roll_deg).apply(rays)
    lon, lat = dir_to_lonlat(world)
    x, y = lonlat_to_equirect_xy(lon, lat, width, height)
    xy = np.stack([x, y], -1)
    cut = np.nonzero(np.abs(np.diff(x)) > width / 2)[0] + 1
    parts = [q for q in np.split(xy, cut) if len(q) >= 2]
    return parts


def _fit(img: NDArray[np.uint8], w: int, h: int, area: bool = False) -> NDArray[np.uint8]:
    import cv2

    if img.shape[1] == w and img.shape[0] == h:
        return img
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA if area else cv2.INTER_LINEAR)


#: What a still image's review shows for its EPOF (one image repeated: nothing moves).
STILL_NO_FLOW = "still image: no flow"


class ReviewWriter:
    """Writes ``review.mp4`` and ``sheet.png`` from a render's frames (see the module doc).

    times_s, yaw_deg, pitch_deg, roll_deg, epof_dps, opacity : per rendered frame
    hfov_deg, vfov_deg : the eye's FOV (the outline drawn)
    fps : frame rate of the review video
    height : height of the equirect panel (its width is twice that; the eye panel is
        square of the same height; both rounded to even numbers)
    n_sheet : eye views on the contact sheet (evenly spaced times)
    preset, crf : x264 settings of the review video (ultrafast: it must cost little
        beside the eye videos)
    audio : None, or a :class:`simulator.media.audio.AudioSource` carried into the review video
    thresholds_dps : the opacity rule's (0, 1) thresholds, deg/s: drawn as dashed lines on
        the strip, labelled (None or NaN: not drawn)
    opacity_used : False when the render ignores the per-frame opacity (``local-grf``:
        each cell's own flow drives it): the strip and sheet then show no opacity
    video_times_s : None (frame ``i`` at ``i / fps``), or each frame's time in seconds (a
        variable-rate source's timestamps: the review video keeps its timing)
    no_flow : what a frame without an EPOF shows instead of a number (a still image:
        ``"still image: no flow"``)
    """

    def __init__(
        self,
        video_path: str | Path,
        sheet_path: str | Path,
        *,
        times_s,
        yaw_deg,
        pitch_deg,
        roll_deg,
        epof_dps,
        opacity,
        hfov_deg: float,
        vfov_deg: float,
        fps: float,
        height: int = 360,
        n_sheet: int = 12,
        preset: str = "ultrafast",
        crf: int = 23,
        audio=None,
        thresholds_dps=None,
        opacity_used: bool = True,
        video_times_s=None,
        no_flow: str = "no flow (no grid)",
    ):
        self.t = np.asarray(times_s, float)
        self.yaw, self.pitch = np.asarray(yaw_deg, float), np.asarray(pitch_deg, float)
        self.roll = np.asarray(roll_deg, float)
        self.epof, self.op = np.asarray(epof_dps, float), np.asarray(opacity, float)
        self.fov = (float(hfov_deg), float(vfov_deg))
        th = [float(v) for v in (thresholds_dps or ())]
        self.thresholds = th if len(th) == 2 and all(np.isfinite(th)) else None
        self.opacity_used = bool(opacity_used)
        self.no_flow = str(no_flow)
        self.ph = int(height) // 2 * 2
        self.pw = 2 * self.ph
        self.strip_h = max(60, self.ph // 3) // 2 * 2
        self.size = (self.pw + self.ph, self.ph + self.strip_h)
        self.sheet_path = Path(sheet_path)
        n = len(self.t)
        k = min(int(n_sheet), n)
        self.sheet_at = {int(i): None for i in np.linspace(0, n - 1, k).round().astype(int)}
        self._strip = self._base_strip()
        self._writer = VideoWriter(video_path, fps, self.size, crf=crf, preset=preset,
                                   audio=audio, times_s=video_times_s)  # fmt: skip
        self.n = 0

    # ------------------------------------------------------------------ strip
    def _strip_x(self, i) -> NDArray:
        n = max(len(self.t) - 1, 1)
        return 8 + np.asarray(i, float) / n * (self.size[0] - 16)

    def _base_strip(self) -> NDArray[np.uint8]:
        import cv2

        w, h = self.size[0], self.strip_h
        img = np.full((h, w, 3), 24, np.uint8)
        x = self._strip_x(np.arange(len(self.t)))
        top, bot = 6, h - 18

        def curve(v, vmax, color):
            v = np.nan_to_num(np.asarray(v, float), nan=0.0)
            y = bot - np.clip(v / vmax, 0, 1) * (bot - top) if vmax > 0 else np.full_like(v, bot)
            pts = np.stack([x, y], -1).round().astype(np.int32)
            cv2.polylines(img, [pts], False, color, 1, cv2.LINE_AA)

        fin = self.epof[np.isfinite(self.epof)]
        self.epof_max = float(fin.max()) * 1.05 if fin.size and fin.max() > 0 else 1.0
        if self.thresholds:
            self.epof_max = max(self.epof_max, self.thresholds[1] * 1.05)
            for v, name in zip(self.thresholds, ("opacity 0", "opacity 1")):
                y = round(bot - min(v / self.epof_max, 1.0) * (bot - top))
                for x0 in range(8, w - 8, 12):  # dashed
                    cv2.line(img, (x0, y), (min(x0 + 6, w - 8), y), _EPOF_RGB, 1)
                cv2.putText(img, f"{name} below/above {v:.0f} deg/s" if name == "opacity 0"
                            else f"{name} at {v:.0f} deg/s", (w - 210, max(y - 3, 10)),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.35, _EPOF_RGB, 1, cv2.LINE_AA)  # fmt: skip
        curve(self.epof, self.epof_max, _EPOF_RGB)
        if self.opacity_used:
            curve(self.op, 1.0, _OP_RGB)
        cv2.putText(img, f"EPOF, deg/s (strip height = {self.epof_max:.0f} deg/s)", (8, h - 5),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.38, _EPOF_RGB, 1, cv2.LINE_AA)  # fmt: skip
        label = "opacity, 0 to 1 (strip height = 1)" if self.opacity_used else (
            "opacity: per cell (local-grf), not per frame")  # fmt: skip
        cv2.putText(img, label, (330, h - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.38,
                    _OP_RGB, 1, cv2.LINE_AA)  # fmt: skip
        return img

    def _numbers(self, j: int) -> str:
        """EPOF (and opacity, where the render uses it) of frame ``j``, with units; where
        there is no flow (a still, no grid), why."""
        op = f"  opacity {self.op[j]:.2f}" if self.opacity_used and np.isfinite(self.op[j]) else ""
        if not np.isfinite(self.epof[j]):
            return f"{self.no_flow}{op}"
        return f"EPOF {self.epof[j]:.1f} deg/s{op}"

    # ------------------------------------------------------------------ frames
    def add(self, equirect: NDArray[np.uint8], eye_rgb: NDArray[np.uint8]) -> None:
        """One frame: the decoded equirect frame (one eye's, RGB) and the eye view (RGB)."""
        import cv2

        i = self.n
        j = min(i, len(self.t) - 1)
        pano = np.ascontiguousarray(_fit(equirect, self.pw, self.ph))
        for part in frustum_outline_xy(
            self.yaw[j], self.pitch[j], self.roll[j], *self.fov, self.pw, self.ph
        ):
            pts = (part - 0.5).round().astype(np.int32)
            cv2.polylines(pano, [pts], False, _OUTLINE_RGB, 2, cv2.LINE_AA)
        eye = _fit(eye_rgb, self.ph, self.ph)
        strip = self._strip.copy()
        cx = round(float(self._strip_x(j)))
        cv2.line(strip, (cx, 0), (cx, self.strip_h - 16), _WHITE, 1)
        text = (
            f"t {self.t[j]:.2f} s  yaw {self.yaw[j]:.0f}  pitch {self.pitch[j]:.0f}  "
            + self._numbers(j)
        )
        cv2.putText(strip, text, (max(8, self.size[0] - 470), self.strip_h - 5),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, _WHITE, 1, cv2.LINE_AA)  # fmt: skip
        frame = np.concatenate([np.concatenate([pano, eye], axis=1), strip], axis=0)
        self._writer.write(frame)
        if j in self.sheet_at and self.sheet_at[j] is None:
            self.sheet_at[j] = _fit(eye_rgb, 240, 240, area=True).copy()
        self.n += 1

    def add_yuv(self, equirect: NDArray[np.uint8], eye_yuv420p: NDArray[np.uint8]) -> None:
        """:meth:`add` with the eye image as yuv420p planes (``(h * 3 // 2, w)``), the
        ``on_frame`` signature of :func:`simulator.render.render_video`."""
        import cv2

        self.add(equirect, cv2.cvtColor(eye_yuv420p, cv2.COLOR_YUV2RGB_I420))

    def close(self, ok: bool = True) -> None:
        """Finish ``review.mp4`` (renamed into place if ``ok``) and write ``sheet.png``."""
        self._writer.close(ok)
        if ok:
            self._write_sheet()

    def _write_sheet(self) -> None:
        import cv2
        from PIL import Image

        tiles = []
        for j, img in sorted(self.sheet_at.items()):
            if img is None:
                continue
            tile = np.full((240 + 44, 240, 3), 16, np.uint8)
            tile[:240] = img
            lines = (
                f"t {self.t[j]:.2f} s  yaw {self.yaw[j]:.0f}  pitch {self.pitch[j]:.0f}",
                self._numbers(j),
            )
            for k, s in enumerate(lines):
                cv2.putText(tile, s, (4, 258 + 18 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                            _WHITE, 1, cv2.LINE_AA)  # fmt: skip
            tiles.append(tile)
        if not tiles:
            return
        cols = min(4, len(tiles))
        rows = -(-len(tiles) // cols)
        th, tw = tiles[0].shape[:2]
        sheet = np.full((rows * th, cols * tw, 3), 0, np.uint8)
        for k, tile in enumerate(tiles):
            r, c = divmod(k, cols)
            sheet[r * th : (r + 1) * th, c * tw : (c + 1) * tw] = tile
        with atomic_output(self.sheet_path) as tmp:
            Image.fromarray(sheet).save(tmp, format="PNG")
