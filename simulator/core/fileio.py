"""Small file helpers shared by every writer: atomic output and input checks.

Outputs are written to a temporary name beside the target and renamed into place only
when complete, so an interrupted run never leaves a file that looks finished.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import re
from collections.abc import Iterable, Iterator
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.lifeline import exit_if_orphaned

__all__ = [
    "OutputFolder",
    "PendingOutput",
    "atomic_output",
    "before_output",
    "check_input_file",
    "check_not_input",
    "check_output_dir",
    "check_output_file",
    "csv_cell",
    "csv_row",
    "csv_text",
    "csv_uncell",
    "input_scope",
    "json_text",
    "json_value",
    "known_inputs",
    "register_input",
    "remove_stale_temporaries",
    "write_csv",
]

#: Every file read through :func:`check_input_file` inside :func:`input_scope` (the CLI
#: opens one per command; resolved paths): an output that is the same file as one of
#: them is refused (never destroy an input). Empty and unused outside a scope.
_INPUTS: set[Path] = set()
#: The same inputs by ``(st_dev, st_ino)`` (those that existed when read): one lookup per
#: output, not one ``samefile`` per input (a study reads thousands of files).
_INPUT_IDS: dict[tuple[int, int], Path] = {}
_SCOPES: list[tuple[set[Path], dict]] = []

#: The temporary-name pattern of :func:`atomic_output`: ``.<stem>.tmp-<pid><suffix>``.
_TMP_RE = re.compile(r"^\.(?P<stem>.*)\.tmp-(?P<pid>\d+)(?P<suffix>(\.[^.]*)?)$")

#: Callbacks run once before the first output of a run is created (:func:`before_output`).
_BEFORE_OUTPUT: list = []

#: The manifest a folder output keeps of the files it wrote (see :class:`OutputFolder`).
MANIFEST_NAME = ".vimsim-manifest.json"


@contextlib.contextmanager
def input_scope(inputs: Iterable[str | os.PathLike] = ()) -> Iterator[None]:
    """Within it, every file read through :func:`check_input_file` (and ``inputs``) is an
    input of one run, and :func:`atomic_output` refuses to write over any of them."""
    _SCOPES.append((set(_INPUTS), dict(_INPUT_IDS)))
    _INPUTS.clear()
    _INPUT_IDS.clear()
    try:
        for x in inputs:
            register_input(x)
        yield
    finally:
        paths, ids = _SCOPES.pop()
        _INPUTS.clear()
        _INPUTS.update(paths)
        _INPUT_IDS.clear()
        _INPUT_IDS.update(ids)


@contextlib.contextmanager
def before_output(callback) -> Iterator[None]:
    """Within it, ``callback()`` runs once, just before the first output file or folder is
    created (:class:`PendingOutput`, :func:`check_output_dir`): the moment a run's checks
    have passed (the CLI opens its ``--log`` file then). It may raise InputError to refuse."""
    _BEFORE_OUTPUT.append(callback)
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            _BEFORE_OUTPUT.remove(callback)


def _run_before_output() -> None:
    while _BEFORE_OUTPUT:
        _BEFORE_OUTPUT.pop()()


def register_input(path: str | os.PathLike) -> None:
    """Record ``path`` as an input of this run (inside :func:`input_scope` only)."""
    if _SCOPES:
        with contextlib.suppress(OSError):
            r = Path(path).resolve()
            _INPUTS.add(r)
            st = os.stat(r)
            _INPUT_IDS[(st.st_dev, st.st_ino)] = r


def known_inputs() -> list[Path]:
    """The inputs recorded so far (resolved paths)."""
    return sorted(_INPUTS)


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        try:
            return a.resolve() == b.resolve()
        except OSError:
            return False


def check_not_input(target: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> None:
    """InputError if ``target`` is the same file as an input (by ``os.path.samefile``, so
    symlinks, hard links and ``./`` spellings count; by resolved path where it does not
    exist yet). ``inputs`` adds to those recorded by :func:`register_input`."""
    t = Path(target)
    extra = (Path(x) for x in inputs if x is not None and str(x).strip())
    inp = _registered_input(t) or next((x for x in extra if _same_file(t, x)), None)
    if inp is not None:
        raise InputError(
            f"{target}: output is the same file as the input {inp}; "
            "refusing to overwrite an input (choose another output name)"
        )


def _registered_input(t: Path) -> Path | None:
    """The recorded input that ``t`` is (same inode, or same resolved path), or None."""
    if not _INPUTS:
        return None
    with contextlib.suppress(OSError):
        st = os.stat(t)
        hit = _INPUT_IDS.get((st.st_dev, st.st_ino))
        # confirmed on the input itself: an inode is reused once its file is deleted (a
        # temporary input gone, a new output given its number)
        if hit is not None and _same_file(t, hit):
            return hit
    try:
        r = t.resolve()
    except OSError:
        return None
    return r if r in _INPUTS else None


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return True
    return True


def remove_stale_temporaries(target: str | os.PathLike) -> list[Path]:
    """Remove temporary files of :func:`atomic_output` for ``target`` left by a process
    that is gone (e.g. after ``kill -9``); only names of that pattern whose pid is not
    running. Returns the paths removed."""
    t = Path(target)
    parent = t.parent if str(t.parent) else Path(".")
    removed = []
    prefix = f".{t.stem}.tmp-"
    try:  # names only, a cheap prefix test first: a folder of thousands of outputs
        names = [n for n in os.listdir(parent) if n.startswith(prefix)]
    except OSError:
        return removed
    for name in names:
        m = _TMP_RE.match(name)
        if not m or m["stem"] != t.stem or m["suffix"] != t.suffix:
            continue
        if _pid_alive(int(m["pid"])):
            continue
        e = parent / name
        with contextlib.suppress(OSError):
            e.unlink()
            removed.append(e)
    return removed


def check_output_file(path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """``path`` as a Path if a file can be written there, checked before any work:
    InputError for an empty name, a directory, a missing or read-only folder, or the
    same file as an input."""
    if str(path).strip() == "":
        raise InputError("output name is empty; give a file name, e.g. -o out.png")
    target = Path(path)
    if target.is_dir():
        raise InputError(f"{target}: output is a directory; expected a file name")
    parent = target.parent if str(target.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"{target}: output directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise InputError(f"{target}: output directory {parent} is not writable")
    check_not_input(target, inputs)
    return target


class PendingOutput:
    """One output file being written: checked, written to ``tmp``, then committed by rename.

    The one output-file helper every writer uses (:func:`atomic_output` for ``with``
    blocks, :class:`simulator.media.video.VideoWriter` for encoders). Construction refuses
    (InputError) an output that is the same file as an input of this run, a directory, a
    missing or read-only folder, and removes temporaries of the same target left by dead
    processes. The temporary name keeps the suffix (``.out.png`` ->
    ``.out.tmp-<pid>.png``) so libraries choosing a format from the extension still work.
    """

    def __init__(self, path: str | os.PathLike):
        exit_if_orphaned()  # a worker whose command is gone writes nothing
        self.target = check_output_file(path)
        _run_before_output()
        parent = self.target.parent if str(self.target.parent) else Path(".")
        remove_stale_temporaries(self.target)
        self.tmp = parent / f".{self.target.stem}.tmp-{os.getpid()}{self.target.suffix}"

    def commit(self) -> Path:
        """Rename the finished temporary file into place (refused if the target became an
        input meanwhile); returns the target."""
        check_not_input(self.target)  # an input registered while writing
        exit_if_orphaned(cleanup=self.discard)
        os.replace(self.tmp, self.target)
        return self.target

    def discard(self) -> None:
        """Remove the temporary file (the target is left untouched)."""
        with contextlib.suppress(OSError):
            self.tmp.unlink()


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` on success.

    The temporary name keeps the suffix (``.out.png`` -> ``.out.tmp-<pid>.png``) so that
    libraries choosing a format from the extension (Pillow, matplotlib, PyAV) still work.
    On any exception (a signal too, which the CLI turns into one) the temporary file is
    removed and the target is left untouched. Refused (InputError) before anything is
    written: an output that is the same file as an input of this run, a directory, a
    missing or read-only folder. Temporaries of the same target left by dead processes
    are removed first. An OSError that names no file (a failed ``write()``: a full disk)
    is given the target's name, so its one-line message says which output failed.
    """
    out = PendingOutput(path)
    try:
        yield out.tmp
        out.commit()
    except BaseException as e:
        out.discard()
        if isinstance(e, OSError) and e.filename is None:
            e.filename = str(path)  # a failed write() (a full disk) names no file: the target
        raise


