"""Synthetic 360 deg scenes (camera motions through a static world) and their analytic angular speed.

Four scenes (:data:`SCENES`), all described as a camera moving through a static world:

``rotate``
    A textured panorama at infinity (an environment map) and a camera turning at a
    constant ``omega_dps`` about ``axis`` (camera frame); equivalently, the panorama
    rotates at ``omega`` about ``axis`` in the video. A scene point at direction ``d``
    moves at ``omega * |a x d|`` (``a`` the unit axis).
``forward``
    The camera moves along +z (its forward direction) at ``speed_mps`` through a
    textured box tunnel (walls, floor, ceiling and end walls are planes with texture
    coordinates in metres), ray-cast per equirect pixel with trilinear mipmapping.
``coaster``
    A figure-eight ride with hills through a textured box room: speed varies along the
    path (accelerations), the camera looks along its velocity (turns, pitch) and banks
    into the turns (roll).
``trajectory``
    Any camera path (a CSV of timed poses) through a textured box room:
    :mod:`simulator.synth.trajectory` (it subclasses :class:`SynthScene`).

Frames and conventions (:mod:`simulator.sphere.geometry`): world and camera frames are
+x right, +y up, +z forward; the equirect frame of the video *is* the camera frame
(pixel column ``x`` has longitude ``(x + 0.5) / W * 360 - 180`` deg, row ``y`` latitude
``90 - (y + 0.5) / H * 180`` deg). The camera pose at time ``t`` (seconds) is a rotation
``R(t)`` taking camera-frame vectors to the world frame and an origin ``c(t)`` (metres).
Frame ``k`` of the clip shows time ``k / fps``. Stereo: the eyes sit at
``c + R (-+ipd/2, 0, 0)`` (64 mm apart along the camera's x axis, perpendicular to its
forward direction); the top-bottom layout puts the left eye on top.

Ground truth (derivation). A static world point ``X`` seen from an eye at ``c(t)`` with
orientation ``R(t)`` has camera-frame position ``q = R^T (X - c)``; with the world
angular velocity ``w`` (``dR/dt = [w]x R``) and velocity ``v = dc/dt``::

    dq/dt = -R^T (w x (X - c)) - R^T v = -(w_c x q) - v_c,   w_c = R^T w, v_c = R^T v

and the unit ray ``d = q / r`` (``r = |q|``, the depth along the ray) moves at::

    dd/dt = (dq/dt - (dq/dt . d) d) / r = -(w_c x d) - (v_c - (v_c . d) d) / r

The angular speed is ``|dd/dt|`` (rad/s), reported in deg/s. For the rotating panorama
``r`` is infinite and ``w_c = -omega a``, giving ``omega |a x d|``. An eye offset ``e``
(camera frame) from the rig centre moves at ``v_c + w_c x e``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from simulator.core.choices import MAX_CLIP_FPS, MAX_CLIP_FRAMES, SCENES, SYNTH_LAYOUTS
from simulator.core.errors import InputError
from simulator.sphere.geometry import (
    check_equirect_aspect,
    equirect_pixel_lonlat,
    equirect_remap_coords,
    head_rotation,
    lonlat_to_dir,
    pad_equirect,
    perspective_rays,
)
from simulator.sphere.windows import WindowGrid
from simulator.synth.textures import _MipTexture, load_texture

__all__ = [
    "SCENES",
    "SynthConfig",
    "SynthScene",
    "angular_speed_dps",
    "make_scene",
    "window_truth_dps",
]


#: Upper bounds of a clip (a typo such as ``--fps 1e9`` fails at once, not after hours);
#: shared with a still's clip (:mod:`simulator.core.choices`).
MAX_FPS = MAX_CLIP_FPS
MAX_FRAMES = MAX_CLIP_FRAMES


_G = 9.81  # m/s^2, for the coaster's banking


@dataclass(frozen=True)
class SynthConfig:
    """Everything that defines a synthetic clip (validated on construction).

    Parameters
    ----------
    scene : ``"rotate"``, ``"forward"``, ``"coaster"`` or ``"trajectory"`` (needs a camera
        path: :func:`simulator.synth.trajectory.make_trajectory_scene`)
    seconds : float, clip length in seconds (> 0; at least 2, at most ``MAX_FRAMES``
        = 100,000 frames)
    fps : float, frames per second, in (0, ``MAX_FPS`` = 240]
    size : (W, H), pixels of one eye's equirect frame; ``W = 2 H``, both even
    layout : ``"mono"`` or ``"top-bottom"`` (left eye on top; the frame is W x 2H)
    texture : path of an image (rotate: a 2:1 equirect panorama), or None for the
        bundled panorama
    seed : int, varies the texture placement on the walls
    axis : (x, y, z), rotate: rotation axis in the camera frame (+y up = a yaw pan)
    omega_dps : float, rotate: rotation rate in deg/s (> 0); the panorama turns
        right-handedly about ``axis``: ``axis = (0, 1, 0)`` turns +z toward +x, so
        the content moves right (toward +lon), as if the camera turned left
    speed_mps : float, forward: camera speed in m/s; coaster: mean speed along the path
    ipd_m : float, stereo eye separation in metres (64 mm)
    texture_m : float, metres covered by the texture's width on the walls
    truth_cell_deg : float, cell size of the truth grid in degrees (divides 180)
    """

    scene: str
    seconds: float = 3.0
    fps: float = 30.0
    size: tuple[int, int] = (1024, 512)
    layout: str = "mono"
    texture: str | None = None
    seed: int = 0
    axis: tuple[float, float, float] = (0.0, 1.0, 0.0)
    omega_dps: float = 30.0
    speed_mps: float | None = None
    ipd_m: float = 0.064
    texture_m: float = 3.0
    truth_cell_deg: float = 4.0

    def __post_init__(self) -> None:
        if self.scene not in SCENES:
            raise InputError(f"unknown scene {self.scene!r}; expected one of {', '.join(SCENES)}")
        for name in ("seconds", "fps", "omega_dps", "ipd_m", "texture_m", "truth_cell_deg"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a finite number > 0; got {v!r}")
        if self.speed_mps is not None and not (
            math.isfinite(self.speed_mps) and self.speed_mps > 0
        ):
            raise InputError(f"speed must be a finite number > 0 m/s; got {self.speed_mps!r}")
        if self.fps > MAX_FPS:
            raise InputError(f"fps must be at most {MAX_FPS:g} frames/s; got {self.fps:g}")
        if self.seconds * self.fps > MAX_FRAMES + 0.5:
            raise InputError(
                f"a clip of {self.seconds:g} s at {self.fps:g} fps has "
                f"{self.seconds * self.fps:.4g} frames; at most {MAX_FRAMES:,} "
                "(lower --seconds or --fps)"
            )
        if self.n_frames < 2:
            raise InputError(
                f"a clip of {self.seconds} s at {self.fps} fps has {self.n_frames} frame(s); flow needs at least 2"
            )
        try:
            w, h = int(self.size[0]), int(self.size[1])
        except (TypeError, ValueError, IndexError):
            raise InputError(
                f"size must be (W, H) pixels, e.g. 1024x512; got {self.size!r}"
            ) from None
        if w != 2 * h or h < 16 or h % 2:
            raise InputError(
                f"equirect size must be 2:1 with an even height >= 16, e.g. 1024x512; got {w}x{h}"
            )
        object.__setattr__(self, "size", (w, h))
        if self.layout not in SYNTH_LAYOUTS:
            raise InputError(
                f"unknown layout {self.layout!r}; expected one of {', '.join(SYNTH_LAYOUTS)}"
            )
        a = np.asarray(self.axis, float)
        if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) < 1e-9:
            raise InputError(
                f"rotation axis must be three numbers, not all zero, e.g. 0,1,0; got {self.axis!r}"
            )
        object.__setattr__(self, "axis", tuple(float(x) for x in a))
        n = 180.0 / self.truth_cell_deg
        if abs(n - round(n)) > 1e-6:
            raise InputError(
                f"truth cell size must divide 180 degrees, e.g. 2; got {self.truth_cell_deg}"
            )

    @property
    def n_frames(self) -> int:
        return round(self.seconds * self.fps)

    @property
    def eyes(self) -> tuple[str, ...]:
        return ("left", "right") if self.layout == "top-bottom" else ("mono",)

    @property
    def speed(self) -> float:
        """Speed actually used (m/s): the given one or the scene's default."""
        if self.speed_mps is not None:
            return float(self.speed_mps)
        return {"forward": 2.0, "coaster": 6.0}.get(self.scene, 0.0)

    def to_dict(self) -> dict:
        return {
            "scene": self.scene,
            "seconds": self.seconds,
            "fps": self.fps,
            "size": list(self.size),
            "layout": self.layout,
            "texture": self.texture,
            "seed": self.seed,
            "axis": list(self.axis),
            "omega_dps": self.omega_dps,
            "speed_mps": self.speed_mps,
            "ipd_m": self.ipd_m,
            "texture_m": self.texture_m,
            "truth_cell_deg": self.truth_cell_deg,
        }


