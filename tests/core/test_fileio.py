"""The output-file helper (simulator/core/fileio.py) tested directly: a failed rewrite
leaves the old file byte-identical and no temporary, whatever fails (the writer, the
rename, a real full disk, a signal); folder manifests refuse files they did not write.

Writing in place instead of temporary-name-then-rename makes these tests fail (checked
by mutating ``atomic_output`` to yield the target itself)."""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from simulator.core.errors import InputError
from simulator.core.fileio import (
    MANIFEST_NAME,
    OutputFolder,
    PendingOutput,
    atomic_output,
    input_scope,
)

OLD = b"the previous complete output\n" * 10


def _listing(d: Path) -> list[str]:
    return sorted(p.name for p in d.iterdir())


@pytest.fixture
def old(tmp_path) -> Path:
    p = tmp_path / "out.csv"
    p.write_bytes(OLD)
    return p


def test_success_replaces_whole(old):
    with atomic_output(old) as tmp:
        assert tmp != old and tmp.parent == old.parent and tmp.suffix == ".csv"
        tmp.write_bytes(b"new\n")
        assert old.read_bytes() == OLD  # untouched until the rename
    assert old.read_bytes() == b"new\n" and _listing(old.parent) == ["out.csv"]


@pytest.mark.parametrize("exc", [RuntimeError("writer failed"), KeyboardInterrupt()])
def test_failed_rewrite_keeps_old_file(old, exc):
    """The writer fails halfway (an error, or a signal turned into KeyboardInterrupt)."""
    with pytest.raises(type(exc)), atomic_output(old) as tmp, open(tmp, "wb") as fh:
        fh.write(b"half of the new")
        fh.flush()
        raise exc
    assert old.read_bytes() == OLD and _listing(old.parent) == ["out.csv"]


def test_failed_rename_keeps_old_file(old, monkeypatch):
    def full(src, dst):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(OSError) as e, atomic_output(old) as tmp:
        tmp.write_bytes(b"new")
    assert e.value.filename == str(old)  # a failure that names no file is given the target's
    assert old.read_bytes() == OLD and _listing(old.parent) == ["out.csv"]


def test_full_disk_keeps_old_file(tmp_path):
    """A real full disk (a 16 kB tmpfs; root only): the rewrite of a 300-byte file with
    100 kB fails with ENOSPC naming the file; the old bytes and nothing else remain."""
    m = tmp_path / "m"
    m.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16k", "tmpfs", str(m)],
                       check=False, capture_output=True, text=True)  # fmt: skip
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs ({r.stderr.strip()[:80]}): needs root/CAP_SYS_ADMIN")
    try:
        p = m / "out.csv"
        p.write_bytes(OLD)
        with pytest.raises(OSError) as e, atomic_output(p) as tmp, open(tmp, "wb") as fh:
            for _ in range(100):
                fh.write(b"x" * 1024)
                fh.flush()
                os.fsync(fh.fileno())
        assert e.value.errno == errno.ENOSPC and e.value.filename == str(p)
        assert p.read_bytes() == OLD and _listing(m) == ["out.csv"]
    finally:
        subprocess.run(["umount", str(m)], check=False)


_KILLED = """
import os, sys, time
from pathlib import Path
from simulator.core.fileio import atomic_output
with atomic_output(sys.argv[1]) as tmp:
    with open(tmp, "wb") as fh:
        fh.write(b"half of the new")
        fh.flush()
        Path(sys.argv[2]).touch()
        time.sleep(60)
"""


def test_killed_rewrite_keeps_old_file_and_next_run_cleans(old, tmp_path):
    """SIGKILL mid-write (no handler runs): the old file is intact; the dead process's
    temporary is removed by the next write of the same target."""
    ready = tmp_path / "ready"
    p = subprocess.Popen([sys.executable, "-c", _KILLED, str(old), str(ready)])
    try:
        for _ in range(3000):  # wait for the known point: inside the temporary file
            if ready.exists() or p.poll() is not None:
                break
            import time

            time.sleep(0.01)
        assert ready.exists(), "the child never reached its write"
    finally:
        p.send_signal(signal.SIGKILL)
        p.wait(30)
    ready.unlink()
    assert old.read_bytes() == OLD
    assert [n for n in _listing(tmp_path) if ".tmp-" in n]  # the dead process's temporary
    with atomic_output(old) as tmp:
        tmp.write_bytes(b"new")
    assert _listing(tmp_path) == ["out.csv"] and old.read_bytes() == b"new"


