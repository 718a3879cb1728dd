"""Validation of a grid file's contents: array headers before reading, meta types and ranges, field values, the camera-rotation arrays.

Each check raises InputError (one line naming the file ``p`` and the first problem);
:func:`simulator.media.gridfile.load_grid` calls them in that order.
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from simulator.core.errors import InputError
from simulator.media.lazyfield import LazyField

__all__ = ["EGO_ARRAYS", "check_ego", "check_headers", "check_meta", "check_values", "is_num"]

def check_headers(p: Path, need: set[str]) -> None:
    """InputError before reading if an array header of the .npz claims more data than its
    member holds (a header claiming terabytes), or names an object dtype."""
    try:
        with zipfile.ZipFile(p) as zf:
            for info in zf.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                name = info.filename[:-4]
                with zf.open(info) as fh:
                    version = np.lib.format.read_magic(fh)
                    if version == (1, 0):
                        shape, _fortran, dtype = np.lib.format.read_array_header_1_0(fh)
                    else:
                        shape, _fortran, dtype = np.lib.format.read_array_header_2_0(fh)
                if dtype.hasobject:
                    raise InputError(
                        f"{p}: array {name} holds Python objects; not a vimsim grid file"
                    )
                nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
                if nbytes > info.file_size + 4096:
                    raise InputError(
                        f"{p}: array {name} header claims {nbytes} bytes but the file holds "
                        f"{info.file_size}; corrupt grid file"
                    )
    except InputError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError) as e:
        raise InputError(
            f"{p}: not a vimsim grid file (.npz expected): {type(e).__name__}"
        ) from None


def is_num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)


def check_meta(p: Path, meta: dict) -> None:
    """InputError naming the first meta field of the wrong type or out of range."""
    if not is_num(meta["fps"]) or not meta["fps"] > 0:
        raise InputError(f"{p}: grid meta fps must be a number > 0; got {str(meta['fps'])[:20]!r}")
    if (
        not isinstance(meta["n_frames"], int)
        or isinstance(meta["n_frames"], bool)
        or meta["n_frames"] < 1
    ):
        raise InputError(f"{p}: grid meta n_frames must be an integer >= 1")
    for k in ("grid", "video", "flow"):
        if not isinstance(meta[k], dict):
            raise InputError(f"{p}: grid meta {k} must be an object; got {type(meta[k]).__name__}")
    for k in ("layout", "eye"):
        if not isinstance(meta[k], str):
            raise InputError(f"{p}: grid meta {k} must be a string")
    v = meta["video"]
    for k in ("width", "height"):
        if k in v and not (isinstance(v[k], int) and not isinstance(v[k], bool) and v[k] > 0):
            raise InputError(f"{p}: grid meta video.{k} must be an integer > 0")
    if "n_frames" in v and not (isinstance(v["n_frames"], int) and v["n_frames"] >= 0):
        raise InputError(f"{p}: grid meta video.n_frames must be an integer >= 0")
    if "path" in v and not isinstance(v["path"], str):
        raise InputError(f"{p}: grid meta video.path must be a string")
    sf = meta.get("start_frame", 0)
    if sf is not None and not (isinstance(sf, int) and not isinstance(sf, bool) and sf >= 0):
        raise InputError(f"{p}: grid meta start_frame must be an integer >= 0")
    if "field" in meta:
        fm = meta["field"]
        if not isinstance(fm, dict) or not is_num(fm.get("cell_deg")) or not fm["cell_deg"] > 0:
            raise InputError(f"{p}: grid meta field.cell_deg must be a number > 0")


#: The per-frame camera-rotation arrays and their shapes after T.
EGO_ARRAYS = {"ego_omega_dps": (3,), "ego_confidence": ()}


def check_values(p, name: str, field) -> None:
    """InputError unless a field (lazy or in memory) is finite and >= 0."""
    if isinstance(field, LazyField):
        finite, lo = field.scan()
    else:
        a = np.asarray(field)
        finite = bool(np.isfinite(a).all())
        lo = float(a.min()) if a.size else 0.0
    if not finite or lo < 0:
        raise InputError(f"{p}: {name} must be (T, n_lat, n_lon), finite and >= 0")


def check_ego(p: Path, arrs: dict, T: int, scan: bool = True) -> dict:
    """The per-frame camera-rotation arrays of a grid (all or none), checked."""
    have = [k for k in (*EGO_ARRAYS, "field_trans_dps") if k in arrs]
    if not have:
        return {}
    if len(have) != len(EGO_ARRAYS) + 1 or "field_dps" not in arrs:
        raise InputError(
            f"{p}: grid has {have} but not all of ego_omega_dps, ego_confidence, "
            "field_trans_dps and field_dps; corrupt grid file: re-run vimsim preprocess"
        )
    out = {}
    for k, tail in EGO_ARRAYS.items():
        a = arrs[k]
        if a.dtype.kind != "f" or a.shape != (T, *tail) or not np.all(np.isfinite(a)):
            raise InputError(f"{p}: {k} must be finite floats of shape {(T, *tail)}")
        out[k] = a.astype(np.float32, copy=False)
    ft, f = arrs["field_trans_dps"], arrs["field_dps"]
    if ft.shape != f.shape:
        raise InputError(f"{p}: field_trans_dps must match field_dps, finite and >= 0")
    if scan:
        check_values(p, "field_trans_dps", ft)
    return out
