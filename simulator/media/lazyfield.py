"""A grid file's sphere-mode field read lazily, chunk by chunk, from its ``.npz`` member (memory flat in video length).

:class:`LazyField` stands for the ``(T, n_lat, n_lon)`` array ``field_dps`` of a grid
file without holding it: rows are read (and, for a compressed member, decompressed) on
demand from the zip member, a chunk of rows at a time. Old and new grid files both work
(compressed or stored members; a forward read never restarts the member, a backward one
reopens it). :func:`field_chunks` walks a field (lazy or an ndarray) in chunks of rows;
:func:`take_rows` selects rows without reading them. ``np.asarray(lazy)`` reads all of it
(for callers that need the whole field at once, e.g. the engine export). :func:`spool`
keeps a float32 copy of a field in a raw file, read lazily too but without decompressing
(a process serving many viewings of one grid: a study worker).
"""

from __future__ import annotations

import hashlib
import math
import os
import zipfile
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from simulator.core.errors import InputError
from simulator.core.fileio import atomic_output

__all__ = ["CHUNK_BYTES", "LazyField", "field_chunks", "spool", "spool_name", "take_rows"]

#: Bytes of float32 rows read at a time (a chunk is at least one row).
CHUNK_BYTES = 2 << 20


class _Member:
    """One open ``.npy`` member of a zip: sequential reads of C-order rows."""

    def __init__(self, path: Path, name: str):
        self.path, self.name = path, name
        self._zf = self._fh = None
        self._pos = 0  # byte position in the data (after the .npy header)

    def _open(self) -> None:
        self.close()
        self._zf = zipfile.ZipFile(self.path)
        self._fh = self._zf.open(self.name)
        version = np.lib.format.read_magic(self._fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(self._fh)
        else:
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(self._fh)
        self.header = (tuple(shape), bool(fortran), dtype)
        self._data0 = self._fh.tell()
        self._pos = 0

    def header_info(self) -> tuple[tuple[int, ...], bool, np.dtype]:
        if self._fh is None:
            self._open()
        return self.header

    def read(self, start: int, nbytes: int) -> bytes:
        """``nbytes`` of the array data from byte ``start`` (short at the end of the member)."""
        if self._fh is None or start < self._pos:
            self._open()  # a compressed member cannot seek back: start it again
        if start > self._pos:
            self._fh.seek(self._data0 + start)
        b = self._fh.read(nbytes)
        self._pos = start + len(b)
        return b

    def close(self) -> None:
        for h in (self._fh, self._zf):
            if h is not None:
                h.close()
        self._zf = self._fh = None


class _RawFile:
    """A raw C-order array file (no header; shape and dtype known): reads at any offset
    (no decompression, no restart), the store of :func:`spool`."""

    def __init__(self, path: Path, shape: tuple[int, ...], dtype):
        self.path, self.header = Path(path), (tuple(shape), False, np.dtype(dtype))
        self._fd: int | None = os.open(self.path, os.O_RDONLY)

    def header_info(self) -> tuple[tuple[int, ...], bool, np.dtype]:
        return self.header

    def read(self, start: int, nbytes: int) -> bytes:
        parts = []
        while nbytes > 0:
            b = os.pread(self._fd, nbytes, start)
            if not b:
                break
            parts.append(b)
            start, nbytes = start + len(b), nbytes - len(b)
        return b"".join(parts)

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def spool_name(field: LazyField, what: str) -> str | None:
    """A file name for a spool of ``field`` (made ``what``-wise) that changes with the
    grid file it reads (path, size, time, inode, member; a spool's own name); None for a
    row selection."""
    if field._rows is not None:
        return None
    if isinstance(field._src, _RawFile):  # a spool: its name already says what it holds
        key = f"{field.path.name}:{what}"
    else:
        st = field.path.stat()
        key = f"{field.path.resolve()}:{st.st_size}:{st.st_mtime_ns}:{st.st_ino}:{field._src.name}:{what}"
    return hashlib.sha1(key.encode()).hexdigest()[:24] + f".{what}.f32"


def spool(field, path: str | Path, transform=None) -> LazyField:
    """A float32 copy of ``field`` (lazy or in memory) in a raw file at ``path``, made
    once (written to a temporary name, renamed when complete; an existing file of the
    right size is reused) and read lazily from then on: chunk reads without the
    decompression of a grid file's member, memory flat in the video's length.
    ``transform(i0, block) -> block`` changes each chunk of rows on the way (e.g. a
    field's rotational part); the caller names ``path`` after everything it depends on."""
    path = Path(path)
    shape = (len(field), *tuple(field.shape[1:]))
    if not (path.is_file() and path.stat().st_size == 4 * math.prod(shape)):
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path) as tmp, open(tmp, "wb") as f:
            for i0, c in field_chunks(field):
                c = c if transform is None else transform(i0, c)
                f.write(np.ascontiguousarray(c, np.float32).tobytes())
    return LazyField(path, _src=_RawFile(path, shape, np.float32))


