"""``vimsim export GRID.npz -o DIR [--format unity|web]``: the POF matrix or the sphere-mode field
for a game engine or a web player, with its runtime (Unity: ``VimsimEpof.cs``; web: ``vimsim.js``)."""

from __future__ import annotations

import argparse

from simulator.commands._opacity import add_opacity_arguments, add_preset_argument, rule_from_args
from simulator.commands._types import (
    add_fov_arguments,
    fov_from_args,
    nonneg_deg,
    nonneg_int,
    positive_float,
)

__all__ = ["register", "run"]

_FORMATS = ("unity", "web", "cao-csv")
_METHODS = ("auto", "paper", "sphere")  # = simulator.export.unity.METHODS (light import)
_DTYPES = ("auto", "float16", "float32")  # = simulator.export.unity.DTYPES
#: = simulator.core.choices.MITIGATIONS; local-grf is refused with its reason (the overlay
#: draws one opacity per frame, not one per field cell).
_MITIGATIONS = ("grf", "vignette", "grf+vignette", "local-grf", "none")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export`` parser."""
    p = subparsers.add_parser(
        "export",
        help="the POF matrix or sphere field for a game engine, with a C# runtime (Unity)",
        description="Write DIR/vimsim_epof.bin (the grid's POF matrix, or its sphere-mode field, as "
        "little-endian float16/float32 with a JSON header: layout, FOV, fps, frames, opacity "
        "thresholds and rule, source video hash) and the C# runtime DIR/VimsimEpof.cs (no "
        "UnityEngine dependency) with an optional MonoBehaviour DIR/VimsimEpofBehaviour.cs. "
        "The runtime gives the same EPOF as 'vimsim epof' for a video time and a head "
        "orientation (degrees: positive yaw turns right, positive pitch looks up, positive "
        "roll tilts the head right ear down). The folder is a Unity package (package.json, "
        "asmdef, importer) with the overlay shader (VimsimOverlay.hlsl/.shader: the grains and "
        "vignette of vimsim render, from the grain layout and settings in the file) and a "
        "prefab. See docs/unity.md.",
    )
    p.add_argument("grid", metavar="GRID.npz", help="grid file from vimsim preprocess")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument(
        "--format",
        choices=_FORMATS,
        default="unity",
        help="unity (default): vimsim_epof.bin + the C# runtime; web: the same vimsim_epof.bin "
        "(and the overlap table in paper mode) with an ES-module runtime (vimsim.js, "
        "vimsim_grains.js, vimsim_gl.js) and example.html (docs/web.md); the overlay options "
        "apply to both; cao-csv: a paper-mode grid's pof_px in the authors' Unity layout (one "
        "horizontal_<yaw>_vertical_<pitch>.csv per window and percentileData.csv, from --preset "
        "cao2021-code's fixed 0.18/53.73 px/frame or the grid's --low-pct/--high-pct "
        "percentiles of pof_px; docs/parity.md)",
    )
    add_preset_argument(p)  # cao-csv: cao2021-code = their fixed scale in percentileData.csv;
    # unity / web: the header records it; cao2021-code adds their rule (DIR/cao2021/)
    p.add_argument(
        "--method",
        choices=_METHODS,
        default="auto",
        help="paper: the window POF matrix (overlap weights, paper 3.5); sphere: the field "
        "(exact integration over the viewport); auto (default): sphere when the grid has a "
        "field, as vimsim epof",
    )
    p.add_argument(
        "--dtype",
        choices=_DTYPES,
        default="auto",
        help="float16 (half the size; values rounded to 2^-11 relative) or float32; auto "
        "(default): the precision vimsim epof uses (float32 POFs, the field's stored dtype)",
    )
    add_fov_arguments(p, what="viewport", default="the grid's window FOV")
    # The same rule options (and defaults: comfort) as vimsim epof; the 'viewing' source
    # needs a whole viewing, which an engine export does not have: not offered.
    add_opacity_arguments(p, sources=("grid",))
    _add_overlay_arguments(p)
    p.set_defaults(func=run)


def _add_overlay_arguments(p: argparse.ArgumentParser) -> None:
    """The overlay's options, as vimsim render's (same names and defaults)."""
    p.add_argument("--mitigation", choices=_MITIGATIONS, default="grf",
                   help="what the overlay draws (default grf; as vimsim render --mitigation)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=0, metavar="N",
                   help="seed of the grain layout (default 0)")  # fmt: skip
    p.add_argument("--grain-size", type=float, default=1.5, metavar="DEG",
                   help="grain diameter, degrees (default 1.5)")  # fmt: skip
    p.add_argument("--density", type=float, default=0.5, metavar="F",
                   help="blocked fraction of the view, 0..1 exclusive (default 0.5)")  # fmt: skip
    p.add_argument("--cutout", type=float, nargs=2, default=(18.0, 40.0), metavar=("INNER", "OUTER"),
                   help="cutout radii from the view centre, degrees (default 18 40)")  # fmt: skip
    p.add_argument("--aperture-min", type=positive_float, default=60.0, metavar="DEG",
                   help="vignette aperture diameter at opacity 1, degrees (default 60)")  # fmt: skip
    p.add_argument("--feather", type=nonneg_deg, default=10.0, metavar="DEG",
                   help="width of the vignette's soft edge, degrees (default 10)")  # fmt: skip
    p.add_argument("--vignette-color", default="0,0,0", metavar="R,G,B",
                   help="vignette colour, R,G,B 0..255 or #RRGGBB (default black)")  # fmt: skip


def _overlay_from_args(args: argparse.Namespace):
    """``(GrfConfig, Mitigation)``; one line naming the option for bad values."""
    from simulator.core.errors import InputError
    from simulator.mitigation.grf import GrfConfig
    from simulator.mitigation.kinds import Mitigation, parse_color

    if not (0.0 < args.grain_size <= 30.0):
        raise InputError(f"--grain-size must be degrees in (0, 30], e.g. 1.5; got {args.grain_size:g}")
    if not (0.0 < args.density < 1.0):
        raise InputError(f"--density must be a blocked fraction in (0, 1), e.g. 0.5; got {args.density:g}")
    if args.mitigation == "local-grf":
        raise InputError(
            "--mitigation local-grf cannot be exported: the overlay draws one opacity per frame; "
            "choose grf, vignette, grf+vignette or none"
        )
    inner, outer = args.cutout
    if not (0.0 <= inner < outer <= 180.0):
        raise InputError(
            f"--cutout INNER OUTER must satisfy 0 <= INNER < OUTER <= 180 degrees, e.g. 18 40; "
            f"got {inner:g} {outer:g}"
        )
    grf = GrfConfig(grain_deg=args.grain_size, density=args.density, inner_deg=inner,
                    outer_deg=outer, seed=args.seed)  # fmt: skip
    mit = Mitigation(args.mitigation, aperture_min_deg=args.aperture_min,
                     feather_deg=args.feather, color=parse_color(args.vignette_color))  # fmt: skip
    return grf, mit


def run(args: argparse.Namespace) -> int:
    """Export; InputError -> exit 2 with nothing written."""
    from simulator.export.unity import export_unity

    hfov, vfov = fov_from_args(args, (None, None))  # default: the grid's window FOV
    if args.preset == "paper" and args.format != "cao-csv":
        args.method = "paper" if args.method == "auto" else args.method
        args.opacity_rule = "paper" if args.opacity_rule == "comfort" else args.opacity_rule
    rule = rule_from_args(args)
    if args.format == "cao-csv":
        return _run_cao_csv(args, rule)
    grf, mitigation = _overlay_from_args(args)  # the same overlay options for both formats
    preset = _engine_preset(args)
    if args.preset == "cao2021-code":  # their grains: 0.5 deg, Fibonacci layout, no cutout
        from simulator.mitigation.cao2021 import cao_grf_config

        grf = cao_grf_config(seed=args.seed)
    if args.format == "web":
        rc = _run_web(args, hfov, vfov, rule, grf, mitigation, preset)
        return rc if preset["name"] != "cao2021-code" else _write_cao_rule(args)
    res = export_unity(
        args.grid,
        args.output,
        method=args.method,
        dtype=args.dtype,
        hfov_deg=hfov,
        vfov_deg=vfov,
        rule=rule,
        grf=grf,
        mitigation=mitigation,
        preset=preset,
    )
    h = res.header
    shape = "x".join(str(s) for s in res.shape)
    rounding = f", rounded <= {res.max_rel_error:.2g} relative" if res.max_rel_error else ""
    print(
        f"wrote {res.out_dir}: {res.files[0].name} ({res.mode} mode, {res.dtype} {shape}, "
        f"{res.file_bytes / 1024:.0f} KiB; grid file {res.grid_bytes / 1024:.0f} KiB{rounding}), "
        f"a Unity package ({len(res.files) - 1} files: runtime, overlay shader, prefab; "
        f"{res.n_grains} grains, {h['mitigation']}); viewport {h['viewport']['hfov_deg']:g} x "
        f"{h['viewport']['vfov_deg']:g} deg, opacity 0 at {h['opacity']['low_dps']:.3g}, 1 at "
        f"{h['opacity']['high_dps']:.3g} deg/s ({h['opacity']['name']} rule: ease-in "
        f"{h['opacity']['ease_in_s']:g} s, ease-out {h['opacity']['ease_out_s']:g} s, smoothing "
        f"{h['opacity']['smoothing_s']:g} s)"
    )
    return 0 if preset["name"] != "cao2021-code" else _write_cao_rule(args)


#: Where a unity / web export with ``--preset cao2021-code`` puts the authors' rule.
CAO_SUBDIR = "cao2021"


def _engine_preset(args: argparse.Namespace) -> dict:
    """The header's ``preset`` section of a unity / web export; for ``cao2021-code`` the
    options it fixes are refused and a sphere-mode grid too (InputError before writing)."""
    from simulator.core.errors import InputError
    from simulator.media.gridfile import load_grid

    if args.preset != "cao2021-code":
        return {"name": args.preset}
    given = [o for o, on in (("--grain-size", args.grain_size != 1.5),
                             ("--density", args.density != 0.5),
                             ("--cutout", tuple(args.cutout) != (18.0, 40.0)),
                             ("--mitigation", args.mitigation != "grf")) if on]  # fmt: skip
    if given:
        raise InputError(f"--preset cao2021-code fixes {', '.join(given)}; drop them")
    g = load_grid(args.grid)
    if g.field_dps is not None or g.meta.get("method") == "sphere":
        raise InputError(
            f"{args.grid}: a sphere-mode grid; --preset cao2021-code's nearest-window rule "
            "needs a paper-mode grid (vimsim preprocess --method paper --grid cao2021, or "
            "vimsim grid import)"
        )
    from simulator.epof.nearest import grid_px_rule

    r = grid_px_rule(g)
    return {"name": "cao2021-code", "rule": "nearest window, CSV list indexing (row k-2 at "
            "frame k), fixed px/frame scale (docs/parity.md)", "folder": CAO_SUBDIR,
            "runtime": {"unity": "VimsimCao2021.cs", "web": "vimsim_cao2021.js"},
            "low_px": r.low_px, "high_px": r.high_px}  # fmt: skip


def _write_cao_rule(args: argparse.Namespace) -> int:
    """``DIR/cao2021/``: the grid's windows in the authors' layout (with their frame-0 row
    when measured) and the runtimes of their rule, VimsimCao2021.cs and vimsim_cao2021.js."""
    import dataclasses
    from pathlib import Path

    from simulator.epof.nearest import grid_px_rule, preset_pof_px
    from simulator.export.caocsv import export_cao_csv
    from simulator.media.gridfile import load_grid

    g = load_grid(args.grid)
    r = grid_px_rule(g)
    g = dataclasses.replace(g, pof_px=preset_pof_px(g))
    files = export_cao_csv(g, Path(args.output) / CAO_SUBDIR, percentiles_px=(r.low_px, r.high_px))
    print(f"wrote {Path(args.output) / CAO_SUBDIR}: the authors' rule (--preset cao2021-code): "
          f"{len(files) - 3} window CSVs, percentileData.csv ({r.low_px:g}, {r.high_px:g} "
          "px/frame), VimsimCao2021.cs, vimsim_cao2021.js")  # fmt: skip
    return 0


def _run_web(args: argparse.Namespace, hfov, vfov, rule, grf, mitigation, preset=None) -> int:
    from simulator.export.web import export_web

    res = export_web(args.grid, args.output, method=args.method, dtype=args.dtype,
                     hfov_deg=hfov, vfov_deg=vfov, rule=rule, grf=grf,
                     mitigation=mitigation, preset=preset)  # fmt: skip
    h = res.header
    print(
        f"wrote {res.out_dir}: {', '.join(f.name for f in res.files)} ({res.mode} mode; viewport "
        f"{h['viewport']['hfov_deg']:g} x {h['viewport']['vfov_deg']:g} deg; opacity 0 at "
        f"{h['opacity']['low_dps']:.3g}, 1 at {h['opacity']['high_dps']:.3g} deg/s; "
        f"{h['grf']['n_grains']} grains, {h['mitigation']}); open example.html over http "
        "(docs/web.md)"
    )
    return 0


def _run_cao_csv(args: argparse.Namespace, rule) -> int:
    """``--format cao-csv``: the percentile file from the chosen rule (fixed px/frame for
    ``--preset cao2021-code``, else the grid's pof_px percentiles; absolute deg/s refused)."""
    import dataclasses

    import numpy as np

    from simulator.core.errors import InputError
    from simulator.export.caocsv import export_cao_csv
    from simulator.media.gridfile import load_grid
    from simulator.mitigation.cao2021 import CAO_HIGH_PX, CAO_LOW_PX

    g = load_grid(args.grid)
    if args.preset == "cao2021-code":
        from simulator.epof.nearest import preset_pof_px

        pct, how = (CAO_LOW_PX, CAO_HIGH_PX), "the authors' fixed scale"
        g = dataclasses.replace(g, pof_px=preset_pof_px(g))  # their frame-0 row, if measured
    elif rule.is_absolute:
        raise InputError(
            "--format cao-csv writes px/frame thresholds; an absolute deg/s rule has none: "
            "use --preset cao2021-code or a relative --opacity-rule"
        )
    else:
        lo, hi = np.percentile(np.asarray(g.pof_px, np.float64), [rule.low_pct, rule.high_pct])
        pct, how = (float(lo), float(hi)), f"pof_px percentiles {rule.low_pct:g}/{rule.high_pct:g}"
    files = export_cao_csv(g, args.output, percentiles_px=pct)
    print(
        f"wrote {args.output}: {len(files) - 3} window CSVs of {g.n_frames} frames, the "
        f"runtimes VimsimCao2021.cs and vimsim_cao2021.js, and percentileData.csv ({pct[0]:.4g}, {pct[1]:.4g} px/frame: {how})"
    )
    return 0
