"""``vimsim viewport``: one perspective view from an equirect image or video frame."""

from __future__ import annotations

import argparse

from simulator.commands._source import add_source_arguments, source_from_args
from simulator.commands._types import (
    add_fov_arguments,
    angle_deg,
    fov_from_args,
    nonneg_int,
    size_wxh,
)
from simulator.core.choices import EYES, INTERPS, LAYOUTS
from simulator.core.errors import InputError

__all__ = ["DEFAULT_FOV_DEG", "DEFAULT_SIZE", "register", "run"]

#: Preview size (width, height) in pixels and FOV in degrees (HTC Vive Pro Eye: 107 x 107).
DEFAULT_SIZE = (512, 512)
DEFAULT_FOV_DEG = 107.0

# = simulator.sphere.geometry.LAYOUTS / EYES / INTERPS (kept light: no numpy/cv2 import here).


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``viewport`` parser."""
    p = subparsers.add_parser(
        "viewport",
        help="one perspective view (PNG) from an equirect image or video frame",
        description="Render what a head-mounted display shows at one head orientation: a "
        "perspective (gnomonic) view of an equirectangular image or video frame, bicubic. "
        "Angles in degrees: positive yaw turns right (toward +longitude), positive pitch "
        "looks up, positive roll tilts the head right ear down (the picture turns "
        "counter-clockwise). Applied yaw, then pitch, then roll, as ffmpeg's v360. "
        "See docs/geometry.md.",
    )
    p.add_argument("src", metavar="SRC", help="equirect image (.jpg, .png, ...) or video")
    p.add_argument(
        "-o", "--output", metavar="OUT.png", required=True, help="output PNG (written atomically)"
    )
    p.add_argument(
        "--yaw", type=angle_deg, required=True, metavar="D", help="degrees, + turns right"
    )
    p.add_argument(
        "--pitch", type=angle_deg, required=True, metavar="D", help="degrees, + looks up"
    )
    p.add_argument(
        "--roll",
        type=angle_deg,
        default=0.0,
        metavar="D",
        help="degrees, + right ear down (default 0)",
    )
    add_fov_arguments(p, what="view", default="107")
    p.add_argument(
        "--size",
        type=size_wxh,
        default=DEFAULT_SIZE,
        metavar="WxH",
        help=f"output size in pixels, e.g. 1440x1600 (default {DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]})",
    )
    p.add_argument(
        "--frame",
        type=nonneg_int,
        default=0,
        metavar="N",
        help="video frame index from 0 (default 0)",
    )
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=None,
        help="stereo layout: top-bottom = left eye on top, side-by-side = left eye on the left "
        "(default: the file's spherical metadata, else mono)",
    )
    p.add_argument(
        "--eye", choices=EYES, default="left", help="eye of a stereo source (default left)"
    )
    add_source_arguments(p)
    p.add_argument(
        "--interp",
        choices=INTERPS,
        default="cubic",
        help="cubic = OpenCV bicubic (as the window grid); lagrange = ffmpeg v360's cubic (default cubic)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Write the view; InputError (exit 2, no output) on bad input."""
    from PIL import Image

    from simulator.core.fileio import atomic_output
    from simulator.core.resources import check_fits

    hfov, vfov = fov_from_args(args, (DEFAULT_FOV_DEG, DEFAULT_FOV_DEG))
    # rays (float64 x 3, twice), lon/lat, maps and the image: about 120 bytes per pixel
    check_fits(args.size[0] * args.size[1] * 120, f"--size {args.size[0]}x{args.size[1]}")
    source = source_from_args(args, args.src, layout=args.layout, eye=args.eye)
    info, (w, h) = source.info, source.eye_size
    # the view in the frame: the head's angles turned by the file's initial orientation
    args.yaw, args.pitch, args.roll = (
        float(v) for v in source.view_angles_deg(args.yaw, args.pitch, args.roll)
    )
    if info.is_video and args.frame >= info.n_frames:
        raise InputError(
            f"{args.src}: has {info.n_frames} frames; --frame {args.frame} is beyond the last"
        )
    if not info.is_video and args.frame != 0:
        raise InputError(f"{args.src}: a still image has only frame 0; got --frame {args.frame}")
    if source.converter is not None:  # one resampling, straight from the projection
        view = _projected_view(source, args, hfov, vfov)
    else:
        view = _equirect_view(source, args, hfov, vfov, (w, h))
    with atomic_output(args.output) as tmp:
        Image.fromarray(view).save(tmp, format="PNG")
    what = f"frame {args.frame}" if info.is_video else "still"
    print(f"vimsim viewport: {view.shape[1]}x{view.shape[0]} view ({hfov:g} x {vfov:g} deg) at "
          f"yaw {args.yaw:g}, pitch {args.pitch:g}, roll {args.roll:g} deg of {what} -> "
          f"{args.output}")  # fmt: skip
    return 0


def _projected_view(source, args, hfov: float, vfov: float):
    """The view of a non-equirect source, sampled in its own projection (bicubic)."""
    import cv2

    from simulator.sphere import geometry

    if args.interp == "lagrange":
        raise InputError(
            f"--interp lagrange is for equirect sources; --projection {source.projection}"
        )
    flags = {"cubic": cv2.INTER_CUBIC, "linear": cv2.INTER_LINEAR, "nearest": cv2.INTER_NEAREST}
    rays, _ = geometry.perspective_rays(args.size, hfov, vfov)
    R = geometry.head_rotation(args.yaw, args.pitch, args.roll).as_matrix()
    stored = source.read(args.frame, convert=False)
    return source.converter.sample(stored, rays.astype(float) @ R.T, interp=flags[args.interp])


def _equirect_view(source, args, hfov: float, vfov: float, size):
    from simulator.sphere import geometry

    w, h = size
    eye = source.read(args.frame)
    if eye.shape[:2] != (h, w):
        raise InputError(
            f"{args.src}: decoded eye is {eye.shape[1]}x{eye.shape[0]}; expected {w}x{h}"
        )
    return geometry.extract_view(
        eye,
        args.yaw,
        args.pitch,
        args.roll,
        hfov_deg=hfov,
        vfov_deg=vfov,
        size=args.size,
        interp=args.interp,
    )
