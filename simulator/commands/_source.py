"""The options that say what a source is (``--projection``, ``--lens-fov``, ``--ignore-orientation``; ``--seconds``/``--fps`` of a still) and the :class:`simulator.media.source.Source` they open."""

from __future__ import annotations

import argparse

from simulator.commands._types import positive_float
from simulator.core.choices import PROJECTIONS, STILL_FPS, STILL_SECONDS

__all__ = ["add_source_arguments", "source_from_args"]


def add_source_arguments(
    p: argparse.ArgumentParser, *, still: bool = False, orientation: bool = True
) -> None:
    """Add ``--projection``, ``--lens-fov`` and (unless ``orientation`` is False)
    ``--ignore-orientation`` (and with ``still``, ``--seconds``/``--fps``)."""
    p.add_argument(
        "--projection",
        choices=PROJECTIONS,
        default=None,
        help="input projection, ffmpeg v360's names: equirect, eac (equi-angular cubemap, "
        "YouTube), c3x2 / c6x1 (cubemaps, faces r l u / d f b), dfisheye (dual fisheye), "
        "hequirect (half equirect, VR180 per eye) (default: the file's spherical metadata, "
        "else equirect; docs/sources.md)",
    )
    p.add_argument(
        "--lens-fov",
        type=positive_float,
        default=None,
        metavar="DEG",
        help="dual fisheye: each lens's field of view in degrees, in (180, 360) (default 190)",
    )
    if orientation:
        _add_ignore_orientation(p)
    if still:
        _add_still(p)


def _add_ignore_orientation(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--ignore-orientation",
        action="store_true",
        help="ignore the initial orientation of the file's spherical metadata (sv3d prhd "
        "yaw/pitch/roll; default: applied, head yaw/pitch/roll 0 looks where it says; "
        "docs/sources.md)",
    )


def _add_still(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--seconds",
        type=float,
        default=None,
        metavar="S",
        help=f"a still image is a clip of S seconds (default {STILL_SECONDS:g})",
    )
    p.add_argument(
        "--fps",
        type=positive_float,
        default=None,
        metavar="F",
        help=f"a still image's clip rate, frames/s (default {STILL_FPS:g})",
    )


def source_from_args(
    args: argparse.Namespace, path, *, layout=None, eye="left", right=None, layout_default="mono"
):
    """The checked Source of ``path`` with the options of :func:`add_source_arguments`
    (``layout`` None: the file's metadata, else ``layout_default``); its notes (an option
    overriding the file's spherical metadata) go to stderr, one line each."""
    import sys

    from simulator.media.source import Source

    still = None
    if hasattr(args, "seconds") and hasattr(args, "fps"):
        still = (args.seconds, args.fps)
    src = Source.open(
        path,
        layout=layout,
        projection=args.projection,
        right=right,
        eye=eye,
        lens_fov_deg=args.lens_fov,
        still=still,
        layout_default=layout_default,
        orientation=not getattr(args, "ignore_orientation", False),
    )
    for note in src.notes:
        print(f"vimsim: note: {note}", file=sys.stderr)
    return src