def angular_speed_dps(
    dirs_cam: NDArray, omega_cam_dps: NDArray, vel_cam_mps: NDArray, depth_m: NDArray
) -> NDArray:
    """Angular speed (deg/s) of static points seen along camera-frame rays.

    ``|-(w_c x d) - (v_c - (v_c . d) d) / r|`` (derivation in the module docstring).

    Parameters
    ----------
    dirs_cam : ndarray, shape (..., 3), unit rays in the camera frame
    omega_cam_dps : ndarray, shape (3,), camera angular velocity in the camera frame, deg/s
    vel_cam_mps : ndarray, shape (3,), eye velocity in the camera frame, m/s
    depth_m : ndarray, shape (...), distance to the point along each ray (inf allowed)

    Returns
    -------
    ndarray, shape (...), float64, deg/s
    """
    d = np.asarray(dirs_cam, float)
    w = np.radians(np.asarray(omega_cam_dps, float))
    v = np.asarray(vel_cam_mps, float)
    rot = -np.cross(w, d)
    vd = d @ v
    trans = -(v - vd[..., None] * d) / np.asarray(depth_m, float)[..., None]
    return np.degrees(np.linalg.norm(rot + trans, axis=-1))


@dataclass(frozen=True)
class _Box:
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def intersect(self, origin: NDArray, dirs: NDArray) -> tuple[NDArray, NDArray]:
        """Distance along unit rays ``(..., 3)`` from an inside ``origin`` to the box, and
        the face hit (0..5: -x, +x, -y, +y, -z, +z)."""
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_hi = (hi - origin) / dirs
            t_lo = (lo - origin) / dirs
        t = np.where(dirs > 0, t_hi, np.where(dirs < 0, t_lo, np.inf))
        axis = np.argmin(t, axis=-1)
        dist = np.take_along_axis(t, axis[..., None], -1)[..., 0]
        face = 2 * axis + (np.take_along_axis(dirs, axis[..., None], -1)[..., 0] > 0)
        return dist, face

    def contains(self, p: NDArray, margin: float = 0.0) -> bool:
        return bool(
            np.all(p > np.asarray(self.lo) + margin) and np.all(p < np.asarray(self.hi) - margin)
        )