class OutputFolder:
    """A folder output (``render``, ``analyze``, ``demo``) that only touches its own files.

    ``names`` are the files the command writes. Opening it (:meth:`prepare`) refuses an
    input among them and a file of one of those names that no earlier run of the command
    wrote (no manifest lists it); it removes the files the earlier run listed (so an
    interrupted run never leaves old files beside new ones) and writes the manifest
    (state ``incomplete``) before any output. :meth:`complete` rewrites it as
    ``complete`` beside the completion marker, last.
    """

    def __init__(self, path: str | os.PathLike, names: Iterable[str], command: str):
        self.path = Path(path)
        self.names = list(dict.fromkeys(names))
        self.command = command

    def _manifest(self) -> dict:
        m = self.path / MANIFEST_NAME
        try:
            obj = json.loads(m.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError):
            return {}
        return obj if isinstance(obj, dict) else {}

    def check(self, inputs: Iterable[str | os.PathLike] = ()) -> set[str]:
        """The refusals of :meth:`prepare` without touching anything (call it before the
        work); returns the names an earlier run of this command wrote."""
        if str(self.path).strip() == "":
            raise InputError("output folder name is empty; give a folder, e.g. -o out")
        out = self.path
        if out.exists() and not out.is_dir():
            raise InputError(f"{out}: output folder is an existing file; expected a folder")
        check_not_input(out / MANIFEST_NAME, inputs)
        prev = self._manifest()
        mine = prev.get("files", []) if prev.get("command") == self.command else []
        mine = {str(n) for n in mine if isinstance(n, str)}
        for name in self.names:
            f = out / name
            check_not_input(f, inputs)
            if (f.exists() or f.is_symlink()) and name not in mine:
                raise InputError(
                    f"{f}: exists and was not written by vimsim {self.command}; "
                    "refusing to replace it (move it or choose another output folder)"
                )
        return mine

    def prepare(self, inputs: Iterable[str | os.PathLike] = ()) -> Path:
        """Check (:meth:`check`) and clear the folder; returns it (created)."""
        mine = self.check(inputs)
        out = check_output_dir(self.path)
        for name in sorted(mine):
            if "/" in name or name.startswith("."):
                continue
            remove_stale_temporaries(out / name)
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
        self._write(state="incomplete", files=sorted(mine | set(self.names)))
        return out

    def _write(self, *, state: str, files: list[str]) -> None:
        with atomic_output(self.path / MANIFEST_NAME) as tmp:
            tmp.write_text(
                json_text({"command": self.command, "state": state, "files": files}) + "\n",
                encoding="utf-8",
            )

    def complete(self, written: Iterable[str] | None = None) -> None:
        """Record the files written (default: every name) as a complete run."""
        files = self.names if written is None else list(written)
        self._write(state="complete", files=sorted(set(files)))


