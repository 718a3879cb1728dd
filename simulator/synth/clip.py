"""Writing a synthetic clip and its ground-truth file (``OUT.truth.npz``).

The truth file (``OUT.truth.npz``, no pickles; :func:`load_truth`) holds, per frame
``t``, this speed at the centres of a coarse lon/lat grid, evaluated at the middle of the
frame interval from ``t - 1`` to ``t`` (time ``(t - 0.5) / fps``), like the grid file's
``pof_dps`` (frame t = motion from frame t-1 to t; frame 0 repeats frame 1). The
per-frame displacement angle differs from ``speed / fps`` by O((motion per frame)^2).
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output
from simulator.core.progress import Counter, Progress
from simulator.core.resources import check_fits
from simulator.media.video import VideoWriter
from simulator.sphere.geometry import lonlat_to_dir
from simulator.synth.scenes import SynthConfig, SynthScene, make_scene
from simulator.synth.textures import _bundled_texture_path

__all__ = ["Truth", "load_truth", "synthesize", "truth_path_for"]

TRUTH_FORMAT = "vimsim-synth-truth"


TRUTH_VERSION = 1


@dataclass(frozen=True)
class Truth:
    """A loaded truth file (``OUT.truth.npz``).

    speed_dps : ndarray, shape (T, n_lat, n_lon), float32, deg/s
        Left (or mono) eye's angular speed at cell centres; row t = interval t-1 -> t.
    speed_dps_right : same for the right eye (top-bottom clips), else None
    lon_deg : ndarray, shape (n_lon,), cell-centre longitudes, -180 + c/2 .. 180 - c/2
    lat_deg : ndarray, shape (n_lat,), cell-centre latitudes, from +90 - c/2 (top) down
    time_s : ndarray, shape (T,), time at which each row is evaluated
    meta : dict (``config``, ``trajectory``, conventions)
    """

    speed_dps: NDArray[np.float32]
    lon_deg: NDArray[np.float64]
    lat_deg: NDArray[np.float64]
    time_s: NDArray[np.float64]
    meta: dict
    speed_dps_right: NDArray[np.float32] | None = field(default=None, repr=False)

    @property
    def config(self) -> SynthConfig:
        c = dict(self.meta["config"])
        c["size"] = tuple(c["size"])
        c["axis"] = tuple(c["axis"])
        return SynthConfig(**c)

    def scene(self) -> SynthScene:
        """Rebuild the scene (for analytic truth at any ray)."""
        return make_scene(self.config)


def truth_path_for(video_path: str | os.PathLike) -> Path:
    """``OUT.mp4`` -> ``OUT.truth.npz``."""
    p = Path(video_path)
    return p.with_name(p.stem + ".truth.npz")


def _interval_times(n_frames: int, fps: float) -> NDArray[np.float64]:
    t = (np.arange(n_frames) - 0.5) / fps
    t[0] = t[1] if n_frames > 1 else 0.0
    return t


def load_truth(path: str | os.PathLike) -> Truth:
    """Read a truth file written by :func:`synthesize` (``allow_pickle=False``)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{p}: truth file not found")
    try:
        with np.load(p, allow_pickle=False) as z:
            arrs = {k: z[k] for k in z.files}
        meta = json.loads(str(arrs["meta"]))
    except (zipfile.BadZipFile, ValueError, OSError, KeyError, json.JSONDecodeError) as e:
        raise InputError(f"{p}: not a vimsim truth file ({type(e).__name__})") from None
    if meta.get("format") != TRUTH_FORMAT or meta.get("version") != TRUTH_VERSION:
        raise InputError(f"{p}: not a vimsim truth file version {TRUTH_VERSION}")
    return Truth(
        speed_dps=arrs["speed_dps"],
        lon_deg=arrs["lon_deg"],
        lat_deg=arrs["lat_deg"],
        time_s=arrs["time_s"],
        meta=meta,
        speed_dps_right=arrs.get("speed_dps_right"),
    )


def _texture_hash(cfg: SynthConfig) -> str:
    p = _bundled_texture_path() if cfg.texture is None else Path(cfg.texture)
    return "sha256:" + hashlib.sha256(p.read_bytes()).hexdigest()


