"""What the eye sees, as one frozen value (frustum, render config, opacity rule, mitigation), built from options once.

:meth:`ViewSpec.from_options` is the one builder from options to a :class:`ViewSpec`:
``vimsim render`` and ``vimsim frames`` give it their argparse namespace, a study gives it
the merged ``[render]``, ``[grf]`` and ``[epof]`` tables of its manifest (plain TOML
values). Both spell the options alike (the CLI's ``--grain-size`` is the manifest's
``grain_size``), so the same viewing gets the same view either way: a headset's
asymmetric per-eye frustum, the grains, the mitigation and the eased opacity rule.
Every check names the option as the caller spells it (``--eye-size`` on the command
line, ``eye_size`` in a manifest, or the caller's own labels). Angles are degrees.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from simulator.core.choices import EPOF_METHODS, MITIGATIONS, SYSTEM_PRESETS
from simulator.core.errors import InputError
from simulator.core.resources import check_fits
from simulator.mitigation.cao2021 import cao_grf_config
from simulator.mitigation.grf import (
    RULE_OPTIONS,
    GrfConfig,
    OpacityRule,
    grain_count,
    rule_from_options,
)
from simulator.mitigation.kinds import APERTURE_MIN_DEG, FEATHER_DEG, Mitigation, parse_color
from simulator.render.eye import RenderConfig
from simulator.sphere.cells import Frustum
from simulator.sphere.headsets import get_headset

__all__ = ["VIEW_OPTIONS", "ViewSpec"]

#: H.264 level 6.2's largest frame in 16x16 macroblocks (8192x4320 and the like).
MAX_H264_MACROBLOCKS = 139264
#: Estimated bytes per eye pixel while rendering (framebuffers, read-back, encoder frames).
BYTES_PER_EYE_PIXEL = 48
#: Grains the mask pass takes, and their estimated bytes each (directions, buckets).
MAX_GRAINS = 5_000_000
BYTES_PER_GRAIN = 64

#: The option names :meth:`ViewSpec.from_options` reads, with their defaults (None: not
#: given). The CLI's options are these with ``--`` and ``-`` for ``_``; a manifest's keys
#: are these names ( ``grid`` is the CLI's grid file, True in a study: it always has one).
VIEW_OPTIONS: dict[str, object] = {
    "eye_size": (1440, 1440),
    "fov": None,
    "hfov": None,
    "vfov": None,
    "headset": None,
    "grid": None,
    "grf": None,
    "mitigation": None,
    "aperture_min": APERTURE_MIN_DEG,
    "feather": FEATHER_DEG,
    "vignette_color": "0,0,0",
    "opacity": "auto",
    "method": "auto",
    "low_pct": 10.0,
    "high_pct": 90.0,
    "opacity_source": "grid",
    "opacity_rule": "comfort",
    "smooth": None,
    "ease_in": None,
    "ease_out": None,
    "low_dps": None,
    "high_dps": None,
    "seed": 0,
    "grain_size": 1.5,
    "density": 0.5,
    "cutout": (18.0, 40.0),
    "grain_distance": None,
    "hold_last": False,
    "preset": "vimsim",
}


@dataclass(frozen=True)
class ViewSpec:
    """What the eye sees in one viewing, checked (degrees, seconds).

    config : :class:`simulator.render.eye.RenderConfig`: eye size, the left eye's frustum
        (a headset's exact asymmetric one, or a symmetric FOV), grains (None: none drawn)
        and the :class:`simulator.mitigation.kinds.Mitigation` with its options
    rule : the :class:`simulator.mitigation.grf.OpacityRule` of ``opacity="auto"``
        (percentiles, smoothing, easing)
    opacity : ``"auto"`` (from the EPOF through ``rule``), a constant in [0, 1], or an
        EPOF CSV's path (its opacity column)
    method : EPOF method (``auto``, ``paper``, ``sphere``)
    hold : hold the head path's first/last pose where it does not cover the video
    preset : the system whose rules run (:data:`simulator.core.choices.SYSTEM_PRESETS`):
        ``vimsim``; ``paper`` (``method`` paper, the paper's rule); ``cao2021-code``: the
        opacity of ``"auto"`` is the authors' nearest-window rule on the fixed px/frame
        scale (:func:`simulator.epof.nearest.nearest_epof`), the grains theirs
        (:func:`simulator.mitigation.cao2021.cao_grf_config`); ``rule`` and ``method`` unused
    """

    config: RenderConfig = field(default_factory=RenderConfig)
    rule: OpacityRule = field(default_factory=OpacityRule)
    opacity: float | str = "auto"
    method: str = "auto"
    hold: bool = False
    preset: str = "vimsim"

    def __post_init__(self) -> None:
        if self.preset not in SYSTEM_PRESETS:
            raise InputError(
                f"preset must be one of {', '.join(SYSTEM_PRESETS)}; got {self.preset!r}"
            )
        if not isinstance(self.config, RenderConfig):
            raise InputError(
                f"view config must be a RenderConfig; got {type(self.config).__name__}"
            )
        if not isinstance(self.rule, OpacityRule):
            raise InputError(f"view rule must be an OpacityRule; got {type(self.rule).__name__}")
        if self.method not in EPOF_METHODS:
            raise InputError(
                f"EPOF method must be one of {', '.join(EPOF_METHODS)}; got {self.method!r}"
            )
        op = self.opacity
        if isinstance(op, os.PathLike):
            object.__setattr__(self, "opacity", os.fspath(op))
        elif not isinstance(op, str):
            if isinstance(op, bool) or not (0.0 <= float(op) <= 1.0):
                raise InputError(
                    f"opacity must be 'auto', a number in [0, 1] or an EPOF CSV; got {op!r}"
                )
            object.__setattr__(self, "opacity", float(op))
        object.__setattr__(self, "hold", bool(self.hold))

    @property
    def frustum(self) -> Frustum:
        """The left eye's frustum (the right eye mirrors left and right)."""
        return self.config.frustum

    @property
    def mitigation(self) -> Mitigation:
        return self.config.mitigation

    @property
    def grains(self) -> GrfConfig | None:
        """The grain parameters when grains are drawn, else None."""
        return self.config.grains

    @property
    def drawn(self) -> bool:
        """Something is drawn over the video (grains or a vignette)."""
        return self.grains is not None or self.mitigation.vignette

    @classmethod
    def given(cls, view: ViewSpec | None = None, **fields) -> ViewSpec:
        """``view`` with ``fields`` (``config``, ``rule``, ``opacity``, ``method``, ``hold``,
        ``preset``)
        replaced; the default view when None: how the library functions take a view
        (``view=ViewSpec(...)`` or its fields as keywords, e.g. ``opacity=0.8``)."""
        if view is None:
            return cls(**fields)
        if not isinstance(view, ViewSpec):
            raise InputError(f"view must be a ViewSpec; got {type(view).__name__}")
        return dataclasses.replace(view, **fields) if fields else view

    @classmethod
    def from_options(
        cls,
        options,
        *,
        video: bool = True,
        label: Callable[[str], str] | None = None,
    ) -> ViewSpec:
        """The view the options ask for: the one builder from options.

        options : an ``argparse.Namespace`` (``vimsim render``/``frames``) or a mapping
            (a study's merged tables, an API caller's dict) of the names in
            :data:`VIEW_OPTIONS`; a missing or None value takes the default. ``eye_size``
            is ``(w, h)`` or ``"WxH"``, ``cutout`` ``(inner, outer)``.
        video : the eyes are encoded as H.264 (even sizes up to level 6.2's largest
            frame); False for PNGs (``vimsim frames``)
        label : how an option is named in messages; default ``--grain-size`` for a
            namespace, ``grain_size`` for a mapping

        GRF on/off as ``vimsim render`` documents it: on with a grid or a numeric opacity
        unless ``grf = "off"``; an explicit mitigation draws what it names. A headset
        gives its exact per-eye frustum; FOV options a symmetric one (default 107 x 107).
        ``preset`` (docs/parity.md): ``paper`` sets ``method`` paper and the paper's
        opacity rule; ``cao2021-code`` draws the authors' grains (0.5 deg, Fibonacci
        layout, no cutout) at their rule's opacity; options a preset fixes otherwise are
        refused. InputError naming the option for any bad value.
        """
        mapping = isinstance(options, Mapping)
        if label is None:
            label = _mapping_label if mapping else _cli_label
        opt = _Options(options, mapping, label)
        preset = opt.preset()
        frustum = opt.frustum()
        mitigation = opt.mitigation(frustum)
        size = opt.eye_size(video)
        opacity = opt.opacity()
        grf_opt = opt.get("grf")
        if grf_opt not in (None, "on", "off"):
            opt.fail("grf", f"expected on or off; got {grf_opt!r}")
        kind_given = opt.get("mitigation") is not None
        grf_on = grf_opt == "on" or (
            grf_opt is None and (bool(opt.get("grid")) or opacity != "auto")
        )
        if kind_given:  # an explicit mitigation draws what it names
            grf_on = grf_opt != "off" and mitigation.grains
        grf = opt.grf()  # checked whether drawn or not
        if preset == "cao2021-code":  # their grains, at the given seed and distance
            grf = dataclasses.replace(cao_grf_config(seed=grf.seed), distance_m=grf.distance_m)
        config = RenderConfig(
            eye_size=size,
            frustum=frustum,
            grf=opt.count_grains(grf) if grf_on else None,
            mitigation=mitigation,
        )
        method = opt.get("method")
        if method not in EPOF_METHODS:
            opt.fail("method", f"expected one of {', '.join(EPOF_METHODS)}; got {method!r}")
        hold = opt.get("hold_last")
        if not isinstance(hold, bool):
            opt.fail("hold_last", f"expected true or false; got {hold!r}")
        method = "paper" if preset == "paper" else method
        return cls(config, opt.rule(preset), opacity, method, hold, preset)


def _cli_label(key: str) -> str:
    return "--" + key.replace("_", "-")


def _mapping_label(key: str) -> str:
    return key


class _Options:
    """Reads and checks the values of :data:`VIEW_OPTIONS` from a namespace or a mapping."""

    def __init__(self, options, mapping: bool, label: Callable[[str], str]):
        self.o, self.mapping, self.label = options, mapping, label

    def get(self, key: str):
        v = self.o.get(key) if self.mapping else getattr(self.o, key, None)
        return VIEW_OPTIONS[key] if v is None else v

    def fail(self, key: str, msg: str):
        raise InputError(f"{self.label(key)}: {msg}")

    def number(self, key: str, lo=None, hi=None, *, lo_open=False, hi_open=False) -> float | None:
        v = self.get(key)
        if v is None:
            return None
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.fail(key, f"expected a number; got {v!r}")
        low = lo is not None and (v < lo or (lo_open and v == lo))
        high = hi is not None and (v > hi or (hi_open and v == hi))
        if low or high:
            rng = f"{'(' if lo_open else '['}{lo if lo is not None else '-inf'}, "
            rng += f"{hi if hi is not None else 'inf'}{')' if hi_open else ']'}"
            self.fail(key, f"expected a number in {rng}; got {v!r}")
        return float(v)

    def choice(self, key: str, choices) -> str:
        v = self.get(key)
        if v not in choices:
            self.fail(key, f"expected one of {', '.join(choices)}; got {v!r}")
        return v

    def frustum(self) -> Frustum:
        """A headset's exact per-eye (left) frustum, or a symmetric FOV (default 107)."""
        given = [k for k in ("headset", "fov", "hfov") if self.get(k) is not None]
        if self.get("hfov") is None and self.get("vfov") is not None:
            given.append("vfov")
        if len(given) > 1:
            names = [self.label(k) for k in given]
            raise InputError(f"give only one of {', '.join(names)}")
        headset = self.get("headset")
        if headset is not None:
            if not isinstance(headset, str):
                self.fail("headset", f"expected a headset name; got {headset!r}")
            try:
                get_headset(headset)
            except InputError as e:
                self.fail("headset", str(e))
            return Frustum.from_headset(headset, "left")
        if self.get("vfov") is not None and self.get("hfov") is None:
            raise InputError(f"{self.label('vfov')} needs {self.label('hfov')}")
        fov = self.number("fov", 0.0, 180.0, lo_open=True, hi_open=True)
        hfov = self.number("hfov", 0.0, 180.0, lo_open=True, hi_open=True)
        vfov = self.number("vfov", 0.0, 180.0, lo_open=True, hi_open=True)
        key = "fov" if fov is not None else "hfov"
        h, v = (fov, fov) if fov is not None else (hfov, vfov if vfov is not None else hfov)
        if h is None:
            h = v = 107.0
        try:
            return Frustum.symmetric(h, v)
        except InputError as e:
            self.fail(key, str(e))

    def eye_size(self, video: bool) -> tuple[int, int]:
        v = self.get("eye_size")
        try:
            if isinstance(v, str):
                w, h = (int(x) for x in v.lower().split("x"))
            else:
                w, h = v
                if isinstance(w, bool) or isinstance(h, bool) or w != int(w) or h != int(h):
                    raise ValueError
                w, h = int(w), int(h)
        except (TypeError, ValueError):
            self.fail("eye_size", f'expected WxH pixels, e.g. "480x480"; got {v!r}')
        if not (0 < w <= 16384 and 0 < h <= 16384):
            self.fail("eye_size", f"expected 1..16384 pixels per side, e.g. 480x480; got {w}x{h}")
        if video:
            if w % 2 or h % 2:
                self.fail("eye_size", f"{w}x{h}: H.264 needs even numbers, e.g. 480x480")
            if -(-w // 16) * -(-h // 16) > MAX_H264_MACROBLOCKS or max(w, h) > 8192:
                self.fail(
                    "eye_size",
                    f"{w}x{h}: beyond H.264's largest frame (level 6.2: 8192x4320); e.g. 2048x2048",
                )
        check_fits(2 * w * h * BYTES_PER_EYE_PIXEL, f"{self.label('eye_size')} {w}x{h}")
        return w, h

    def mitigation(self, frustum: Frustum) -> Mitigation:
        kind = self.get("mitigation")
        kind = "grf" if kind is None else kind
        if kind not in MITIGATIONS:
            self.fail("mitigation", f"expected one of {', '.join(MITIGATIONS)}; got {kind!r}")
        aperture = self.number("aperture_min", 0.0, 180.0, lo_open=True, hi_open=True)
        feather = self.number("feather", 0.0, 180.0)
        try:
            color = parse_color(self.get("vignette_color"))
        except InputError as e:
            self.fail("vignette_color", str(e))
        m = Mitigation(kind, aperture_min_deg=aperture, feather_deg=feather, color=color)
        if m.vignette and not aperture < frustum.hfov_deg:
            self.fail(
                "aperture_min",
                f"expected degrees in (0, FOV) = (0, {frustum.hfov_deg:g}); got {aperture:g}",
            )
        return m

    def opacity(self) -> float | str:
        v = self.get("opacity")
        if isinstance(v, os.PathLike):
            v = os.fspath(v)
        if isinstance(v, str):
            if v == "auto" or v.lower().endswith(".csv"):
                return v
            self.fail("opacity", f"expected auto, a number in [0, 1] or an EPOF CSV; got {v!r}")
        return self.number("opacity", 0.0, 1.0)

    def grf(self) -> GrfConfig:
        size = self.number("grain_size", 0.0, 90.0, lo_open=True, hi_open=True)
        density = self.number("density", 0.0, 1.0, lo_open=True, hi_open=True)
        cut = self.get("cutout")
        if (
            isinstance(cut, (str, bytes))
            or not hasattr(cut, "__len__")
            or len(cut) != 2
            or not all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in cut)
        ):
            self.fail("cutout", f"expected INNER OUTER degrees, e.g. 18 40; got {cut!r}")
        seed = self.get("seed")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            self.fail("seed", f"expected an integer >= 0; got {seed!r}")
        distance = self.number("grain_distance", 0.0, lo_open=True)
        try:
            return GrfConfig(size, density, float(cut[0]), float(cut[1]), seed, distance)
        except InputError as e:
            self.fail("cutout" if "cutout" in str(e) else "grain_size", str(e))

    def count_grains(self, grf: GrfConfig) -> GrfConfig:
        """``grf``, once its grains fit the mask pass and the memory."""
        size, density = grf.grain_deg, grf.density
        n = grain_count(grf)
        if n > MAX_GRAINS:
            self.fail(
                "grain_size",
                f"{size:g} with {self.label('density')} {density:g} needs {n} grains "
                f"(at most {MAX_GRAINS}); choose a larger grain size, e.g. 0.5",
            )
        check_fits(n * BYTES_PER_GRAIN, f"{self.label('grain_size')} {size:g}")
        return grf

    def rule(self, preset: str = "vimsim") -> OpacityRule:
        """The opacity rule (:func:`simulator.mitigation.grf.rule_from_options`; the
        paper's with ``preset`` paper)."""

        def get(k):
            if preset == "paper" and k == "opacity_rule":
                return "paper"
            return self.o.get(k) if self.mapping else getattr(self.o, k, None)

        return rule_from_options(get, self.label)

    def preset(self) -> str:
        """The system preset, once the options it fixes are checked: with either preset
        ``method`` sphere and the absolute rule are refused; with ``cao2021-code`` also any
        grain, cutout, method, mitigation or opacity-rule option other than its default."""
        preset = self.choice("preset", SYSTEM_PRESETS)
        if preset == "vimsim":
            return preset
        given = [k for k, v in (("method", "sphere"), ("opacity_rule", "absolute"))
                 if self.get(k) == v]  # fmt: skip
        if preset == "cao2021-code":
            keys = ("grain_size", "density", "method", *RULE_OPTIONS)
            given += [k for k in keys if self.get(k) != VIEW_OPTIONS.get(k) and k not in given]
            if self.get("mitigation") not in (None, "grf"):
                given.append("mitigation")
            cut = self.get("cutout")
            if not isinstance(cut, (list, tuple)) or tuple(cut) != VIEW_OPTIONS["cutout"]:
                given.append("cutout")
        if given:
            names = ", ".join(self.label(k) for k in given)
            self.fail("preset", f"{preset} fixes {names}; drop {names}")
        return preset
