"""Workers end with their command: a ``kill -9`` of ``screen`` or ``study`` leaves no worker
running or idle, and nothing new appears in the output folder afterwards; a SIGTERM ends
the running tasks, not after their chunks."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from simulator.core import lifeline

REPO = Path(__file__).resolve().parents[2]


def _session(sid: int) -> list[int]:
    """Live (not zombie) processes of session ``sid``: the command and all it started."""
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()  # state, ppid, pgrp, session, ...
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append(int(d.name))
    return found


def _files(folder: Path) -> dict[str, int]:
    return {str(p): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


def _wait_for(cond, limit_s: float) -> bool:
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.05)
    return cond()


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    from simulator.synth import SynthConfig, synthesize

    d = tmp_path_factory.mktemp("lifeline")
    synthesize(SynthConfig("rotate", seconds=1.0, fps=10, size=(128, 64)), d / "clip.mp4")
    return d / "clip.mp4"


def _command(kind: str, clip: Path, d: Path) -> list[str]:
    if kind == "screen":
        return ["screen", str(clip), "-o", str(d / "out"), "--viewers", "3000", "--workers", "2",
                "--cache-dir", str(d / "cache"), "--no-progress"]  # fmt: skip
    m = d / "study.toml"
    m.write_text(f'[[videos]]\nid = "clip"\npath = "{clip}"\nwindow_size = 64\n\n'
                 '[[viewings]]\nvideo = "clip"\nviewers = {n = 3000}\n')  # fmt: skip
    return ["study", str(m), "-o", str(d / "out"), "--workers", "2", "--cache-dir",
            str(d / "cache"), "--no-progress"]  # fmt: skip


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("kind", ["screen", "study"])
def test_kill_9_leaves_no_worker_and_no_new_file(kind, clip, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-m", "simulator", *_command(kind, clip, tmp_path)],
                            env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)  # fmt: skip
    epof = tmp_path / "out" / "epof"
    try:
        # workers busy: the first viewings' EPOF files written, thousands to go
        assert _wait_for(lambda: epof.is_dir() and any(epof.iterdir()), 120)
        assert proc.poll() is None  # still running: the kill below lands mid-study
        assert len(_session(proc.pid)) >= 3  # the command, its fork server, its workers
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        # every worker (and the fork server) ends by itself within seconds
        assert _wait_for(lambda: not _session(proc.pid), 10), _session(proc.pid)
        before = _files(tmp_path / "out")
        time.sleep(1.0)
        assert _files(tmp_path / "out") == before  # nothing written after the kill
    finally:
        for pid in _session(proc.pid):  # a regression must not leave them behind
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.stderr.close()


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc")
def test_sigterm_ends_running_tasks_not_their_chunks(clip, tmp_path):
    """SIGTERM mid-screening: the command ends (143) with its workers, not after they
    finish the chunks they hold (3000 viewers in 6 chunks of 500: the pool used to be
    joined until both running chunks were done, 1000 files and half a minute later)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-m", "simulator", *_command("screen", clip, tmp_path)],
                            env=env, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)  # fmt: skip
    epof = tmp_path / "out" / "epof"
    try:
        assert _wait_for(lambda: epof.is_dir() and any(epof.iterdir()), 120)
        assert proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 143
        assert "terminated (SIGTERM)" in proc.stderr.read()
        assert _wait_for(lambda: not _session(proc.pid), 10)  # its workers (fork server) too
        assert len(list(epof.iterdir())) < 500  # no chunk ran to its end after the signal
    finally:
        for pid in _session(proc.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.stderr.close()


def test_watch_parent_outside_and_inside_a_worker(tmp_path):
    """Outside a worker nothing is watched; a worker whose command is gone exits at
    once before a task or an output, and the temporary file is not left behind."""
    assert not lifeline.orphaned()
    code = (
        "import os, sys\n"
        "from simulator.core import lifeline\n"
        "from simulator.core.fileio import atomic_output\n"
        "lifeline.watch_parent(int(sys.argv[1]))\n"
        "print('watching', flush=True)\n"
        "sys.stdin.readline()\n"  # the command dies meanwhile
        "with atomic_output(sys.argv[2]) as tmp:\n"
        "    open(tmp, 'w').write('x')\n"
        "print('wrote', flush=True)\n"
    )
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a pid that is gone: the "command" of this worker
    target = tmp_path / "out.txt"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    r = subprocess.run([sys.executable, "-c", code, str(dead.pid), str(target)],
                       input="\n", capture_output=True, text=True, env=env, timeout=60, check=False)  # fmt: skip
    assert r.returncode == lifeline.ORPHAN_STATUS
    assert "wrote" not in r.stdout
    assert list(tmp_path.iterdir()) == []
    ok = subprocess.run([sys.executable, "-c", code, str(os.getpid()), str(target)],
                        input="\n", capture_output=True, text=True, env=env, timeout=60, check=False)  # fmt: skip
    assert ok.returncode == 0 and "wrote" in ok.stdout
    assert target.read_text() == "x"
