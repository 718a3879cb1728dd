"""A real full disk under every writer: each command writes into a tiny tmpfs.

It must fail in one line naming the file (exit 1; a study may instead give its viewings
the error as their status, exit 3), leave no temporary file, no file that looks complete
and no traceback. Mounting needs root (as here and in CI); elsewhere the tests are skipped
with that reason.
"""

from __future__ import annotations

import contextlib
import subprocess
from pathlib import Path

import pytest
from test_reliability import base  # noqa: F401

from simulator.cli import main


@contextlib.contextmanager
def _tmpfs(path: Path, size: str):
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                       check=False, capture_output=True, text=True)  # fmt: skip
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs ({r.stderr.strip()[:80]}): needs root/CAP_SYS_ADMIN")
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=False)


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


#: (writer, argv with {d} = the corpus copy and {m} = the full tmpfs, tmpfs size,
#: a file that must not exist afterwards: the output or the completion marker)
WRITERS = [
    ("render", ["render", "{d}/v.mp4", "{d}/P.csv", "-o", "{m}/o", "--eye-size", "512x512",
                "--opacity", "0.5", "--no-progress"], "24k", "o/summary.json"),
    ("synth", ["synth", "{m}/s.mp4", "--scene", "rotate", "--seconds", "1", "--fps", "10",
               "--size", "512x256"], "24k", "s.mp4"),
    ("preprocess-sphere", ["preprocess", "{d}/v.mp4", "-o", "{m}/g.npz", "--method", "sphere",
                           "--cell", "5", "--window-size", "32", "--no-progress"], "4k", "g.npz"),
    ("frames", ["frames", "{d}/v.mp4", "{d}/P.csv", "-o", "{m}/o", "--eye-size", "512x512",
                "--every", "0.1", "--no-progress"], "24k", "o/frames.json"),
    ("demo", ["demo", "-o", "{m}/o", "--seconds", "0.5", "--no-progress"], "8k", "o/summary.json"),
    ("study", ["study", "{d}/S.toml", "-o", "{m}/o", "--cache-dir", "{m}/c", "--workers", "1",
               "--no-progress"], "4k", "o/study.json"),
]  # fmt: skip


@pytest.mark.parametrize("writer", WRITERS, ids=[w[0] for w in WRITERS])
def test_full_disk(base, tmp_path, capsys, monkeypatch, writer):  # noqa: F811
    name, argv, size, marker = writer
    d = base
    if name == "demo":  # at the tiny size of tests/test_demo.py
        import dataclasses

        import simulator.demo as dm

        real = dm.DemoConfig
        tiny = {"fps": 10.0, "eye_size": (128, 64), "window": 32, "render_size": (64, 64)}
        monkeypatch.setattr(dm, "DemoConfig", lambda **k: dataclasses.replace(real(**k), **tiny))
    if name == "study":
        d = tmp_path / "in"
        d.mkdir()
        for f in ("v.mp4", "P.csv"):
            (d / f).write_bytes((base / f).read_bytes())
        (d / "S.toml").write_text(
            '[study]\nname = "t"\n\n[[videos]]\nid = "a"\npath = "v.mp4"\nmethod = "sphere"\n'
            'window_size = 32\ncell = 10\n\n[[viewings]]\nvideo = "a"\ntrace = "P.csv"\n'
        )
    before = {p: p.read_bytes() for p in d.iterdir() if p.is_file()}
    with _tmpfs(tmp_path / "full", size) as m:
        rc = main([a.replace("{d}", str(d)).replace("{m}", str(m)) for a in argv])
        err = capsys.readouterr().err
        left = _files(m)
        rows = (m / "o" / "viewings.csv").read_text() if rc == 3 else ""
    lines = [ln for ln in err.splitlines() if "error" in ln]
    assert "Traceback" not in err and "internal error" not in err, err
    assert not [f for f in left if ".tmp-" in f], left  # no temporary file
    assert {p: p.read_bytes() for p in d.iterdir() if p.is_file()} == before  # inputs intact
    if name == "study" and rc == 3:  # a complete study whose viewings carry the error
        assert "No space left on device" in rows and str(m) in rows, rows
        return
    assert marker not in left, left  # nothing looks complete
    assert rc == 1, err
    assert len(lines) == 1 and "No space left on device" in lines[0], err
    assert str(m) in lines[0] and ".tmp-" not in lines[0], err  # names the output file
