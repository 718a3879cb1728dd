"""``vimsim synth``: synthetic equirect clips with analytic ground-truth flow."""

from __future__ import annotations

import argparse

from simulator.commands._types import nonneg_int, positive_float, size_wxh, x264_crf
from simulator.core.choices import CAMERA_INTERPS, SCENES, SYNTH_LAYOUTS

__all__ = ["register", "run"]


def _axis(text: str) -> tuple[float, float, float]:
    try:
        parts = [float(t) for t in text.split(",")]
        if len(parts) != 3 or not all(abs(p) < float("inf") for p in parts):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"axis must be three numbers X,Y,Z, e.g. 0,1,0; got {text!r}"
        ) from None
    if all(p == 0 for p in parts):
        raise argparse.ArgumentTypeError(f"axis must not be zero, e.g. 0,1,0; got {text!r}")
    return parts[0], parts[1], parts[2]


def _room(text: str) -> tuple[float, ...]:
    """Parse ``W,H,D`` (metres, e.g. ``8,4,20``) or the corners ``X0,Y0,Z0,X1,Y1,Z1``."""
    try:
        parts = tuple(float(t) for t in text.split(","))
        if len(parts) not in (3, 6) or not all(abs(p) < float("inf") for p in parts):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"room must be W,H,D or X0,Y0,Z0,X1,Y1,Z1 in metres, e.g. 8,4,20; got {text!r}"
        ) from None
    if len(parts) == 3 and min(parts) <= 0:
        raise argparse.ArgumentTypeError(
            f"room size must be > 0 m on each axis, e.g. 8,4,20; got {text!r}"
        )
    return parts


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``synth`` parser."""
    p = subparsers.add_parser(
        "synth",
        help="synthetic 360 clip with known motion and a ground-truth flow file",
        description="Render an equirectangular H.264 clip with known motion and write "
        "OUT.truth.npz beside it: the analytic angular speed (deg/s) of every cell of a "
        "lon/lat grid per frame (row t = motion from frame t-1 to t), the parameters and "
        "the camera trajectory. Scenes: rotate (a panorama turning about --axis at "
        "--omega deg/s), forward (the camera moving forward through a textured tunnel at "
        "--speed m/s), coaster (a figure-eight ride with hills, turns, banking and "
        "changing speed through a textured room), trajectory (any camera path from --camera "
        "CAMERA.csv through a textured room). See docs/synth.md.",
    )
    p.add_argument(
        "output", metavar="OUT.mp4", help="output clip (H.264); OUT.truth.npz is written beside it"
    )
    p.add_argument("--scene", required=True, choices=SCENES, help="which motion")
    p.add_argument(
        "--seconds",
        type=positive_float,
        default=None,
        help="clip length, seconds (default 3; trajectory: the CSV's time span)",
    )
    p.add_argument(
        "--camera",
        metavar="CAMERA.csv",
        default=None,
        help="trajectory: camera poses, columns time_s,x_m,y_m,z_m,yaw_deg,pitch_deg,roll_deg "
        "(world +x right, +y up, +z forward, metres; positive yaw turns right, pitch looks up, "
        "roll tilts right ear down), strictly increasing time, any sampling",
    )
    p.add_argument(
        "--room",
        type=_room,
        default=None,
        metavar="W,H,D",
        help="trajectory: room size in metres (x, y, z), centred on the path, floor 1.6 m below "
        "its lowest point; or the corners X0,Y0,Z0,X1,Y1,Z1 (negative first number: write "
        "--room=-3,...); default: the path's bounding box + 3 m on each side, 1.6 m below, "
        "2.4 m above",
    )
    p.add_argument(
        "--interp",
        choices=CAMERA_INTERPS,
        default="cubic",
        help="trajectory: positions between poses, linear or cubic spline (default cubic); "
        "orientations always Slerp",
    )
    p.add_argument(
        "--fps",
        type=positive_float,
        default=30.0,
        help="frames per second, at most 240 (default 30); seconds x fps <= 100,000 frames",
    )
    p.add_argument(
        "--size",
        type=size_wxh,
        default=(1024, 512),
        metavar="WxH",
        help="one eye's equirect size, 2:1 (default 1024x512); top-bottom clips are W x 2H",
    )
    p.add_argument(
        "--layout",
        choices=SYNTH_LAYOUTS,
        default="mono",
        help="mono, or top-bottom stereo (left eye on top, eyes 64 mm apart)",
    )
    p.add_argument(
        "--texture",
        metavar="IMG",
        default=None,
        help="texture image: the panorama for rotate (2:1 equirect, checked), tiled on the walls "
        "for forward/coaster/trajectory (default: the bundled procedural panorama)",
    )
    p.add_argument(
        "--seed", type=nonneg_int, default=0, help="texture placement on the walls (default 0)"
    )
    p.add_argument(
        "--axis",
        type=_axis,
        default=(0.0, 1.0, 0.0),
        metavar="X,Y,Z",
        help="rotate: rotation axis in the camera frame (+x right, +y up, +z forward); "
        "default 0,1,0 (right-handed: the content moves right, toward +lon)",
    )
    p.add_argument(
        "--omega",
        type=positive_float,
        default=30.0,
        metavar="DPS",
        help="rotate: rate, deg/s (default 30)",
    )
    p.add_argument(
        "--speed",
        type=positive_float,
        default=None,
        metavar="M/S",
        help="forward: camera speed (default 2 m/s); coaster: mean speed along the ride (default 6 m/s)",
    )
    p.add_argument(
        "--truth-cell",
        type=positive_float,
        default=4.0,
        metavar="DEG",
        help="cell size of the truth grid, degrees dividing 180 (default 4)",
    )
    p.add_argument(
        "--crf",
        type=x264_crf,
        default=16,
        help="x264 quality (CRF) 0..51, lower is better (default 16)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Render the clip and its truth file; print what was written."""
    from simulator.commands._progress import progress_bar
    from simulator.core.errors import InputError
    from simulator.synth import SynthConfig, synthesize

    if args.scene == "trajectory":
        return _run_trajectory(args)
    for opt, val in (("--camera", args.camera), ("--room", args.room)):
        if val is not None:
            raise InputError(f"{opt} is for --scene trajectory; got --scene {args.scene}")
    cfg = SynthConfig(
        scene=args.scene,
        seconds=3.0 if args.seconds is None else args.seconds,
        fps=args.fps,
        size=args.size,
        layout=args.layout,
        texture=args.texture,
        seed=args.seed,
        axis=args.axis,
        omega_dps=args.omega,
        speed_mps=args.speed,
        truth_cell_deg=args.truth_cell,
    )
    with progress_bar(f"synth {cfg.scene}") as bar:
        video, truth = synthesize(cfg, args.output, crf=args.crf, progress=bar)
    return _wrote(video, truth, cfg, cfg.scene)


