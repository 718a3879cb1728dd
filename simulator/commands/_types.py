"""argparse ``type=`` validators shared by the subcommands.

Each raises ``argparse.ArgumentTypeError`` with an example of a valid value.
"""

from __future__ import annotations

import argparse

__all__ = ["fov_deg", "nonneg_int", "positive_float", "size_wxh", "unit_interval"]


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
        raise argparse.ArgumentTypeError(f"size must be 1..16384 per side, e.g. 256x256; got {text!r}")
    return w, h


def fov_deg(text: str) -> float:
    """Parse a field of view in degrees, strictly inside (0, 180) (e.g. ``107``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"FOV must be degrees in (0, 180), e.g. 107; got {text!r}") from None
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
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, e.g. 0; got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, e.g. 0; got {text!r}")
    return v


def unit_interval(text: str) -> float:
    """Parse a number in [0, 1] (e.g. ``0.5``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], e.g. 0.5; got {text!r}") from None
    if not (0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(f"expected a number in [0, 1], e.g. 0.5; got {text!r}")
    return v
