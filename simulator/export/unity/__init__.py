"""The Unity export: ``vimsim_epof.bin`` (the POF matrix or the sphere-mode field, the grain layout
and the mitigation's settings, with a JSON header) and a UPM package around it: the C# runtime
that computes from it the same EPOF and opacity as ``vimsim epof``, the HLSL overlay that draws
the same grains and vignette as ``vimsim render``, a prefab, an importer and manifests.

:func:`export_unity` plans (checks, data, header, files), writes (every file complete before
any is renamed) and summarises; :mod:`.binary` is the file format, :mod:`.header` the header,
:mod:`.assets` the package files (``docs/unity.md``).
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output, check_output_dir
from simulator.epof.overlaps import viewport_fov
from simulator.epof.parts import has_parts, rotation_share
from simulator.export.unity.assets import (
    ASSET_FILES,
    CS_FILES,
    asset_bytes,
    is_ours,
    meta_files,
)
from simulator.export.unity.binary import (
    DATA_FILE,
    FORMAT,
    FRAME_EPS,
    ROT_FILE,
    VERSION,
    covers,
    frame_at,
    pack,
    read_export,
    read_grain_layout,
)
from simulator.export.unity.header import build_header
from simulator.media.gridfile import GridFile, load_grid, require_field
from simulator.media.lazyfield import take_rows
from simulator.mitigation.grf import GrainField, GrfConfig, OpacityRule, grain_count
from simulator.mitigation.kinds import Mitigation

__all__ = [
    "ASSET_FILES",
    "CS_FILES",
    "DATA_FILE",
    "DTYPES",
    "FORMAT",
    "FRAME_EPS",
    "MAX_GRAINS",
    "METHODS",
    "ROT_FILE",
    "VERSION",
    "ExportResult",
    "covers",
    "export_unity",
    "frame_at",
    "read_export",
    "read_grain_layout",
]

DTYPES: tuple[str, ...] = ("auto", "float16", "float32")
METHODS: tuple[str, ...] = ("auto", "paper", "sphere")
#: Most grains an export carries (12 bytes each in the file; the runtime builds a mask from them).
MAX_GRAINS = 2_000_000
_FLOAT16_MAX = 65504.0


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export_unity` wrote.

    ``files``: paths written (the data first, then the package files, then ``.meta`` files);
    ``mode``: ``paper`` or ``sphere``; ``dtype`` and ``shape`` of the data; ``file_bytes``:
    size of ``vimsim_epof.bin``; ``grid_bytes``: size of the grid file; ``max_rel_error``:
    largest relative rounding of a data value against the values ``vimsim epof`` uses (0.0
    when stored exactly; at most 2^-11 for float16); ``n_grains``: grains in the layout.
    """

    out_dir: Path
    files: tuple[Path, ...]
    mode: str
    dtype: str
    shape: tuple[int, int, int]
    file_bytes: int
    grid_bytes: int
    max_rel_error: float
    header: dict
    n_grains: int = 0


@dataclass(frozen=True)
class _Plan:
    out: Path
    files: tuple[tuple[Path, bytes], ...]
    header: dict
    data: np.ndarray
    max_rel: float
    grid_bytes: int
    n_grains: int


def _check_options(g: GridFile, method, dtype, rule: OpacityRule, cache_bins, grf: GrfConfig) -> int:
    """InputError for options no export can have; returns the grain count."""
    if method not in METHODS:
        raise InputError(f"export method must be one of {', '.join(METHODS)}; got {method!r}")
    if dtype not in DTYPES:
        raise InputError(f"export dtype must be one of {', '.join(DTYPES)}; got {dtype!r}")
    if rule.source != "grid":
        raise InputError(
            "export: opacity thresholds come from the grid's flow (the paper's whole video); "
            "the 'viewing' source needs the whole viewing and cannot be exported"
        )
    if not (1 <= int(cache_bins) <= 1_000_000):
        raise InputError(f"cache_bins must be 1..1000000; got {cache_bins}")
    n = grain_count(grf)
    if n > MAX_GRAINS:
        raise InputError(
            f"--grain-size {grf.grain_deg:g} with --density {grf.density:g} needs {n} grains "
            f"(at most {MAX_GRAINS} in an export); choose a larger --grain-size, e.g. 0.5"
        )
    return n