def test_output_is_never_an_input(old):
    with (
        input_scope([old]),
        pytest.raises(InputError, match="same file as the input"),
        atomic_output(old) as tmp,
    ):
        tmp.write_bytes(b"x")
    assert old.read_bytes() == OLD


def test_pending_output_discard(old):
    out = PendingOutput(old)
    out.tmp.write_bytes(b"partial")
    out.discard()
    assert old.read_bytes() == OLD and _listing(old.parent) == ["out.csv"]


def test_output_folder_refuses_foreign_and_replaces_own(tmp_path):
    d = tmp_path / "o"
    d.mkdir()
    (d / "mine.txt").write_text("a user's file")
    (d / "a.txt").write_text("a user's a.txt")
    f = OutputFolder(d, ["a.txt", "b.txt"], "cmd")
    with pytest.raises(InputError, match="not written by vimsim cmd"):
        f.prepare()
    (d / "a.txt").unlink()
    out = f.prepare()
    assert json.loads((d / MANIFEST_NAME).read_text())["state"] == "incomplete"
    for n in ("a.txt", "b.txt"):
        with atomic_output(out / n) as tmp:
            tmp.write_text(n)
    f.complete()
    assert json.loads((d / MANIFEST_NAME).read_text())["state"] == "complete"
    g = OutputFolder(d, ["b.txt"], "cmd")  # a rerun: its own files are cleared first
    g.prepare()
    assert not (d / "a.txt").exists() and not (d / "b.txt").exists()
    assert (d / "mine.txt").read_text() == "a user's file"  # never touched
    with pytest.raises(InputError, match="not written by vimsim other"):
        OutputFolder(d, ["mine.txt"], "other").check()


def test_input_check_is_a_lookup_not_a_scan(tmp_path, monkeypatch):
    """An output is checked against thousands of recorded inputs by one lookup (a study
    reads each viewing's EPOF CSV: a samefile per input per output made the driver
    quadratic), and still refuses an input by another spelling, a symlink or a hard link."""
    from simulator.core import fileio

    files = []
    for k in range(3000):
        f = tmp_path / f"in{k}.csv"
        f.write_text("x")
        files.append(f)
    (tmp_path / "link.csv").symlink_to(files[7])
    os.link(files[9], tmp_path / "hard.csv")
    calls = []
    real = os.path.samefile
    monkeypatch.setattr(os.path, "samefile", lambda a, b: calls.append(a) or real(a, b))
    with input_scope(files):
        for name in ("out1.csv", "out2.csv"):
            with atomic_output(tmp_path / name) as tmp:
                Path(tmp).write_text("y")
        assert calls == []
        for bad in (tmp_path / "sub" / ".." / "in5.csv", tmp_path / "link.csv",
                    tmp_path / "hard.csv"):  # fmt: skip
            (tmp_path / "sub").mkdir(exist_ok=True)
            with pytest.raises(InputError, match="same file as the input"):
                fileio.check_not_input(bad)
    assert not fileio.known_inputs()  # the scope's inputs are gone after it


def test_a_deleted_inputs_inode_reused_by_an_output_is_not_that_input(tmp_path):
    """An input read then deleted (a temporary) frees its inode; a new output given the
    same number is not that input (it was refused as 'the same file as the input')."""
    import os

    from simulator.core.fileio import check_not_input, input_scope, register_input

    gone = tmp_path / "tmp_input.bin"
    gone.write_bytes(b"x")
    with input_scope():
        register_input(gone)
        ino = os.stat(gone).st_ino
        gone.unlink()
        for k in range(200):  # new files until one gets the freed inode number
            new = tmp_path / f"out{k}.json"
            new.write_text("{}")
            if os.stat(new).st_ino == ino:
                break
        else:
            raise AssertionError("no new file reused the freed inode; cannot check")
        check_not_input(new)  # not refused