class LazyField:
    """The ``(T, n_lat, n_lon)`` field of a grid file, read on demand.

    ``shape``, ``dtype`` (the stored one, float16 or float32, unless
    :meth:`with_dtype`), ``len()`` and ``field[t]`` (one row) behave as the array's; :meth:`chunks` yields
    float32 blocks of rows in order; :meth:`take` is a lazy row selection. The last
    chunk read is kept, so ``field[t]`` for ascending ``t`` reads each chunk once.
    """

    ndim = 3

    def __init__(self, path: str | Path, member: str = "field_dps.npy", *, _rows=None, _src=None):
        self.path = Path(path)
        self._src = _src or _Member(self.path, member)
        shape, fortran, dtype = self._src.header_info()
        if fortran or len(shape) != 3:
            raise InputError(
                f"{self.path}: field_dps must be a C-order (T, n_lat, n_lon) array; got shape {shape}"
            )
        self._base_shape = tuple(int(s) for s in shape)
        self._rows = None if _rows is None else np.asarray(_rows, np.intp)
        n = self._base_shape[0] if self._rows is None else len(self._rows)
        self.shape = (n, *self._base_shape[1:])
        self._stored = np.dtype(dtype)
        self.dtype = self._stored  # of what it returns (see with_dtype)
        self._row_bytes = int(np.prod(self._base_shape[1:])) * self._stored.itemsize
        self.chunk_rows = max(1, CHUNK_BYTES // max(1, int(np.prod(self.shape[1:])) * 4))
        self._cache: tuple[int, NDArray] | None = None

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"LazyField({str(self.path)!r}, shape={self.shape}, dtype={self.dtype})"

    # ---------------------------------------------------------------- reading
    def _base_block(self, r0: int, r1: int) -> NDArray:
        """Stored rows ``r0 <= r < r1`` of the member, the stored dtype."""
        b = self._src.read(r0 * self._row_bytes, (r1 - r0) * self._row_bytes)
        if len(b) != (r1 - r0) * self._row_bytes:
            raise InputError(f"{self.path}: field_dps is truncated (corrupt grid file)")
        a = np.frombuffer(b, self._stored).reshape(r1 - r0, *self._base_shape[1:])
        return a if self.dtype == self._stored else a.astype(self.dtype)

    def block(self, i0: int, i1: int) -> NDArray:
        """Rows ``i0 <= i < i1`` of this field (a new array of ``dtype``)."""
        i0, i1 = max(0, int(i0)), min(len(self), int(i1))
        if i1 <= i0:
            return np.empty((0, *self.shape[1:]), self.dtype)
        if self._rows is None:
            return self._base_block(i0, i1).copy()
        m = self._rows[i0:i1]
        lo, hi = int(m.min()), int(m.max()) + 1
        if hi - lo <= 2 * len(m) + 16:  # near-contiguous (the usual case): one read
            return self._base_block(lo, hi)[m - lo]
        out = np.empty((len(m), *self.shape[1:]), self.dtype)
        order = np.argsort(m, kind="stable")  # ascending: a compressed member reads forward
        for k in order:
            out[k] = self._base_block(int(m[k]), int(m[k]) + 1)[0]
        return out

    def chunks(self, rows: int | None = None):
        """``(i0, block)`` pairs in order: float32 blocks of at most ``rows`` rows."""
        n = int(rows or self.chunk_rows)
        for i0 in range(0, len(self), n):
            yield i0, self.block(i0, i0 + n).astype(np.float32, copy=False)

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            t = int(key)
            t = t + len(self) if t < 0 else t
            if not 0 <= t < len(self):
                raise IndexError(f"row {key} out of range for {len(self)} rows")
            c = t // self.chunk_rows
            if self._cache is None or self._cache[0] != c:
                self._cache = (c, self.block(c * self.chunk_rows, (c + 1) * self.chunk_rows))
            return self._cache[1][t - c * self.chunk_rows]
        if isinstance(key, slice):
            return (
                self.block(*key.indices(len(self))[:2])
                if key.step in (None, 1)
                else (self.take(np.arange(len(self))[key]).block(0, len(self)))
            )
        return self.take(key).block(0, len(np.asarray(key).reshape(-1)))

    def with_dtype(self, dtype) -> LazyField:
        """The same rows, returned as ``dtype`` (e.g. float32 of a float16 field)."""
        new = self._copy()
        new.dtype, new._cache = np.dtype(dtype), None
        return new

    def _copy(self) -> LazyField:
        new = LazyField.__new__(LazyField)
        new.__dict__.update(self.__dict__)
        return new

    def take(self, rows) -> LazyField:
        """The rows ``rows`` (indices into this field) as a new lazy field."""
        r = np.asarray(rows, np.intp).reshape(-1)
        if r.size and (r.min() < -len(self) or r.max() >= len(self)):
            raise IndexError(f"rows out of range for {len(self)} rows")
        r = np.where(r < 0, r + len(self), r)
        base = r if self._rows is None else self._rows[r]
        new = self._copy()
        new._rows, new._cache = base, None
        new.shape = (len(base), *self.shape[1:])
        return new

    def __array__(self, dtype=None, copy=None):
        a = self.block(0, len(self))
        return a if dtype is None else a.astype(dtype, copy=False)

    def scan(self) -> tuple[bool, float]:
        """``(all finite, minimum)`` over the whole field, chunk by chunk."""
        lo = np.inf
        for _, c in self.chunks():
            if not np.all(np.isfinite(c)):
                return False, float("nan")
            if c.size:
                lo = min(lo, float(c.min()))
        return True, lo

    def close(self) -> None:
        self._src.close()


def field_chunks(field, rows: int | None = None):
    """``(i0, block)`` pairs over a field's rows: a :class:`LazyField` chunk by chunk
    (float32 blocks), an ndarray as one block (as it is)."""
    if isinstance(field, LazyField):
        yield from field.chunks(rows)
    else:
        yield 0, np.asarray(field)


def take_rows(field, rows):
    """``field[rows]``: lazy for a :class:`LazyField`, an ndarray otherwise."""
    if isinstance(field, LazyField):
        return field.take(rows)
    return np.asarray(field)[np.asarray(rows, np.intp)]
