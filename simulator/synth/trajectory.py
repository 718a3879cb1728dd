"""The ``trajectory`` synthetic scene: a camera on any path (camera CSV) through a textured room.

:class:`TrajectoryScene` is a :class:`simulator.synth.SynthScene` (rendering, ray cast,
analytic truth ``|-(w_c x d) - (v_c - (v_c . d) d) / r|``) whose pose comes from a
:class:`simulator.synth.camera_path.CameraTrajectory` (positions: spline, orientations:
Slerp, exact derivatives). World and camera frames: +x right, +y up, +z forward, metres.
Video time ``tau`` (frame ``k`` at ``k / fps``) is trajectory time ``tau + t_0`` (``t_0``
the first pose's time). The room is an axis-aligned box: by default the trajectory's
bounding box grown by 3 m horizontally, 1.6 m below and 2.4 m above (the ``forward``
scene's tunnel cross-section around a walk).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from simulator.core.errors import InputError
from simulator.core.progress import Progress
from simulator.synth.camera_path import CameraTrajectory, load_camera_csv
from simulator.synth.clip import load_truth, synthesize, truth_path_for
from simulator.synth.scenes import MAX_FPS, MAX_FRAMES, SynthConfig, SynthScene, _Box
from simulator.synth.textures import load_texture

__all__ = [
    "TrajectoryScene",
    "check_inside",
    "default_room",
    "make_trajectory_scene",
    "room_box",
    "scene_from_truth",
    "synthesize_trajectory",
    "trajectory_config",
]

#: Default room around the path, metres: on each horizontal side, below, above.
ROOM_SIDE_M = 3.0
ROOM_BELOW_M = 1.6
ROOM_ABOVE_M = 2.4
#: Closest the rig centre may come to a wall (plus half the eye separation), metres.
WALL_MARGIN_M = 0.2
_CHECKS_PER_FRAME = 4  # room check: samples per frame interval (and every pose)


# ------------------------------------------------------------------------------ room
def _check_times(traj: CameraTrajectory, fps: float) -> NDArray[np.float64]:
    """Trajectory times at which the room is checked: every pose and 4 per frame."""
    n = max(2, math.ceil((traj.end_s - traj.start_s) * fps * _CHECKS_PER_FRAME) + 1)
    return np.union1d(traj.times_s, np.linspace(traj.start_s, traj.end_s, n))


def default_room(traj: CameraTrajectory, fps: float = 30.0) -> _Box:
    """The path's bounding box grown by 3 m on each horizontal side, 1.6 m below
    (eye height over the floor) and 2.4 m above."""
    pos = traj.position(_check_times(traj, fps))
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    grow_lo = np.array([ROOM_SIDE_M, ROOM_BELOW_M, ROOM_SIDE_M])
    grow_hi = np.array([ROOM_SIDE_M, ROOM_ABOVE_M, ROOM_SIDE_M])
    return _Box(tuple((lo - grow_lo).tolist()), tuple((hi + grow_hi).tolist()))


def room_box(traj: CameraTrajectory, room_m=None, *, fps: float = 30.0) -> _Box:
    """The room of a trajectory scene, metres, world frame.

    ``room_m``: None (:func:`default_room`); ``(W, H, D)``: a room W wide (x), H high (y),
    D deep (z), centred on the path's bounding box in x and z, its floor 1.6 m below the
    lowest camera position; ``(x0, y0, z0, x1, y1, z1)``: the two corners.
    """
    if room_m is None:
        return default_room(traj, fps)
    r = np.asarray(room_m, dtype=np.float64).ravel()
    if r.size not in (3, 6) or not np.all(np.isfinite(r)):
        raise InputError(
            f"room must be W,H,D or X0,Y0,Z0,X1,Y1,Z1 in metres, e.g. 8,4,20; got {room_m!r}"
        )
    if r.size == 3:
        if np.any(r <= 0):
            raise InputError(f"room size must be > 0 m on each axis, e.g. 8,4,20; got {room_m!r}")
        pos = traj.position(_check_times(traj, fps))
        mid = (pos.min(axis=0) + pos.max(axis=0)) / 2
        floor = float(pos[:, 1].min()) - ROOM_BELOW_M
        lo = np.array([mid[0] - r[0] / 2, floor, mid[2] - r[2] / 2])
        hi = np.array([mid[0] + r[0] / 2, floor + r[1], mid[2] + r[2] / 2])
    else:
        lo, hi = r[:3], r[3:]
        if np.any(hi <= lo):
            raise InputError(
                f"room corners must satisfy X0 < X1, Y0 < Y1, Z0 < Z1 (metres); got {room_m!r}"
            )
    return _Box(tuple(lo.tolist()), tuple(hi.tolist()))


def check_inside(traj: CameraTrajectory, box: _Box, *, fps: float, ipd_m: float) -> None:
    """InputError naming the first time (trajectory time, seconds) at which the rig
    centre comes within ``0.2 m + ipd/2`` of a wall of ``box`` (poses and 4 samples per
    frame are checked)."""
    t = _check_times(traj, fps)
    pos = traj.position(t)
    margin = WALL_MARGIN_M + ipd_m / 2
    lo, hi = np.asarray(box.lo) + margin, np.asarray(box.hi) - margin
    out = (pos <= lo) | (pos >= hi)
    bad = np.flatnonzero(out.any(axis=1))
    if bad.size == 0:
        return
    k = int(bad[0])
    t_out = float(t[k])
    if k > 0:  # the crossing lies between samples k-1 (inside) and k: bisect it
        a, b = float(t[k - 1]), t_out
        for _ in range(40):
            m = (a + b) / 2
            p = traj.position(m)
            a, b = (m, b) if np.all((p > lo) & (p < hi)) else (a, m)
        t_out = b
    p_out = traj.position(t_out)
    ax = int(np.flatnonzero((p_out <= lo) | (p_out >= hi))[0])
    name = "xyz"[ax]
    raise InputError(
        f"{traj.source or 'camera trajectory'}: the camera leaves the room at t = {t_out:.3f} s "
        f"({name} = {p_out[ax]:.2f} m; the room spans {name} {box.lo[ax]:.2f}..{box.hi[ax]:.2f} m "
        f"and the camera must stay {margin:.2f} m from its walls); give a larger --room or "
        "leave it out (the default room encloses the path)"
    )


# ----------------------------------------------------------------------------- scene
class TrajectoryScene(SynthScene):
    """A :class:`simulator.synth.SynthScene` whose camera follows a
    :class:`CameraTrajectory` through a textured box room.

    Video time ``tau`` (seconds; frame ``k`` at ``k / fps``) is trajectory time
    ``tau + trajectory.start_s``. Built by :func:`make_trajectory_scene`.
    """

    def __init__(
        self,
        cfg: SynthConfig,
        texture: NDArray[np.uint8],
        texture_name: str,
        trajectory: CameraTrajectory,
        room_m=None,
    ):
        if cfg.scene != "trajectory":
            raise InputError(f"TrajectoryScene needs scene='trajectory'; got {cfg.scene!r}")
        self.trajectory = trajectory
        self._t0 = trajectory.start_s
        self._room_m = room_m
        super().__init__(cfg, texture, texture_name)

    # -- hooks of SynthScene
    def _make_room(self) -> _Box:
        return room_box(self.trajectory, self._room_m, fps=self.cfg.fps)

    def _check_inside_room(self) -> None:
        check_inside(self.trajectory, self.box, fps=self.cfg.fps, ipd_m=self.cfg.ipd_m)

    # -- pose (video time, seconds)
    def position(self, t: float) -> NDArray[np.float64]:
        return self.trajectory.position(t + self._t0)

    def velocity(self, t: float) -> NDArray[np.float64]:
        return self.trajectory.velocity(t + self._t0)

    def rotation(self, t: float) -> Rotation:
        return self.trajectory.rotation(t + self._t0)

    def omega_cam_dps(self, t: float, h: float | None = None) -> NDArray[np.float64]:
        """Camera-frame angular velocity, deg/s (exact: Slerp's per-segment rate)."""
        return np.degrees(self.trajectory.omega_cam_rad(t + self._t0))

    # -- truth file
    def speed_parts_dps(
        self, t: float, dirs_cam: NDArray, eye: str = "mono"
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The rotation part ``|w_c x d|`` and the translation part
        ``|v_c - (v_c . d) d| / r`` of the angular speed, deg/s, each shape ``(...)``
        (their vector sum is :meth:`speed_dps`)."""
        d = np.asarray(dirs_cam, float)
        w = np.radians(self.omega_cam_dps(t))
        v = self.eye_velocity_cam(t, eye)
        r = self.depth(t, d, eye)
        rot = np.linalg.norm(np.cross(w, d), axis=-1)
        trans = np.linalg.norm(v - (d @ v)[..., None] * d, axis=-1) / r
        return np.degrees(rot), np.degrees(trans)

    def truth_extras(self, dirs_cam: NDArray, times_s: NDArray) -> tuple[dict, dict]:
        tr = self.trajectory
        n = len(times_s)
        rot = np.empty((n, *dirs_cam.shape[:-1]), np.float32)
        trans = {e: np.empty_like(rot) for e in self.cfg.eyes}
        for k, t in enumerate(np.asarray(times_s, float)):
            for e in self.cfg.eyes:
                r_part, t_part = self.speed_parts_dps(float(t), dirs_cam, e)
                rot[k] = r_part
                trans[e][k] = t_part
        y, p, r = tr.angles_deg()
        arrays = {
            "speed_rot_dps": rot,
            "speed_trans_dps": trans[self.cfg.eyes[0]],
            "camera_time_s": tr.times_s.copy(),
            "camera_position_m": tr.positions_m.copy(),
            "camera_quat_xyzw": tr.rotations.as_quat(),
            "camera_ypr_deg": np.column_stack([y, p, r]),
        }
        if "right" in trans:
            arrays["speed_trans_dps_right"] = trans["right"]
        speeds = np.linalg.norm(self.velocity(np.asarray(times_s, float)), axis=-1)
        meta = {
            "speed_mps": float(np.mean(speeds)),
            "camera": {
                "source": tr.source,
                "interp": tr.interp,
                "n_poses": tr.n,
                "time_offset_s": tr.start_s,
                "span_s": tr.end_s - tr.start_s,
                "arrays": "camera_time_s (N,), camera_position_m (N, 3), camera_quat_xyzw "
                "(N, 4) camera->world, camera_ypr_deg (N, 3): the poses as read; video time "
                "= camera time - time_offset_s",
                "parts": "speed_rot_dps = |w_c x d| (both eyes), speed_trans_dps[_right] = "
                "|v_c - (v_c.d) d| / r per eye, deg/s; speed_dps is their vector sum",
                "room_spec_m": None if self._room_m is None else list(map(float, self._room_m)),
            },
        }
        return arrays, meta


def trajectory_config(
    traj: CameraTrajectory,
    *,
    fps: float = 30.0,
    size: tuple[int, int] = (1024, 512),
    layout: str = "mono",
    texture: str | None = None,
    seed: int = 0,
    ipd_m: float = 0.064,
    texture_m: float = 3.0,
    truth_cell_deg: float = 4.0,
) -> SynthConfig:
    """The :class:`SynthConfig` of a clip covering ``traj``'s time span at ``fps``:
    ``floor(span * fps) + 1`` frames (the last at most one frame interval before the
    last pose)."""
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise InputError(f"fps must be a number in (0, {MAX_FPS:g}]; got {fps!r}")
    span = traj.end_s - traj.start_s
    if span * fps > MAX_FRAMES:
        raise InputError(
            f"{traj.source or 'camera trajectory'}: spans {span:.6g} s, "
            f"{span * fps:.4g} frames at {fps:g} fps; at most {MAX_FRAMES:,} (lower --fps)"
        )
    n = math.floor(span * fps + 1e-9) + 1
    if n < 2:
        raise InputError(
            f"{traj.source or 'camera trajectory'}: spans {span:.6g} s, {n} frame at {fps:g} "
            "fps; flow needs at least 2 (a longer trajectory or a higher --fps)"
        )
    return SynthConfig(
        "trajectory",
        seconds=n / fps,
        fps=fps,
        size=size,
        layout=layout,
        texture=texture,
        seed=seed,
        ipd_m=ipd_m,
        texture_m=texture_m,
        truth_cell_deg=truth_cell_deg,
    )


def make_trajectory_scene(cfg: SynthConfig, traj: CameraTrajectory, room_m=None) -> TrajectoryScene:
    """Load ``cfg``'s texture and build the trajectory scene (room checked)."""
    tex, name = load_texture(cfg.texture)
    return TrajectoryScene(cfg, tex, name, traj, room_m)


def synthesize_trajectory(
    camera: str | os.PathLike | CameraTrajectory,
    out: str | os.PathLike,
    *,
    room_m=None,
    interp: str = "cubic",
    crf: int = 16,
    progress: Progress | None = None,
    **config,
) -> tuple[Path, Path, SynthConfig]:
    """``vimsim synth OUT.mp4 --scene trajectory --camera CAMERA.csv``: render the clip
    and ``OUT.truth.npz``; ``config``: keywords of :func:`trajectory_config`.

    Every check (camera file, room, texture, output) runs before rendering; an output
    that resolves to an input (the camera CSV, the texture) is refused.
    Returns ``(video_path, truth_path, cfg)``.
    """
    out = Path(out)
    traj = (
        camera if isinstance(camera, CameraTrajectory) else load_camera_csv(camera, interp=interp)
    )
    inputs = [Path(camera)] if not isinstance(camera, CameraTrajectory) else []
    if config.get("texture"):
        inputs.append(Path(config["texture"]))
    for o in (out, truth_path_for(out)):
        for i in inputs:
            if o.resolve() == i.resolve():
                raise InputError(f"{o}: output is the input {i}; choose another output name")
    cfg = trajectory_config(traj, **config)
    scene = make_trajectory_scene(cfg, traj, room_m)
    video, truth = synthesize(cfg, out, crf=crf, progress=progress, scene=scene)
    return video, truth, cfg


def scene_from_truth(path: str | os.PathLike) -> TrajectoryScene:
    """Rebuild the trajectory scene of a truth file (for the truth at any ray and time)."""
    tr = load_truth(path)
    cam = tr.meta.get("camera")
    if tr.meta["config"].get("scene") != "trajectory" or cam is None:
        raise InputError(f"{path}: not the truth file of a trajectory clip")
    with np.load(path, allow_pickle=False) as z:
        t, p, q = z["camera_time_s"], z["camera_position_m"], z["camera_quat_xyzw"]
    traj = CameraTrajectory(t, p, Rotation.from_quat(q), cam["interp"], cam["source"])
    room = tr.meta["room_m"]
    return make_trajectory_scene(tr.config, traj, (*room["lo"], *room["hi"]))
