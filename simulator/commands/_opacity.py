"""The GRF opacity options and the system ``--preset`` shared by ``vimsim epof``, ``render`` and ``frames`` (argparse only)."""

from __future__ import annotations

import argparse

from simulator.commands._types import nonneg_float, percentile, seconds
from simulator.core.choices import OPACITY_SOURCES, SYSTEM_PRESETS, X264_PRESETS

__all__ = ["add_opacity_arguments", "add_preset_argument", "rule_from_args", "system_preset"]

#: ``--preset``'s help, one text for every command that takes it (docs/parity.md).
PRESET_HELP = (
    "the system whose rules run: vimsim (default): the options as given; paper: the paper's "
    "text (overlap-weighted EPOF, --method paper --opacity-rule paper, 1.5 deg grains, 36-80 "
    "deg cutout); cao2021-code: the authors' Unity code (the nearest window's flow with their "
    "CSV list indexing, row k-2 at frame k, opacity on the fixed 0.18..53.73 px/frame scale "
    "or an imported grid's, black 0.5 deg grains on their Fibonacci layout, no cutout; "
    "docs/parity.md)"
)


def system_preset(text: str) -> str:
    """argparse type of ``--preset``: one of :data:`SYSTEM_PRESETS`; an x264 preset name
    is refused with the option that takes it (``--x264-preset``)."""
    if text in SYSTEM_PRESETS:
        return text
    if text in X264_PRESETS:
        raise argparse.ArgumentTypeError(
            f"{text!r} is an x264 preset: give it as --x264-preset {text}; --preset takes "
            f"{', '.join(SYSTEM_PRESETS)}"
        )
    raise argparse.ArgumentTypeError(f"expected one of {', '.join(SYSTEM_PRESETS)}; got {text!r}")


def add_preset_argument(p: argparse.ArgumentParser) -> None:
    """``--preset vimsim|paper|cao2021-code``: the whole system's rules (declared once)."""
    p.add_argument("--preset", type=system_preset, default="vimsim",
                   metavar="|".join(SYSTEM_PRESETS), help=PRESET_HELP)  # fmt: skip


def add_opacity_arguments(p: argparse.ArgumentParser, *, sources=OPACITY_SOURCES) -> None:
    """``--low-pct --high-pct --opacity-source --smooth --ease-in --ease-out --opacity-rule
    --low-dps --high-dps``;
    ``sources``: the ``--opacity-source`` values the command can use (export: grid only)."""
    g = p.add_argument_group("GRF opacity rule (EPOF -> opacity)")
    g.add_argument(
        "--low-pct",
        type=percentile,
        default=10.0,
        metavar="P",
        help="opacity 0 at this percentile (10)",
    )
    g.add_argument(
        "--high-pct",
        type=percentile,
        default=90.0,
        metavar="P",
        help="opacity 1 at this percentile (90)",
    )
    g.add_argument(
        "--opacity-source",
        choices=sources,
        default="grid",
        help="percentiles of every window of every frame (grid, the paper)"
        + (" or of this viewing's EPOF (viewing)" if "viewing" in sources else ""),
    )
    g.add_argument(
        "--opacity-rule",
        choices=("comfort", "paper", "absolute"),
        default="comfort",
        help="comfort (default): eased, see --ease-in/--ease-out; paper: the paper's rule, "
        "opacity follows the EPOF frame by frame (no smoothing, no easing); absolute: eased "
        "as comfort, opacity 0 at --low-dps and 1 at --high-dps deg/s whatever the video "
        "(comfort and paper are relative: percentiles of this video's flow)",
    )
    g.add_argument(
        "--low-dps",
        type=nonneg_float,
        default=None,
        metavar="A",
        help="absolute rule: opacity 0 at A deg/s (default 5, the vection band's lower edge)",
    )
    g.add_argument(
        "--high-dps",
        type=nonneg_float,
        default=None,
        metavar="B",
        help="absolute rule: opacity 1 at B deg/s (default 30, the provocative band's lower edge)",
    )
    g.add_argument(
        "--smooth",
        type=seconds,
        default=None,
        metavar="S",
        help="causal exponential smoothing of the opacity, time constant S seconds (default 0 = off)",
    )
    g.add_argument(
        "--ease-in",
        type=seconds,
        default=None,
        metavar="S",
        help="grains come in: a full 0 -> 1 opacity change takes at least S seconds "
        "(default 0.4 with the comfort rule; 0 = no limit)",
    )
    g.add_argument(
        "--ease-out",
        type=seconds,
        default=None,
        metavar="S",
        help="grains leave: a full 1 -> 0 change takes at least S seconds "
        "(default 1.5 with the comfort rule; 0 = no limit)",
    )


def rule_from_args(args: argparse.Namespace):
    """The :class:`simulator.mitigation.grf.OpacityRule` the options ask for, by the one
    builder :func:`simulator.mitigation.grf.rule_from_options` (InputError if
    ``--opacity-rule paper`` is combined with smoothing or easing)."""
    from simulator.mitigation.grf import rule_from_options

    return rule_from_options(
        lambda name: getattr(args, name, None), lambda name: "--" + name.replace("_", "-")
    )
