"""argparse ``type=`` validators shared by the subcommands.

Each raises ``argparse.ArgumentTypeError`` with an example of a valid value.
"""

from __future__ import annotations

import argparse
import math

__all__ = [
    "add_fov_arguments",
    "angle_deg",
    "finite_float",
    "fov_deg",
    "fov_from_args",
    "frustum_from_args",
    "nonneg_deg",
    "nonneg_float",
    "nonneg_int",
    "number",
    "percentile",
    "positive_float",
    "positive_int",
    "seconds",
    "size_wxh",
    "unit_interval",
    "x264_crf",
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


def number(
    expected: str,
    example: str,
    *,
    integer: bool = False,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    hi_open: bool = False,
):
    """A ``type=`` validator of one number: the one factory behind every numeric option.

    ``expected`` is the first half of the error ("expected a number >= 0"), ``example`` a
    valid value; bounds ``lo``/``hi`` are inclusive unless ``*_open``. Floats must be finite.
    The error reads ``"<expected>, e.g. <example>; got '<text>'"``.
    """

    def parse(text: str):
        msg = f"{expected}, e.g. {example}; got {text!r}"
        try:
            v = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(msg) from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(msg)
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise argparse.ArgumentTypeError(msg)
        if hi is not None and (v > hi or (hi_open and v == hi)):
            raise argparse.ArgumentTypeError(msg)
        return v

    parse.__name__ = parse.__qualname__ = "number"
    parse.__doc__ = f"Parse {expected.removeprefix('expected ')} (e.g. ``{example}``)."
    return parse


#: A field of view in degrees, strictly inside (0, 180) (e.g. ``107``).
fov_deg = number(
    "FOV must be degrees in (0, 180)", "107", lo=0.0, hi=180.0, lo_open=True, hi_open=True
)
#: A finite number > 0 (e.g. ``30``).
positive_float = number("expected a number > 0", "30", lo=0.0, lo_open=True)
#: A finite number >= 0 (e.g. ``1000``).
nonneg_float = number("expected a number >= 0", "1000", lo=0.0)
#: An angle in degrees >= 0 (e.g. ``10``).
nonneg_deg = number("expected degrees >= 0", "10", lo=0.0)
#: Seconds >= 0 (e.g. ``1.5``).
seconds = number("expected seconds >= 0", "1.5", lo=0.0)
#: An integer >= 0 (e.g. ``0``).
nonneg_int = number("expected an integer >= 0", "0", integer=True, lo=0)
#: An integer >= 1 (e.g. ``4``).
positive_int = number("expected an integer >= 1", "4", integer=True, lo=1)
#: A number in [0, 1] (e.g. ``0.5``).
unit_interval = number("expected a number in [0, 1]", "0.5", lo=0.0, hi=1.0)
#: A percentile in [0, 100] (e.g. ``10``).
percentile = number("expected a percentile in [0, 100]", "10", lo=0.0, hi=100.0)
#: A finite number (e.g. ``30``).
finite_float = number("expected a finite number", "30")
#: A finite angle in degrees (e.g. ``-30.5``).
angle_deg = number("expected a finite angle in degrees", "-30.5")
#: An x264 CRF (e.g. ``16``).
x264_crf = number("expected an x264 CRF, an integer 0..51", "16", integer=True, lo=0, hi=51)


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
        from simulator.core.choices import HEADSET_NAMES  # light: the parser stays numpy-free

        p.add_argument(
            "--headset",
            default=None,
            metavar="NAME",
            help=f"per-eye FOV of a headset profile: {', '.join(HEADSET_NAMES)} "
            "(vive-pro-eye = 107 x 107, the paper's HMD); instead of --fov/--hfov/--vfov",
        )


def fov_from_args(args: argparse.Namespace, default):
    """``(hfov_deg, vfov_deg)`` from the options of :func:`add_fov_arguments`.

    ``default`` is returned when none is given (e.g. ``(107.0, 107.0)``, or
    ``(None, None)`` for "the grid's FOV"). InputError for conflicting options.
    """
    from simulator.sphere.headsets import resolve_fov

    return resolve_fov(
        headset=getattr(args, "headset", None),
        fov_deg=args.fov,
        hfov_deg=args.hfov,
        vfov_deg=args.vfov,
        default=default,
    )


def frustum_from_args(args: argparse.Namespace, default, eye: str = "left"):
    """The one :class:`simulator.sphere.cells.Frustum` of the options of :func:`add_fov_arguments`.

    A headset profile gives its exact (asymmetric) per-eye frustum for ``eye``; FOV options
    a symmetric one; ``default`` (``(hfov, vfov)`` or ``(None, None)``) when none is given,
    ``None`` if that is ``(None, None)`` (e.g. "the grid's FOV"). Built and checked once,
    then carried to EPOF and the renderer.
    """
    from simulator.sphere.cells import Frustum

    if getattr(args, "headset", None):
        fov_from_args(args, default)  # refuses --headset together with FOV options
        return Frustum.from_headset(args.headset, eye)
    hfov, vfov = fov_from_args(args, default)
    if hfov is None:
        return None
    return Frustum.symmetric(hfov, vfov)