def _flow_data(g: GridFile, sphere: bool, dtype: str):
    """``(data in its output dtype, dtype name, max relative rounding, cells or None)``."""
    src = g.path or "grid"
    cells = None
    if sphere:
        field, cells = require_field(g)
        values = np.asarray(field, np.float32)  # float32, what vimsim epof integrates
        default = "float16" if np.dtype(g.field_dps.dtype) == np.float16 else "float32"
    else:
        values = np.asarray(g.pof_dps, np.float32)
        default = "float32"
    out_dtype = default if dtype == "auto" else dtype
    peak = float(np.max(np.abs(values)))
    if out_dtype == "float16" and peak > _FLOAT16_MAX:
        raise InputError(
            f"{src}: flow up to {peak:.6g} deg/s exceeds float16's range ({_FLOAT16_MAX:g}); "
            "export with --dtype float32"
        )
    data = np.ascontiguousarray(values.astype("<f2" if out_dtype == "float16" else "<f4"))
    back, ref = data.astype(np.float64), np.asarray(values, np.float64)
    nz = ref != 0
    max_rel = float(np.max(np.abs(back[nz] - ref[nz]) / np.abs(ref[nz]))) if nz.any() else 0.0
    return data, out_dtype, max_rel, cells


def _rot_blob(g: GridFile, header: dict, dtype, grains) -> bytes:
    """:data:`ROT_FILE`: the export of the field's rotational part (same header, plus
    ``part``): the same runtime loading it computes ``epof_rot_dps``."""
    field, cells = require_field(g)
    f = np.asarray(field, np.float32)
    n = len(f)  # the rows exported (a caller may pass a grid of its first rows)
    om = np.asarray(g.extras["ego_omega_dps"][:n], np.float64)
    trans = np.asarray(take_rows(g.field_trans_dps, np.arange(n)), np.float32)
    rot = f * rotation_share(f, trans, om, cells)
    h = {**header, "data": dict(header["data"])}
    h["part"] = "rot: the field's rotational part (simulator.epof.parts); EPOF of it = epof_rot_dps"
    return pack(h, np.ascontiguousarray(rot.astype(dtype)), grains)


def _targets(g: GridFile, out_dir, rot: bool = False) -> tuple[Path, list[Path]]:
    """The output folder and every file to write, refused (InputError) before anything is
    written when one is the grid, a folder, or a file vimsim did not write."""
    out = Path(out_dir)
    grid_path = Path(g.path).resolve() if g.path else None
    if grid_path is not None and out.resolve() == grid_path:
        raise InputError(f"{out}: output folder is the input grid file; choose another -o")
    out = check_output_dir(out)
    rels = [DATA_FILE, *ASSET_FILES, *meta_files(), *([ROT_FILE] if rot else [])]
    targets = [out / r for r in rels]
    for t in targets:
        if grid_path is not None and t.resolve() == grid_path:
            raise InputError(f"{t}: output would replace the input grid file; choose another -o")
        if t.is_dir():
            raise InputError(f"{t}: is a folder; expected the export's file name to be free")
        if t.exists() and not is_ours(t):
            raise InputError(f"{t}: exists and was not written by vimsim export; move it or choose another -o")
    return out, targets