def synthesize(
    cfg: SynthConfig,
    out: str | os.PathLike,
    *,
    crf: int = 16,
    progress: Progress | None = None,
    scene: SynthScene | None = None,
) -> tuple[Path, Path]:
    """Render the clip of ``cfg`` to ``out`` (H.264 MP4) and its truth file beside it.

    ``crf`` is the x264 constant rate factor, an integer 0..51 (lower is better).
    ``scene``: an already built scene of ``cfg`` (e.g. a trajectory scene), else
    :func:`make_scene` builds it.
    Returns ``(video_path, truth_path)``. Both are written atomically; the truth file is
    written after the video, so a truth file implies a complete video, and a failure
    while writing the truth removes this run's video (no clip without its truth).
    """

    out = Path(out)
    if out.suffix.lower() != ".mp4":
        raise InputError(f"{out}: output must be an .mp4 file")
    if isinstance(crf, bool) or not isinstance(crf, (int, np.integer)) or not 0 <= crf <= 51:
        raise InputError(f"x264 crf must be an integer 0..51 (lower is better); got {crf!r}")
    if scene is None:
        scene = make_scene(cfg)
    elif scene.cfg != cfg:
        raise ValueError("synthesize: scene.cfg differs from cfg")
    W, H = cfg.size
    n = cfg.n_frames
    c = cfg.truth_cell_deg  # the truth is held whole: refused before any work if it cannot fit
    check_fits(n * round(180 / c) * round(360 / c) * 4.0 * len(cfg.eyes), "--truth-cell")
    workers = max(1, min(4, os.cpu_count() or 1))
    # frames in flight (2 per worker + the one written) at ~48 bytes a pixel while drawn
    # (measured: 2048x1024 at 2 workers peaks at 540 MB, ~37 bytes a pixel in flight)
    check_fits(W * H * len(cfg.eyes) * 48.0 * (2 * workers + 1), f"--size {W}x{H}")
    frame_size = (W, H * len(cfg.eyes))
    it = range(n)
    bar = Counter(progress, n)
    # Frames are independent: render a few ahead on worker threads (numpy and cv2 release
    # the GIL for most of the work), write them in order.
    with VideoWriter(out, cfg.fps, frame_size, crf=crf) as vw, ThreadPoolExecutor(workers) as pool:
        pending = []
        for k in it:
            pending.append(pool.submit(scene.render, k / cfg.fps))
            if len(pending) > 2 * workers:
                vw.write(pending.pop(0).result())
                bar.update(1)
        for f in pending:
            vw.write(f.result())
            bar.update(1)
    try:
        return out, _write_truth(cfg, scene, out, n, frame_size)
    except BaseException:
        out.unlink(missing_ok=True)  # this run's video without its truth would look complete
        raise


def _write_truth(cfg: SynthConfig, scene: SynthScene, out: Path, n: int, frame_size) -> Path:
    """The truth file of the clip ``out`` just written (atomically); returns its path."""
    # Truth on the coarse grid (cell centres), per eye, per frame interval.
    c = cfg.truth_cell_deg
    n_lat, n_lon = round(180 / c), round(360 / c)
    lon_deg = -180.0 + c * (np.arange(n_lon) + 0.5)
    lat_deg = 90.0 - c * (np.arange(n_lat) + 0.5)
    LO, LA = np.meshgrid(np.radians(lon_deg), np.radians(lat_deg))
    dirs = lonlat_to_dir(LO, LA)
    times = _interval_times(n, cfg.fps)
    fields = {e: np.empty((n, n_lat, n_lon), np.float32) for e in cfg.eyes}
    traj = {
        "frame_time_s": [],
        "position_m": [],
        "quat_xyzw": [],
        "interval_time_s": [],
        "omega_cam_dps": [],
        "velocity_cam_mps": [],
    }
    for k in range(n):
        for e in cfg.eyes:
            fields[e][k] = scene.speed_dps(float(times[k]), dirs, e)
        tk = k / cfg.fps
        traj["frame_time_s"].append(tk)
        traj["position_m"].append(scene.position(tk).round(9).tolist())
        traj["quat_xyzw"].append(scene.rotation(tk).as_quat().round(12).tolist())
        traj["interval_time_s"].append(float(times[k]))
        traj["omega_cam_dps"].append(scene.omega_cam_dps(float(times[k])).round(9).tolist())
        traj["velocity_cam_mps"].append(
            scene.eye_velocity_cam(float(times[k]), "mono").round(9).tolist()
        )
    meta = {
        "format": TRUTH_FORMAT,
        "version": TRUTH_VERSION,
        "config": cfg.to_dict(),
        "video": {
            "path": out.name,
            "width": frame_size[0],
            "height": frame_size[1],
            "fps": cfg.fps,
            "n_frames": n,
        },
        "texture": {"name": scene.texture_name, "hash": _texture_hash(cfg)},
        "speed_mps": scene.cfg.speed,
        "room_m": None
        if scene.box is None
        else {"lo": list(scene.box.lo), "hi": list(scene.box.hi)},
        "eyes": list(cfg.eyes),
        "units": "deg/s of visual angle",
        "cells": (
            f"speed_dps[t, i, j]: cell centre lon_deg[j] = -180 + {c:g} (j + 0.5), "
            f"lat_deg[i] = 90 - {c:g} (i + 0.5) (row 0 at the top), camera frame = equirect frame"
        ),
        "time": "row t covers frames t-1 -> t, evaluated at (t - 0.5) / fps; row 0 repeats row 1",
        "frames": "camera: +x right, +y up, +z forward; quat_xyzw/position_m: camera->world pose at frame_time_s",
        "trajectory": traj,
    }
    extra_arrays, extra_meta = scene.truth_extras(dirs, times)
    meta.update(extra_meta)
    arrays = {
        "speed_dps": fields[cfg.eyes[0]],
        "lon_deg": lon_deg,
        "lat_deg": lat_deg,
        "time_s": times,
        "meta": np.array(json.dumps(meta)),
    }
    if "right" in fields:
        arrays["speed_dps_right"] = fields["right"]
    arrays.update(extra_arrays)
    tpath = truth_path_for(out)
    with atomic_output(tpath) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    return tpath