def check_input_file(path: str | os.PathLike, what: str = "input") -> Path:
    """Return ``path`` as a Path if it is a readable regular file, else raise InputError."""
    if str(path).strip() == "":
        raise InputError(f"{what} file name is empty")
    p = Path(path)
    if not p.exists():
        raise InputError(f"{p}: {what} file not found")
    if not p.is_file():
        raise InputError(f"{p}: {what} is not a regular file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{p}: {what} file is not readable")
    if p.stat().st_size == 0:
        raise InputError(f"{p}: {what} file is empty")
    register_input(p)
    return p


def check_output_dir(path: str | os.PathLike) -> Path:
    """Create ``path`` (a directory for outputs) if needed; InputError if impossible."""
    if str(path).strip() == "":
        raise InputError("output folder name is empty; give a folder, e.g. -o out")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{p}: output folder is an existing file; expected a folder")
    _run_before_output()
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InputError(f"{p}: cannot create output directory ({e.strerror})") from None
    if not os.access(p, os.W_OK):
        raise InputError(f"{p}: output directory is not writable")
    return p


def csv_cell(value: str) -> str:
    """A text cell for a CSV output that a spreadsheet will not run as a formula: one
    beginning with ``=``, ``+``, ``@``, a tab or carriage return, or ``-`` not followed by
    a digit (``-3`` stays a number) gets a leading ``'`` (OWASP's CSV-injection advice)."""
    s = str(value)
    if s and (
        s[0] in "=+@\t\r" or (s[0] == "-" and not (len(s) > 1 and (s[1].isdigit() or s[1] == ".")))
    ):
        return "'" + s
    return s


