"""argparse ``type=`` validators shared by the subcommands.

Each raises ``argparse.ArgumentTypeError`` with an example of a valid value.
"""

from __future__ import annotations

import argparse

__all__ = [
    "add_fov_arguments",
    "crf",
    "fov_deg",
    "fov_from_args",
    "nonneg_int",
    "positive_float",
    "size_wxh",
    "unit_interval",
]


def size_wxh(text: str) -> tuple[int, int]:
    """Parse ``"WxH"`` (e.g. ``"1440x1600"``) into ``(width, height)`` in pixels."""
    parts = text.lower().split("x")
    try:
        if len(parts) != 2:
            raise ValueError
        w, h = int(parts[0]), int(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"size must be WxH in pixels, e.g. 1440x1600; got {text!r}"
        ) from None
    if w <= 0 or h <= 0 or w > 16384 or h > 16384:
        raise argparse.ArgumentTypeError(
            f"size must be 1..16384 per side, e.g. 256x256; got {text!r}"
        )
    return w, h


def crf(text: str) -> int:
    """Parse an x264 constant rate factor, an integer 0..51 (e.g. ``18``)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer 0..51, e.g. 18; got {text!r}"
        ) from None
    if not 0 <= v <= 51:
        raise argparse.ArgumentTypeError(
            f"expected an integer 0..51 (x264's range), e.g. 18; got {text!r}"
        )
    return v


def fov_deg(text: str) -> float:
    """Parse a field of view in degrees, strictly inside (0, 180) (e.g. ``107``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"FOV must be degrees in (0, 180), e.g. 107; got {text!r}"
        ) from None
    if not (0.0 < v < 180.0):
        raise argparse.ArgumentTypeError(f"FOV must be degrees in (0, 180), e.g. 107; got {text!r}")
    return v


def positive_float(text: str) -> float:
    """Parse a finite number > 0 (e.g. ``30``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, e.g. 30; got {text!r}") from None
    if not (v > 0.0 and v < float("inf")):
        raise argparse.ArgumentTypeError(f"expected a number > 0, e.g. 30; got {text!r}")
    return v


def nonneg_int(text: str) -> int:
    """Parse an integer >= 0 (e.g. ``0``)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an integer >= 0, e.g. 0; got {text!r}"
        ) from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, e.g. 0; got {text!r}")
    return v


def unit_interval(text: str) -> float:
    """Parse a number in [0, 1] (e.g. ``0.5``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a number in [0, 1], e.g. 0.5; got {text!r}"
        ) from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], e.g. 0.5; got {text!r}")
    return v


def add_fov_arguments(
    p: argparse.ArgumentParser, *, what: str, default: str, headset: bool = True
) -> None:
    """Add ``--fov``, ``--hfov``, ``--vfov`` (and ``--headset``) to a subcommand's parser.

    Resolve them with :func:`fov_from_args`: one rule for every command (``--fov`` sets
    both axes; ``--vfov`` defaults to ``--hfov``; a headset profile gives its per-eye FOV).
    """
    p.add_argument(
        "--fov",
        type=fov_deg,
        default=None,
        metavar="D",
        help=f"{what} FOV in degrees, horizontal = vertical (default {default})",
    )
    p.add_argument(
        "--hfov",
        type=fov_deg,
        default=None,
        metavar="D",
        help=f"exact horizontal {what} FOV in degrees (--vfov defaults to it)",
    )
    p.add_argument(
        "--vfov",
        type=fov_deg,
        default=None,
        metavar="D",
        help=f"exact vertical {what} FOV in degrees (with --hfov)",
    )
    if headset:
        from simulator.headsets import HEADSETS

        p.add_argument(
            "--headset",
            default=None,
            metavar="NAME",
            help=f"per-eye FOV of a headset profile: {', '.join(HEADSETS)} "
            "(vive-pro-eye = 107 x 107, the paper's HMD); instead of --fov/--hfov/--vfov",
        )


def fov_from_args(args: argparse.Namespace, default):
    """``(hfov_deg, vfov_deg)`` from the options of :func:`add_fov_arguments`.

    ``default`` is returned when none is given (e.g. ``(107.0, 107.0)``, or
    ``(None, None)`` for "the grid's FOV"). InputError for conflicting options.
    """
    from simulator.headsets import resolve_fov

    return resolve_fov(
        headset=getattr(args, "headset", None),
        fov_deg=args.fov,
        hfov_deg=args.hfov,
        vfov_deg=args.vfov,
        default=default,
    )
