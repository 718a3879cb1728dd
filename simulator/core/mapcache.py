"""A user cache folder for derived arrays (remap maps) that are slow to build and cheap to load.

Where: ``$VIMSIM_CACHE_DIR`` if set (vimsim's one cache variable: the study's grids live
there too, under ``grids/``), else the deprecated ``$VIMSIM_CACHE``, else
``$XDG_CACHE_HOME/vimsim``, else ``~/.cache/vimsim``. An entry is one folder named by the SHA-256 of its key (a
JSON-serialisable dict naming everything the arrays depend on, with a format version)
holding ``key.json`` and one ``.npy`` per array (no pickles), loaded memory-mapped
(read-only; no copy, pages come from the OS cache). The key is checked on load, so a
hash collision or a foreign folder is never used. An entry is written as a temporary
folder beside it and renamed when complete: concurrent runs that build the same entry
each write their own temporary folder, the first rename wins and the others remove
theirs; a reader sees a whole entry or none. A missing, unreadable or mismatching entry
is rebuilt and replaces it (moved aside first, so runs using it keep their copy); a cache folder that cannot be written is reported through
:func:`warnings.warn` and the arrays are used uncached. Entries are never evicted: delete
the folder to reclaim the space.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import threading
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["DEPRECATED_ENV", "cache_dir", "cached_arrays", "deprecation_note"]

#: The study cache's old variable, read when ``VIMSIM_CACHE_DIR`` is not set.
DEPRECATED_ENV = "VIMSIM_CACHE"


def deprecation_note() -> str | None:
    """A line for the CLI when only the deprecated cache variable is set, else None."""
    if os.environ.get(DEPRECATED_ENV) and not os.environ.get("VIMSIM_CACHE_DIR"):
        return (f"note: {DEPRECATED_ENV} is deprecated; use VIMSIM_CACHE_DIR (the same "
                "folder, for every cache of vimsim)")  # fmt: skip
    return None

_FORMAT = "vimsim-map-cache-1"


def cache_dir() -> Path:
    """The cache folder (not created): ``$VIMSIM_CACHE_DIR``, the deprecated
    ``$VIMSIM_CACHE`` (:data:`DEPRECATED_ENV`), ``$XDG_CACHE_HOME/vimsim`` or
    ``~/.cache/vimsim``."""
    own = os.environ.get("VIMSIM_CACHE_DIR") or os.environ.get(DEPRECATED_ENV)
    if own:
        return Path(own).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "vimsim"


def _entry(key: dict) -> tuple[Path, str]:
    text = json.dumps({"format": _FORMAT, **key}, sort_keys=True)
    name = hashlib.sha256(text.encode()).hexdigest()[:32]
    return cache_dir() / f"{key.get('kind', 'arrays')}-{name}", text


def _load(path: Path, text: str) -> dict[str, NDArray] | None:
    try:
        if (path / "key.json").read_text() != text:
            return None
        names = sorted(p.stem for p in path.glob("*.npy"))
        return {n: np.load(path / f"{n}.npy", mmap_mode="r", allow_pickle=False) for n in names}
    except Exception:  # noqa: BLE001 - a missing or damaged entry is rebuilt, whatever the damage
        return None


def _store(path: Path, text: str, arrays: dict[str, NDArray]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.tmp-{os.getpid()}-{threading.get_ident()}"
    try:
        tmp.mkdir()
        for n, a in arrays.items():
            np.save(tmp / f"{n}.npy", np.ascontiguousarray(a), allow_pickle=False)
        (tmp / "key.json").write_text(text)
        try:
            os.rename(tmp, path)
        except OSError:
            if not path.is_dir():
                raise
            if _load(path, text) is not None:
                return  # another run stored the same entry first; theirs is identical
            # A damaged or foreign entry: move it aside (runs that mapped its files keep
            # them), put ours in its place.
            old = path.parent / f".{path.name}.old-{os.getpid()}-{threading.get_ident()}"
            os.rename(path, old)
            shutil.rmtree(old, ignore_errors=True)
            os.rename(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def cached_arrays(
    key: dict, build: Callable[[], dict[str, NDArray]], *, use_cache: bool = True
) -> tuple[dict[str, NDArray], str]:
    """The arrays of ``key`` from the cache, or ``build()`` them (and store them).

    Parameters
    ----------
    key : JSON-serialisable dict of everything the arrays depend on (``kind`` names the
        entry's folder prefix)
    build : makes the arrays, ``{name: ndarray}`` (numeric dtypes)
    use_cache : False: always build, neither read nor write the cache (``--no-cache``)

    Returns
    -------
    ``(arrays, how)`` with ``how`` one of ``"hit"`` (read-only memory maps), ``"built"``
    (and stored), ``"uncached"`` (``use_cache=False`` or the folder is not writable).
    """
    if not use_cache:
        return build(), "uncached"
    path, text = _entry(key)
    got = _load(path, text)
    if got is not None:
        return got, "hit"
    arrays = build()
    try:
        _store(path, text, arrays)
    except OSError as e:
        warnings.warn(
            f"map cache {path.parent} not writable ({e.strerror or e}); maps not cached "
            "(set VIMSIM_CACHE_DIR or pass --no-cache)",
            stacklevel=2,
        )
        return arrays, "uncached"
    return arrays, "built"
