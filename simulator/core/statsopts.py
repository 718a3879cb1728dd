"""The options of the study statistics (design, transform, power, bootstrap), declared once in one table.

``vimsim analyze`` generates its argparse options from :data:`STATS_OPTIONS`, and
:class:`simulator.analyze.stats.StatsOptions` takes its defaults and its checks from the same
table, so the command line and the library cannot drift apart. Nothing here imports anything
heavier than :mod:`dataclasses` (the CLI's fast start).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from simulator.core.errors import InputError

__all__ = ["DESIGNS", "STATS_OPTIONS", "TRANSFORMS", "StatsOption", "check_stats_option"]

#: Study designs: ``auto`` detects from the data (a participant id in more than one row).
DESIGNS: tuple[str, ...] = ("auto", "between", "within", "mixed")

#: Transforms of the model's response: ``log1p`` for right-skewed SSQ scores.
TRANSFORMS: tuple[str, ...] = ("none", "log1p")


@dataclass(frozen=True)
class StatsOption:
    """One option: its name (``--name`` on the command line), type, default, bounds, help."""

    name: str
    kind: type
    default: Any
    help: str
    choices: tuple[str, ...] | None = None
    low: float | None = None  # exclusive lower bound
    high: float | None = None  # exclusive upper bound
    minimum: int | None = None  # inclusive lower bound (integers)
    example: str = ""

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


STATS_OPTIONS: tuple[StatsOption, ...] = (
    StatsOption(
        "design",
        str,
        "auto",
        "study design: between (one row per participant), "
        "within (each participant in both conditions), mixed (several videos or sessions "
        "per participant); auto detects it (an id in more than one row)",
        choices=DESIGNS,
    ),
    StatsOption(
        "transform",
        str,
        "none",
        "transform of the model's response: log1p for right-skewed SSQ scores (log(1 + score))",
        choices=TRANSFORMS,
    ),
    StatsOption(
        "power",
        float,
        None,
        "target power of the next study, e.g. 0.8: writes power.csv (participants needed)",
        low=0.0,
        high=1.0,
        example="0.8",
    ),
    StatsOption(
        "alpha",
        float,
        0.05,
        "significance level of the power analysis and of every interval (1 - alpha)",
        low=0.0,
        high=1.0,
        example="0.05",
    ),
    StatsOption(
        "effect",
        float,
        None,
        "standardised effect for the power analysis (d_z within, "
        "Cohen's d between); default: the observed one",
        example="0.5",
    ),
    StatsOption(
        "seed",
        int,
        0,
        "seed of the bootstrap intervals (same seed, same intervals)",
        minimum=0,
        example="0",
    ),
    StatsOption(
        "n_boot", int, 2000, "bootstrap resamples per effect interval", minimum=200, example="2000"
    ),
)


def check_stats_option(name: str, value: Any) -> Any:
    """``value`` checked against the table's entry ``name`` (None stays None where the
    default is None); InputError naming the option, what arrived and an example."""
    opt = next((o for o in STATS_OPTIONS if o.name == name), None)
    if opt is None:
        raise InputError(
            f"unknown statistics option {name!r}; expected one of {[o.name for o in STATS_OPTIONS]}"
        )
    if value is None and opt.default is None:
        return None
    if opt.choices is not None:
        if value not in opt.choices:
            raise InputError(f"{opt.flag}: {value!r}; expected one of {', '.join(opt.choices)}")
        return value
    try:
        if opt.kind is int and (isinstance(value, bool) or float(value) != int(float(value))):
            raise ValueError
        v = opt.kind(value)
    except (TypeError, ValueError):
        raise InputError(
            f"{opt.flag}: {value!r} is not a {opt.kind.__name__}; e.g. {opt.flag} {opt.example}"
        ) from None
    if isinstance(v, float) and not math.isfinite(v):
        raise InputError(f"{opt.flag}: {value!r} is not finite; e.g. {opt.flag} {opt.example}")
    if opt.low is not None and not v > opt.low or opt.high is not None and not v < opt.high:
        raise InputError(
            f"{opt.flag}: {value!r} outside ({opt.low:g}, {opt.high:g}) "
            f"(bounds excluded); e.g. {opt.flag} {opt.example}"
        )
    if opt.minimum is not None and v < opt.minimum:
        raise InputError(
            f"{opt.flag}: {value!r} below {opt.minimum}; e.g. {opt.flag} {opt.example}"
        )
    if name == "effect" and v == 0.0:
        raise InputError(
            f"{opt.flag}: 0 needs infinitely many participants; give a nonzero "
            "standardised effect, e.g. --effect 0.5"
        )
    return v