class SynthScene:
    """A camera trajectory through a static world, with rendering and analytic flow.

    Built by :func:`make_scene` from a :class:`SynthConfig`. Times in seconds.
    """

    def __init__(self, cfg: SynthConfig, texture: NDArray[np.uint8], texture_name: str):
        self.cfg = cfg
        self.texture_name = texture_name
        W, H = cfg.size
        self._pixel_rad = math.pi / H
        if cfg.scene == "rotate":
            self.box = None
            th, tw = texture.shape[:2]
            # The panorama must be an equirect image (resizing a 16:9 photo would distort it).
            check_equirect_aspect(tw, th, source=f"{texture_name}: rotate texture")
            if (tw, th) != (W, H):
                interp = cv2.INTER_AREA if tw > W else cv2.INTER_CUBIC
                texture = cv2.resize(texture, (W, H), interpolation=interp)
            self._pano_padded = pad_equirect(texture)
            a = np.asarray(cfg.axis) / np.linalg.norm(cfg.axis)
            self._axis = a
        else:
            self._mip = _MipTexture(texture)
            self._texels_per_m = texture.shape[1] / cfg.texture_m
            rng = np.random.default_rng(cfg.seed)
            self._face_offset = rng.uniform(0, 2 * cfg.texture_m, (6, 2))
            if cfg.scene == "forward":
                length = cfg.speed * cfg.seconds
                self.box = _Box((-3.0, -1.6, -20.0), (3.0, 2.4, length + 30.0))
            elif cfg.scene == "coaster":
                self.box = _Box((-17.0, -4.5, -12.5), (17.0, 6.5, 12.5))
                self._coaster_w = self._coaster_rate(cfg.speed)
            else:
                self.box = self._make_room()
            self._check_inside_room()

    # -- hooks for subclasses (simulator.synth.trajectory) -------------------------------
    def _make_room(self) -> _Box:
        """The room of a scene without a built-in one (subclasses override)."""
        raise InputError(
            f"the {self.cfg.scene} scene needs a camera path: vimsim synth --camera CAMERA.csv "
            "(Python: simulator.synth.trajectory.make_trajectory_scene)"
        )

    def _check_inside_room(self) -> None:
        """InputError if the camera comes within 0.2 m of a wall."""
        cfg = self.cfg
        for t in np.linspace(0, cfg.seconds, 64):
            if not self.box.contains(self.position(float(t)), margin=0.2):
                raise InputError(
                    f"{cfg.scene}: the camera leaves the room at t = {t:.2f} s; lower --speed or --seconds"
                )

    def truth_extras(self, dirs_cam: NDArray, times_s: NDArray) -> tuple[dict[str, NDArray], dict]:
        """Extra arrays and meta entries for the truth file (none for the built-in
        scenes); ``dirs_cam`` are the truth cells' rays, ``times_s`` its row times."""
        return {}, {}

    # -- trajectory ------------------------------------------------------------------
    @staticmethod
    def _lissajous(s: NDArray | float) -> tuple[NDArray, NDArray, NDArray]:
        """Coaster path at phase ``s`` (radians): position, d/ds, d2/ds2 (metres)."""
        s = np.asarray(s, float)
        A, B, C = 12.0, 8.0, 2.0
        p = np.stack([A * np.sin(s), C * np.sin(3 * s), B * np.sin(2 * s)], -1)
        dp = np.stack([A * np.cos(s), 3 * C * np.cos(3 * s), 2 * B * np.cos(2 * s)], -1)
        ddp = np.stack([-A * np.sin(s), -9 * C * np.sin(3 * s), -4 * B * np.sin(2 * s)], -1)
        return p, dp, ddp

    @classmethod
    def _coaster_rate(cls, mean_speed: float) -> float:
        s = np.linspace(0, 2 * np.pi, 2001)[:-1]
        return mean_speed / float(np.mean(np.linalg.norm(cls._lissajous(s)[1], axis=-1)))

    def position(self, t: float) -> NDArray[np.float64]:
        """Rig centre ``c(t)`` in the world frame, metres."""
        cfg = self.cfg
        if cfg.scene == "rotate":
            return np.zeros(3)
        if cfg.scene == "forward":
            return np.array([0.0, 0.0, cfg.speed * t])
        return self._lissajous(self._coaster_w * t + 0.3)[0]

    def velocity(self, t: float) -> NDArray[np.float64]:
        """Rig velocity ``dc/dt`` in the world frame, m/s (analytic)."""
        cfg = self.cfg
        if cfg.scene == "rotate":
            return np.zeros(3)
        if cfg.scene == "forward":
            return np.array([0.0, 0.0, cfg.speed])
        return self._lissajous(self._coaster_w * t + 0.3)[1] * self._coaster_w

    def rotation(self, t: float) -> Rotation:
        """``R(t)``: camera-frame vectors to world-frame vectors."""
        cfg = self.cfg
        if cfg.scene == "rotate":
            # The panorama turns by +omega t about the axis, so the camera by -omega t.
            return Rotation.from_rotvec(-self._axis * math.radians(cfg.omega_dps) * t)
        if cfg.scene == "forward":
            return Rotation.identity()
        w = self._coaster_w
        _, dp, ddp = self._lissajous(w * t + 0.3)
        vel, acc = dp * w, ddp * w * w
        f = vel / np.linalg.norm(vel)
        right = np.cross([0.0, 1.0, 0.0], f)
        right /= np.linalg.norm(right)
        up = np.cross(f, right)
        # Bank into the turn: roll (+ right ear down) = atan(lateral acceleration / g).
        roll = math.atan2(float(acc @ right), _G)
        look = Rotation.from_matrix(np.stack([right, up, f], axis=1))
        return look * Rotation.from_rotvec([0.0, 0.0, -roll])

    def omega_cam_dps(self, t: float, h: float = 1e-4) -> NDArray[np.float64]:
        """Camera angular velocity in the camera frame, deg/s (central difference of
        the analytic ``R(t)`` with step ``h`` seconds; relative error ~1e-8)."""
        if self.cfg.scene == "forward":
            return np.zeros(3)
        if self.cfg.scene == "rotate":
            return -self._axis * self.cfg.omega_dps
        w_world = (self.rotation(t + h) * self.rotation(t - h).inv()).as_rotvec() / (2 * h)
        return np.degrees(self.rotation(t).inv().apply(w_world))

    def eye_offset(self, eye: str) -> NDArray[np.float64]:
        """Camera-frame offset of an eye from the rig centre, metres."""
        half = self.cfg.ipd_m / 2.0
        return {
            "mono": np.zeros(3),
            "left": np.array([-half, 0.0, 0.0]),
            "right": np.array([half, 0.0, 0.0]),
        }[eye]

    def eye_velocity_cam(self, t: float, eye: str) -> NDArray[np.float64]:
        """Velocity of an eye in the camera frame, m/s: ``v_c + w_c x e``."""
        v_c = self.rotation(t).inv().apply(self.velocity(t))
        return v_c + np.cross(np.radians(self.omega_cam_dps(t)), self.eye_offset(eye))

    def eye_origin(self, t: float, eye: str) -> NDArray[np.float64]:
        return self.position(t) + self.rotation(t).apply(self.eye_offset(eye))

    # -- geometry and truth ------------------------------------------------------------
    def depth(self, t: float, dirs_cam: NDArray, eye: str = "mono") -> NDArray[np.float64]:
        """Distance (m) to the scene along camera-frame unit rays ``(..., 3)`` (inf for
        the panorama at infinity)."""
        if self.box is None:
            return np.full(np.shape(dirs_cam)[:-1], np.inf)
        world = self.rotation(t).apply(np.asarray(dirs_cam, float).reshape(-1, 3))
        dist, _ = self.box.intersect(self.eye_origin(t, eye), world)
        return dist.reshape(np.shape(dirs_cam)[:-1])

    def speed_dps(self, t: float, dirs_cam: NDArray, eye: str = "mono") -> NDArray[np.float64]:
        """Analytic angular speed (deg/s) at time ``t`` of the static points seen along
        camera-frame unit rays ``dirs_cam`` ``(..., 3)`` by ``eye`` (mono/left/right)."""
        return angular_speed_dps(
            dirs_cam,
            self.omega_cam_dps(t),
            self.eye_velocity_cam(t, eye),
            self.depth(t, dirs_cam, eye),
        )

    # -- rendering -------------------------------------------------------------------
    @functools.cached_property
    def _cam_dirs(self) -> NDArray[np.float64]:
        W, H = self.cfg.size
        lon, lat = equirect_pixel_lonlat(W, H)
        LO, LA = np.meshgrid(lon, lat)
        return lonlat_to_dir(LO, LA)

    def render_eye(self, t: float, eye: str = "mono") -> NDArray[np.uint8]:
        """One eye's equirect frame ``(H, W, 3)`` uint8 RGB at time ``t`` seconds."""
        R = self.rotation(t)
        if self.box is None:
            # Output pixel d (camera) shows the panorama at world direction R d.
            W, H = self.cfg.size
            world = R.apply(self._cam_dirs.reshape(-1, 3)).reshape(H, W, 3)
            mx, my = equirect_remap_coords(world, W, H)
            return cv2.remap(
                self._pano_padded, mx, my, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE
            )
        W, H = self.cfg.size
        world = R.apply(self._cam_dirs.reshape(-1, 3))
        origin = self.eye_origin(t, eye)
        dist, face = self.box.intersect(origin, world)
        hit = origin + world * dist[:, None]
        axis = face // 2
        # Texture coordinates (metres) on each face: x faces (z, y), y faces (x, z), z faces (x, y).
        uu = np.where(axis == 0, hit[:, 2], hit[:, 0])
        vv = np.where(axis == 1, hit[:, 2], hit[:, 1])
        off = self._face_offset[face]
        k = self._texels_per_m
        u = (uu + off[:, 0]) * k
        v = (-vv + off[:, 1]) * k
        cos_inc = np.abs(np.take_along_axis(world, axis[:, None], 1)[:, 0])
        footprint = dist * self._pixel_rad / np.sqrt(np.maximum(cos_inc, 1e-3)) * k
        lod = np.log2(np.maximum(footprint, 1.0))
        rgb = self._mip.sample(u.reshape(H, W), v.reshape(H, W), lod.reshape(H, W))
        return np.clip(rgb + 0.5, 0, 255).astype(np.uint8)

    def render(self, t: float) -> NDArray[np.uint8]:
        """The clip's frame at time ``t`` (both eyes stacked for top-bottom)."""
        eyes = self.cfg.eyes
        imgs = [self.render_eye(t, e) for e in eyes]
        return imgs[0] if len(imgs) == 1 else np.concatenate(imgs, axis=0)


