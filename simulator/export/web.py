"""The web export: the EPOF data, overlap table and grain layout with an ES-module runtime (``vimsim.js``) for web players.

``vimsim export GRID.npz -o DIR --format web`` writes, beside each other:

==========================  ==============================================================
``vimsim_web.json``         what the runtime loads first: file names, table shape and axes,
                            the grain parameters (``"format": "vimsim-web"``)
``vimsim_epof.bin``         the Unity export's binary, byte for byte (format 5,
                            :mod:`simulator.export.unity.binary`): the flow, the grain
                            layout, the GRF and vignette settings, the source's length and
                            the exported range
``vimsim_overlaps.bin``     paper mode only: ``VIMSIMOV`` + 8 zero bytes, then the overlap
                            table of :class:`simulator.epof.overlaps.ViewportOverlaps`
                            (float32 little-endian, shape in the JSON), the numbers ``vimsim
                            epof`` interpolates
``vimsim.js``               the runtime (load, EPOF at any pose and time, NaN outside the
                            exported range, opacity rule with easing, the grain layout)
``vimsim_grains.js``        the grain layout: read from the file, or drawn from the seed
                            (numpy's PCG64 ported), and its coverage mask
``vimsim_gl.js``            the WebGL2 eye renderer and overlay shader (video on the sphere,
                            grains, cutout, vignette) as vimsim's renderer draws them
``example.html``            a minimal page: drag to look around, live EPOF and opacity
==========================  ==============================================================

``docs/web.md`` shows the calls and how to use them with three.js or A-Frame.
"""

from __future__ import annotations

import dataclasses
import importlib.resources
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.core.fileio import OutputFolder, atomic_output, json_text
from simulator.epof.overlaps import viewport_overlaps
from simulator.export.unity import DATA_FILE, VERSION, export_unity, read_grain_layout
from simulator.export.unity.binary import grain_layout_bytes, pack_head
from simulator.export.unity.header import set_data_shape
from simulator.media.gridfile import GridFile, load_grid
from simulator.media.lazyfield import field_chunks, take_rows
from simulator.mitigation.grf import GrfConfig, OpacityRule
from simulator.mitigation.kinds import Mitigation
from simulator.sphere.windows import WindowGrid

__all__ = ["JS_FILES", "MANIFEST_VERSION", "WEB_FILES", "WebExport", "export_web", "js_source"]

MANIFEST = "vimsim_web.json"
#: 2: the grain layout and the mitigation's settings are read from ``vimsim_epof.bin``
#: (format 3 on); 1 had a ``vimsim_grains.bin`` beside a format-2 binary.
MANIFEST_VERSION = 2
OVERLAPS = "vimsim_overlaps.bin"
#: The runtime files shipped in ``simulator/export/web/``.
JS_FILES: tuple[str, ...] = ("vimsim.js", "vimsim_grains.js", "vimsim_gl.js")
EXAMPLE = "example.html"
WEB_FILES: tuple[str, ...] = (MANIFEST, DATA_FILE, OVERLAPS, *JS_FILES, EXAMPLE)


@dataclass(frozen=True)
class WebExport:
    """What :func:`export_web` wrote: the folder, the files, the mode and the manifest."""

    out_dir: Path
    files: tuple[Path, ...]
    mode: str
    manifest: dict
    header: dict


def js_source(name: str) -> bytes:
    """A file of the web runtime (``simulator/export/web/NAME``)."""
    return importlib.resources.files("simulator.export").joinpath("web", name).read_bytes()


def overlap_bytes(grid: GridFile, hfov_deg: float, vfov_deg: float) -> tuple[bytes, dict]:
    """``vimsim_overlaps.bin`` and its JSON description: the overlap table ``vimsim epof``
    interpolates for this grid and viewport FOV (degrees)."""
    ov = viewport_overlaps(WindowGrid.from_dict(dict(grid.meta["grid"])), hfov_deg, vfov_deg)
    info = {
        "file": OVERLAPS,
        "shape": [int(s) for s in ov.table.shape],
        "pitch_grid": [float(x) for x in ov.pitch_grid],
        "roll_grid": [float(x) for x in ov.roll_grid],
        "n_u": int(ov.n_u),
        "step_deg": float(ov.step),
        "yaw_start_deg": float(ov.yaw_start),
        "centres": [float(x) for x in np.asarray(ov._centres, np.float64).ravel()],
        "layout": "float32 [pitch][roll][yaw offset][window row][m] after 16 bytes",
    }
    raw = np.ascontiguousarray(ov.table, "<f4").tobytes()
    return b"VIMSIMOV" + bytes(8) + raw, info


def _float16_field(g: GridFile) -> bool:
    """The grid holds a float16 field (``vimsim preprocess``'s default): stored values, exact."""
    return g.field_dps is not None and np.dtype(g.field_dps.dtype) == np.float16