def _plan(g, out_dir, *, method, dtype, fov, rule, cache_bins, grf, mitigation,
          preset=None) -> _Plan:  # fmt: skip
    """Everything to write, checked; nothing written yet."""
    n_grains = _check_options(g, method, dtype, rule, cache_bins, grf)
    sphere = method == "sphere" or (method == "auto" and g.field_dps is not None)
    h, v = viewport_fov(g, *fov)
    data, out_dtype, max_rel, cells = _flow_data(g, sphere, dtype)
    header = build_header(
        g, data, sphere=sphere, dtype=out_dtype, fov=(h, v), rule=rule,
        thresholds=rule.fit(g, None), grf=grf, mitigation=mitigation, n_grains=n_grains,
        cache_bins=cache_bins, cells=cells,
    )  # fmt: skip
    if preset:  # the system preset the package carries (docs/parity.md)
        header["preset"] = dict(preset)
    grains = GrainField.from_config(grf).centers.astype(np.float32)
    blob = pack(header, data, grains)
    rot = sphere and has_parts(g)
    out, targets = _targets(g, out_dir, rot)
    metas = meta_files()
    contents = [blob, *(asset_bytes(r) for r in ASSET_FILES), *metas.values()]
    if rot:
        contents.append(_rot_blob(g, header, data.dtype, grains))
    (out / "Editor").mkdir(exist_ok=True)
    size = Path(g.path).stat().st_size if g.path and Path(g.path).is_file() else 0
    return _Plan(out, tuple(zip(targets, contents)), header, data, max_rel, size, n_grains)


def _write(plan: _Plan) -> None:
    """Every file complete under a temporary name before any is renamed."""
    with contextlib.ExitStack() as stack:
        for t, c in plan.files:
            tmp = stack.enter_context(atomic_output(t))
            Path(tmp).write_bytes(c)


def export_unity(
    grid: GridFile | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    method: str = "auto",
    dtype: str = "auto",
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    rule: OpacityRule | None = None,
    cache_bins: int = 1024,
    grf: GrfConfig | None = None,
    mitigation: Mitigation | None = None,
    preset: dict | None = None,
) -> ExportResult:
    """Write ``out_dir/vimsim_epof.bin`` and the Unity package (:data:`ASSET_FILES`) for a grid.

    Parameters
    ----------
    grid : GridFile or path of a grid file (``vimsim preprocess``)
    out_dir : folder, created if needed; files vimsim did not write there are never replaced
    method : ``"paper"`` (window POFs, overlap weights), ``"sphere"`` (the field, exact
        integration; InputError if the grid has none) or ``"auto"``: sphere when the grid has
        a field, as ``vimsim epof``
    dtype : ``"float16"``, ``"float32"`` or ``"auto"`` (the precision ``vimsim epof`` uses:
        float32 for the POF matrix, the stored dtype of a field)
    hfov_deg, vfov_deg : float, degrees; viewport FOV, default the grid's window FOV
    rule : OpacityRule (default ``OpacityRule()``, the paper's 10th/90th percentiles, no
        easing; the CLI's default is :func:`simulator.mitigation.grf.comfort_rule`, as ``vimsim epof``);
        its thresholds are taken from the grid's flow (``source="grid"``); its smoothing and
        ease-in / ease-out times go into the header for the runtime's ``OpacityEasing``
    cache_bins : sphere mode: weight bins the runtime keeps (~16 kB each for 4 deg cells)
    grf : the grains (default ``GrfConfig()``, the paper's): layout and settings go into the
        file, so that the overlay draws the grains ``vimsim render`` draws (at infinity)
    mitigation : what the overlay draws and the vignette's settings (default ``grf``)
    preset : the header's ``preset`` section (``name`` and, for ``cao2021-code``, where the
        package's nearest-window rule and its data are), or None: none

    Returns
    -------
    ExportResult
    """
    g = grid if isinstance(grid, GridFile) else load_grid(grid)
    plan = _plan(
        g, out_dir, method=method, dtype=dtype, fov=(hfov_deg, vfov_deg),
        rule=OpacityRule() if rule is None else rule, cache_bins=cache_bins,
        grf=GrfConfig() if grf is None else grf,
        mitigation=Mitigation() if mitigation is None else mitigation, preset=preset,
    )  # fmt: skip
    _write(plan)
    return ExportResult(
        out_dir=plan.out,
        files=tuple(t for t, _ in plan.files),
        mode=plan.header["mode"],
        dtype=plan.header["data"]["dtype"],
        shape=tuple(int(s) for s in plan.data.shape),
        file_bytes=len(plan.files[0][1]),
        grid_bytes=plan.grid_bytes,
        max_rel_error=plan.max_rel,
        header=plan.header,
        n_grains=plan.n_grains,
    )