def window_truth_dps(
    scene: SynthScene,
    grid: WindowGrid,
    times_s: NDArray,
    eye: str = "mono",
    *,
    rays: int = 24,
) -> NDArray[np.float64]:
    """Analytic POF of every window of ``grid``: the solid-angle-weighted mean of the true
    angular speed over the window's rays (what ``pof_dps`` of a grid file estimates).

    Parameters
    ----------
    scene : the scene (the equirect frame is its camera frame)
    grid : window grid (centres, FOVs; ``rays x rays`` pixel-centre rays per window are
        used, weighted by their solid angles, whatever ``grid.size``)
    times_s : ndarray, shape (T,), seconds (e.g. :attr:`Truth.time_s`)
    eye : ``"mono"``, ``"left"`` or ``"right"``

    Returns
    -------
    ndarray, shape (T, P, Y), deg/s
    """
    dirs, sa = perspective_rays((rays, rays), grid.hfov_deg, grid.vfov_deg)
    pitch, yaw = grid.centres_deg()
    R = head_rotation(yaw.ravel(), pitch.ravel(), 0.0).as_matrix()
    world = np.einsum("nij,hwj->nhwi", R, dirs.astype(np.float64)).reshape(-1, 3)
    wts = np.broadcast_to(sa.astype(np.float64), (len(R), rays, rays)).reshape(len(R), -1)
    P, Y = grid.shape
    out = np.empty((len(times_s), P, Y))
    for k, t in enumerate(np.asarray(times_s, float)):
        s = scene.speed_dps(float(t), world, eye).reshape(len(R), -1)
        out[k] = ((s * wts).sum(1) / wts.sum(1)).reshape(P, Y)
    return out


def make_scene(cfg: SynthConfig) -> SynthScene:
    """Load the texture and build the scene of ``cfg``."""
    tex, name = load_texture(cfg.texture)
    return SynthScene(cfg, tex, name)