def write_epof(g: GridFile, target: Path, **kw) -> dict:
    """Write ``vimsim_epof.bin`` to ``target`` as :func:`export_unity` writes it (format 5,
    byte for byte); returns its header. ``kw``: export_unity's options.

    A float16 field exported as float16 (sphere mode, ``dtype`` auto or float16) is streamed
    from the grid file chunk by chunk (memory flat in the video's length): the header is
    made by :func:`export_unity` from the field's first two rows and given the whole field's
    shape, source length and range (:func:`~simulator.export.unity.header.set_data_shape`);
    the grain layout follows the data as in :func:`~simulator.export.unity.binary.pack`
    (the Unity path holds the whole field as float32, twice, to measure a rounding that is
    zero here)."""
    method = kw.get("method", "auto")
    sphere = method == "sphere" or (method == "auto" and g.field_dps is not None)
    with tempfile.TemporaryDirectory(prefix="vimsim-web-") as tmp:
        if not (sphere and _float16_field(g) and kw.get("dtype", "auto") in ("auto", "float16")):
            res = export_unity(g, tmp, **kw)
            shutil.copyfile(Path(tmp) / DATA_FILE, target)
            return res.header
        first = np.asarray(take_rows(g.field_dps, [0, min(1, g.n_frames - 1)]), np.float16)
        res = export_unity(dataclasses.replace(g, field_dps=first), tmp, **kw)
        grains = read_grain_layout(tmp)
    header = res.header
    if header["mode"] != "sphere" or header["data"]["dtype"] != "float16":
        raise AssertionError("export: the float16 field's header is not a float16 sphere export")
    set_data_shape(header, g, g.field_dps.shape)
    head, pad = pack_head(header, int(header["data"]["bytes"]))
    with open(target, "wb") as f:
        f.write(head)
        f.writelines(
            np.ascontiguousarray(block, "<f2").tobytes() for _, block in field_chunks(g.field_dps)
        )
        f.write(pad + grain_layout_bytes(grains))
    return header


def export_web(
    grid: GridFile | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    method: str = "auto",
    dtype: str = "auto",
    hfov_deg: float | None = None,
    vfov_deg: float | None = None,
    rule: OpacityRule | None = None,
    grf: GrfConfig | None = None,
    mitigation: Mitigation | None = None,
    example: bool = True,
    preset: dict | None = None,
) -> WebExport:
    """Write the web runtime for a grid into ``out_dir`` (see the module docstring).

    ``method``, ``dtype``, ``hfov_deg``, ``vfov_deg``, ``rule``, ``grf`` (the grains: default
    ``GrfConfig()``, the paper's), ``mitigation`` (what the overlay draws and the vignette's
    settings: default ``grf``), ``preset``: as :func:`simulator.export.unity.export_unity`, whose
    ``vimsim_epof.bin`` this writes; ``example``: write ``example.html``. Files of these
    names that an earlier web export did not write are refused (InputError, nothing written).
    """
    g = grid if isinstance(grid, GridFile) else load_grid(grid)
    names = [MANIFEST, DATA_FILE, *JS_FILES] + ([EXAMPLE] if example else [])
    inputs = [g.path] if g.path else []
    OutputFolder(out_dir, names, "export --format web").check(inputs)
    kw = {"method": method, "dtype": dtype, "hfov_deg": hfov_deg, "vfov_deg": vfov_deg,
          "rule": rule, "grf": grf, "mitigation": mitigation, "preset": preset}  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="vimsim-web-") as work:
        data_tmp = Path(work) / DATA_FILE  # bad options fail here, before anything is written
        try:
            header = write_epof(g, data_tmp, **kw)
        except OSError as e:  # a full disk: named as the output file, not the temporary one
            raise OSError(e.errno, e.strerror or str(e), str(Path(out_dir) / DATA_FILE)) from None
        contents: dict[str, bytes] = {}
        manifest = {"format": "vimsim-web", "version": MANIFEST_VERSION, "data": DATA_FILE,
                    "data_version": VERSION, "mode": header["mode"],
                    "grains": "in the data file: header grf, section grains"}  # fmt: skip
        if header["mode"] == "paper":
            vp = header["viewport"]
            contents[OVERLAPS], manifest["overlaps"] = overlap_bytes(
                g, vp["hfov_deg"], vp["vfov_deg"]
            )
            names.insert(2, OVERLAPS)
        folder = OutputFolder(out_dir, names, "export --format web")
        folder.check(inputs)
        contents[MANIFEST] = (json_text(manifest) + "\n").encode()
        for n in JS_FILES:
            contents[n] = js_source(n)
        if example:
            contents[EXAMPLE] = js_source(EXAMPLE)
        out = folder.prepare(inputs)
        for name in names:
            with atomic_output(out / name) as t:
                if name == DATA_FILE:
                    shutil.move(data_tmp, t)
                else:
                    Path(t).write_bytes(contents[name])
        folder.complete()
    return WebExport(out, tuple(out / n for n in names), header["mode"], manifest, header)


def read_manifest(path: str | os.PathLike) -> dict:
    """``vimsim_web.json`` of an export folder; InputError when it is not one."""
    p = Path(path)
    p = p / MANIFEST if p.is_dir() else p
    try:
        m = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as e:
        raise InputError(f"{p}: not a vimsim web export ({e.__class__.__name__})") from None
    if not isinstance(m, dict) or m.get("format") != "vimsim-web":
        raise InputError(f"{p}: not a vimsim web export")
    if m.get("version") != MANIFEST_VERSION:
        raise InputError(
            f"{p}: web export version {m.get('version')} (this vimsim reads {MANIFEST_VERSION}); "
            "export again with vimsim export --format web"
        )
    return m
