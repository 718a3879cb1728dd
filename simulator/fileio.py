"""Small file helpers shared by every writer: atomic output and input checks.

Outputs are written to a temporary name beside the target and renamed into place only
when complete, so an interrupted run never leaves a file that looks finished.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Iterator
from pathlib import Path

from simulator.errors import InputError

__all__ = ["atomic_output", "check_input_file", "check_output_dir", "json_text"]


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` on success.

    The temporary name keeps the suffix (``.out.png`` -> ``.out.tmp-<pid>.png``) so that
    libraries choosing a format from the extension (Pillow, matplotlib, PyAV) still work.
    On any exception the temporary file is removed and the target is left untouched.
    """
    target = Path(path)
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{target}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"{target}: output directory {parent} is not writable")
    tmp = parent / f".{target.stem}.tmp-{os.getpid()}{target.suffix}"
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def check_input_file(path: str | os.PathLike, what: str = "input") -> Path:
    """Return ``path`` as a Path if it is a readable regular file, else raise InputError."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: {what} file not found")
    if not p.is_file():
        raise InputError(f"{p}: {what} is not a regular file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{p}: {what} file is not readable")
    if p.stat().st_size == 0:
        raise InputError(f"{p}: {what} file is empty")
    return p


def check_output_dir(path: str | os.PathLike) -> Path:
    """Create ``path`` (a directory for outputs) if needed; InputError if impossible."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{p}: cannot create output directory ({e.strerror})") from None
    if not os.access(p, os.W_OK):
        raise InputError(f"{p}: output directory is not writable")
    return p


def _json_safe(x):
    """``x`` with NaN/inf floats as None and numpy scalars/arrays as Python values."""
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if hasattr(x, "tolist") and not isinstance(x, (str, bytes)):  # numpy scalar or array
        return _json_safe(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def json_text(obj, *, indent: int | None = 2) -> str:
    """Standard JSON for files users read with any tool: a non-finite number (``NaN``,
    ``Infinity``, which Python's ``json`` writes but JSON does not allow) becomes
    ``null``; numpy values become numbers or lists; anything else unknown becomes its
    ``str``."""
    return json.dumps(_json_safe(obj), indent=indent, allow_nan=False, default=str)