def _run_trajectory(args: argparse.Namespace) -> int:
    from simulator.commands._progress import progress_bar
    from simulator.core.errors import InputError
    from simulator.synth.trajectory import synthesize_trajectory

    if args.camera is None:
        raise InputError("--scene trajectory needs --camera CAMERA.csv (docs/synth.md)")
    if args.seconds is not None:
        raise InputError(
            "--seconds does not apply to --scene trajectory: the clip covers the camera "
            "CSV's time span"
        )
    with progress_bar("synth trajectory") as bar:
        video, truth, cfg = synthesize_trajectory(
            args.camera,
            args.output,
            room_m=args.room,
            interp=args.interp,
            crf=args.crf,
            progress=bar,
            fps=args.fps,
            size=args.size,
            layout=args.layout,
            texture=args.texture,
            seed=args.seed,
            truth_cell_deg=args.truth_cell,
        )
    return _wrote(video, truth, cfg, f"trajectory {args.camera}")


def _wrote(video, truth, cfg, what: str) -> int:
    """The one summary line of a written clip and its truth file; exit status 0."""
    w, h = cfg.size
    print(
        f"wrote {video} ({what}, {cfg.n_frames} frames at {cfg.fps:g} fps, "
        f"{w}x{h * len(cfg.eyes)} {cfg.layout}) and {truth}"
    )
    return 0
