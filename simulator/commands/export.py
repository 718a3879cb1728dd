"""``vimsim export GRID.npz -o DIR [--format unity|web]``: the POF matrix or the sphere-mode field
for a game engine or a web player, with its runtime (Unity: ``VimsimEpof.cs``; web: ``vimsim.js``)."""

from __future__ import annotations

import argparse

from simulator.commands._opacity import add_opacity_arguments, rule_from_args
from simulator.commands._types import add_fov_arguments, fov_from_args

__all__ = ["register", "run"]

_FORMATS = ("unity", "web")
_METHODS = ("auto", "paper", "sphere")  # = simulator.export.unity.METHODS (light import)
_DTYPES = ("auto", "float16", "float32")  # = simulator.export.unity.DTYPES


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
        "roll tilts the head right ear down). See docs/unity.md.",
    )
    p.add_argument("grid", metavar="GRID.npz", help="grid file from vimsim preprocess")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument(
        "--format",
        choices=_FORMATS,
        default="unity",
        help="unity (default): vimsim_epof.bin + the C# runtime; web: the same data, the overlap "
        "table and grain layout with an ES-module runtime (vimsim.js, vimsim_gl.js) and "
        "example.html (docs/web.md)",
    )
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
    add_opacity_arguments(p)  # the same rule options (and defaults: comfort) as vimsim epof
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Export; InputError -> exit 2 with nothing written."""
    from simulator.export.unity import export_unity

    hfov, vfov = fov_from_args(args, (None, None))  # default: the grid's window FOV
    rule = rule_from_args(args)
    if args.format == "web":
        return _run_web(args, hfov, vfov, rule)
    res = export_unity(
        args.grid,
        args.output,
        method=args.method,
        dtype=args.dtype,
        hfov_deg=hfov,
        vfov_deg=vfov,
        rule=rule,
    )
    h = res.header
    shape = "x".join(str(s) for s in res.shape)
    rounding = f", rounded <= {res.max_rel_error:.2g} relative" if res.max_rel_error else ""
    print(
        f"wrote {res.out_dir}: {res.files[0].name} ({res.mode} mode, {res.dtype} {shape}, "
        f"{res.file_bytes / 1024:.0f} KiB; grid file {res.grid_bytes / 1024:.0f} KiB{rounding}), "
        f"{', '.join(f.name for f in res.files[1:])}; viewport {h['viewport']['hfov_deg']:g} x "
        f"{h['viewport']['vfov_deg']:g} deg, opacity 0 at {h['opacity']['low_dps']:.3g}, 1 at "
        f"{h['opacity']['high_dps']:.3g} deg/s ({h['opacity']['name']} rule: ease-in "
        f"{h['opacity']['ease_in_s']:g} s, ease-out {h['opacity']['ease_out_s']:g} s, smoothing "
        f"{h['opacity']['smoothing_s']:g} s)"
    )
    return 0


def _run_web(args: argparse.Namespace, hfov, vfov, rule) -> int:
    from simulator.export.web import export_web

    res = export_web(args.grid, args.output, method=args.method, dtype=args.dtype,
                     hfov_deg=hfov, vfov_deg=vfov, rule=rule)  # fmt: skip
    h = res.header
    print(
        f"wrote {res.out_dir}: {', '.join(f.name for f in res.files)} ({res.mode} mode; viewport "
        f"{h['viewport']['hfov_deg']:g} x {h['viewport']['vfov_deg']:g} deg; opacity 0 at "
        f"{h['opacity']['low_dps']:.3g}, 1 at {h['opacity']['high_dps']:.3g} deg/s); open "
        "example.html over http (docs/web.md)"
    )
    return 0