def csv_row(line: str, where: str | os.PathLike) -> list[str]:
    """The fields of one CSV line; a line the csv module refuses (a field over its 128 KiB
    limit, a NUL) is an InputError naming ``where`` (bad input, not an internal error)."""
    try:
        return next(csv.reader([line]), [])
    except csv.Error as e:
        raise InputError(f"{where}: not a readable CSV line ({e})") from None


def csv_uncell(value: str) -> str:
    """The text :func:`csv_cell` guarded, as it was (for vimsim reading its own CSVs)."""
    s = str(value)
    return s[1:] if s[:1] == "'" and csv_cell(s[1:]) == s else s


def _csv_number(v) -> str:
    """A non-text cell: empty for None and non-finite floats, 10 significant digits."""
    if v is None:
        return ""
    if hasattr(v, "item") and not isinstance(v, (str, bytes)):  # a numpy scalar
        v = v.item()
    if isinstance(v, float):
        return f"{v + 0.0:.10g}" if math.isfinite(v) else ""
    return str(v)


def csv_text(header, rows, *, comments=(), fmt=None) -> str:
    """CSV text (``#`` comment lines, the header, the rows) as :func:`write_csv` writes it."""
    fmt = fmt or _csv_number
    buf = io.StringIO()
    for c in comments:
        buf.write(f"# {c}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([csv_cell(h) for h in header])
    for r in rows:
        w.writerow([csv_cell(v) if isinstance(v, str) else fmt(v) for v in r])
    return buf.getvalue()


def write_csv(path: str | os.PathLike, header, rows, *, comments=(), fmt=None) -> Path:
    """The one CSV writer of every table a command writes (``viewings.csv``, ``DATA.csv``,
    ``comparison.csv``, screen and study tables): atomic (:func:`atomic_output`), every
    text cell through :func:`csv_cell` (a participant ``=HYPERLINK(...)`` cannot run as a
    spreadsheet formula; ``-3.5`` stays a number), other cells through ``fmt`` (default: 10
    significant digits, empty for None and NaN)."""
    text = csv_text(header, rows, comments=comments, fmt=fmt)
    with atomic_output(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return Path(path)


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


_NO_DEFAULT = object()


def json_value(text: str, where: str | os.PathLike, *, default=_NO_DEFAULT):
    """``json.loads(text)`` (``default`` instead for text that is not JSON, if given); JSON
    nested too deeply to parse (``RecursionError``: e.g. 200,000 ``[``) is an InputError
    naming ``where`` (bad input, not an internal error)."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        if default is _NO_DEFAULT:
            raise
        return default
    except RecursionError:
        raise InputError(f"{where}: holds JSON nested too deeply to read") from None
