"""Executors of the study's task graph: a local process pool (default) and Ray (optional).

Both take the same calls -- ``submit(fn, *args, num_cpus=, alone=)`` returning a
handle, ``wait(handles, timeout)`` returning the finished ones, ``result(handle)``
(raising if the task's worker process died: ``lost(exc)`` says whether to run it again,
``describe(exc)`` says it in one line), ``max_task_cpus`` and ``close()``
(``close(wait=False)`` shuts down in the background, e.g. while the driver writes the
study's outputs; ``join()`` then waits for it) -- so the runner schedules one graph
either way and the results are the same bytes. ``num_cpus`` is the task's declared CPU
need: Ray schedules by it; the local pool runs ``workers`` tasks at a time and uses it
only for the task's own thread count (a task keeps to what it declares).

Ray is imported only here, only when asked for (``pip install vimsim[ray]``).
``ray`` starts a local Ray runtime with ``workers`` CPUs; ``ray:ADDRESS`` joins a running
cluster (``ray start --head`` ...), whose resources then decide the parallelism. The
address is checked (a TCP connection, 3 s) before Ray is initialised, so an unreachable
cluster is one line, not a hang.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import contextlib
import multiprocessing
import multiprocessing.forkserver
import os
import signal
import socket
import sys
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

from simulator.core.errors import InputError
from simulator.core.lifeline import exit_if_orphaned, watch_parent

__all__ = ["LocalExecutor", "RayExecutor", "make_executor", "parse_executor"]


def parse_executor(text: str) -> tuple[str, str | None]:
    """``"local"`` -> ("local", None); ``"ray"`` -> ("ray", None); ``"ray:HOST:PORT"`` ->
    ("ray", "HOST:PORT"). InputError for anything else."""
    if text == "local":
        return "local", None
    if text == "ray":
        return "ray", None
    if text.startswith("ray:") and len(text) > 4:
        return "ray", text[4:]
    raise InputError(
        f"unknown executor {text!r}; expected local, ray or ray:ADDRESS (e.g. ray:10.0.0.5:6379)"
    )


def check_ray_address(address: str, *, timeout_s: float = 3.0) -> None:
    """InputError unless ``HOST:PORT`` accepts a TCP connection (``auto`` is left to Ray)."""
    if address == "auto":
        return
    host, sep, port = address.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise InputError(f"Ray address {address!r}: expected HOST:PORT, e.g. 127.0.0.1:6379")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout_s):
            pass
    except OSError as e:
        raise InputError(
            f"Ray address {address}: unreachable ({e.strerror or e}); start the cluster with "
            "`ray start --head --port PORT` or check the address"
        ) from None


_IN_TASK = [False]


#: Modules the fork server imports once for every worker (what the tasks run: the task
#: module and the stages it calls). multiprocessing ignores a name that does not import,
#: so tests/study/test_study.py imports each.
WORKER_PRELOAD = (
    "simulator.study.tasks",
    "simulator.preprocess.paper",
    "simulator.preprocess.sphere",
    "simulator.epof.viewing",
    "simulator.viewing.job",
)


def _on_sigint(signum, frame) -> None:
    """A pool worker's Ctrl-C: interrupt the task it runs (a paper-mode preprocess then
    saves its checkpoint); while idle, nothing (the driver shuts the pool down), so no
    worker prints a traceback."""
    if _IN_TASK[0]:
        raise KeyboardInterrupt


#: Where the ``simulator`` package is imported from: the one import-path entry a worker
#: needs beside the interpreter's own (site-packages, PYTHONPATH: what the user chose).
_PACKAGE_ROOT = str(Path(__file__).resolve().parents[2])


def safe_import_path(path: list[str], cwd: str | None = None) -> list[str]:
    """``path`` (a ``sys.path``) without the entries that name the working folder (``''``,
    ``'.'``, the folder itself), unless the package is imported from there: a worker
    imports only the package and the interpreter's libraries, never a ``json.py`` or
    ``concurrent.py`` lying in the folder a study was started from."""
    here = os.path.realpath(cwd if cwd is not None else os.getcwd())
    keep = []
    for entry in path:
        real = os.path.realpath(os.path.join(here, entry))
        if real == here and real != _PACKAGE_ROOT:
            continue
        keep.append(entry)
    return keep


def _worker_init(command_pid: int | None = None) -> None:
    # Die with the command (even a kill -9 of it): no orphan keeps writing into OUTDIR.
    watch_parent(command_pid)
    # The pool hands each worker the driver's sys.path (with the working folder first
    # when the driver was started as ``python -m`` / ``-c``): drop it before any task.
    sys.path[:] = safe_import_path(sys.path)
    signal.signal(signal.SIGINT, _on_sigint)


@contextlib.contextmanager
def _safe_path_env():
    """New Python processes started inside do not put their working folder first on the
    import path (``PYTHONSAFEPATH``, Python 3.11): the fork server is ``python -c ...``."""
    old = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("PYTHONSAFEPATH", None)
        else:
            os.environ["PYTHONSAFEPATH"] = old


def _start_fork_server() -> None:
    """Start the fork server now, from the package's folder with a safe import path, so
    that its preloads (and every worker forked from it) import nothing from the folder the
    study was started in."""
    with _safe_path_env():
        multiprocessing.forkserver.ensure_running()


def _run_task(fn, args):
    exit_if_orphaned()  # a task still queued when the command died is never started
    _IN_TASK[0] = True
    try:
        return fn(*args)
    finally:
        _IN_TASK[0] = False


#: Seconds a cancelled pool's workers get to end on SIGTERM before SIGKILL.
STOP_GRACE_S = 1.0


def _stop_workers(pool: cf.ProcessPoolExecutor, grace_s: float = STOP_GRACE_S) -> None:
    """End a pool now: its queue cancelled, its workers terminated (killed if still there
    after ``grace_s``), never joined without a bound."""
    procs = list((getattr(pool, "_processes", None) or {}).values())
    for p in procs:
        with contextlib.suppress(OSError, ValueError, AttributeError):
            p.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    end = time.monotonic() + grace_s
    for p in procs:
        with contextlib.suppress(OSError, ValueError, AssertionError, AttributeError):
            p.join(max(0.0, end - time.monotonic()))
            if p.is_alive():
                p.kill()
                p.join(0.5)


class LocalExecutor:
    """A pool of ``workers`` processes, fed at most ``workers`` tasks at a time.

    Workers come from a fork server where the platform has one (a fresh single-threaded
    process that has imported the task module once, then forks each worker): no
    re-import per worker, and none of the caller's threads (decoders, encoders, a test
    runner's) are forked with a lock held, which can deadlock a plain ``fork``.
    Elsewhere ``spawn``. Workers import only the package: the fork server starts with a
    safe import path and each worker drops the working folder from the one it is handed
    (:func:`safe_import_path`), so a ``json.py`` in the folder a study is started from is
    never run.

    The rest wait here, not in the pool's queue: when a worker process dies (killed, out
    of memory, a crash in a native library) the pool fails every task it holds, so it
    holds only the running ones. The pool is then replaced; a task submitted with
    ``alone=True`` (a rerun of such a task) runs with no other task beside it, so a task
    that kills its worker every time cannot take others down with it twice.
    """

    name = "local"

    def __init__(self, workers: int):
        self.workers = int(workers)
        if "forkserver" in multiprocessing.get_all_start_methods():
            ctx = multiprocessing.get_context("forkserver")
            # What every task needs, imported once in the server (no GL context is made there).
            ctx.set_forkserver_preload(list(WORKER_PRELOAD))
            _start_fork_server()
        else:
            os.environ["PYTHONSAFEPATH"] = "1"  # every spawned worker: no working folder
            ctx = multiprocessing.get_context("spawn")
        self._ctx = ctx
        self._pool = self._new_pool()
        self._queue: collections.deque = collections.deque()  # (handle, fn, args, alone)
        self._running: dict = {}  # pool future -> (handle, alone)

    def _new_pool(self) -> cf.ProcessPoolExecutor:
        return cf.ProcessPoolExecutor(
            max_workers=self.workers, mp_context=self._ctx, initializer=_worker_init,
            initargs=(os.getpid(),),
        )

    def submit(self, fn, *args, num_cpus: int = 1, alone: bool = False) -> cf.Future:
        h: cf.Future = cf.Future()
        self._queue.append((h, fn, args, alone))
        self._dispatch()
        return h

    def _dispatch(self) -> None:
        """Hand queued tasks to the pool: up to ``workers`` at once; an ``alone`` task
        only into an empty pool, and nothing beside it."""
        while self._queue and len(self._running) < self.workers:
            h, fn, args, alone = self._queue[0]
            if any(a for _, a in self._running.values()) or (alone and self._running):
                return
            self._queue.popleft()
            try:
                f = self._pool.submit(_run_task, fn, args)
            except BrokenProcessPool:
                # A worker died: the pool is unusable; later tasks go to a new one.
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
                f = self._pool.submit(_run_task, fn, args)
            self._running[f] = (h, alone)

    def _collect(self, timeout: float | None) -> None:
        """Wait for a running task; move finished ones' results to their handles."""
        if not self._running:
            return
        done, _ = cf.wait(list(self._running), timeout=timeout, return_when=cf.FIRST_COMPLETED)
        for f in done:
            h, _ = self._running.pop(f)
            e = f.exception()
            if e is None:
                h.set_result(f.result())
            else:
                h.set_exception(e)
        self._dispatch()

    @staticmethod
    def lost(exc: BaseException) -> bool:
        """The task's worker process died (this or another task's: the pool breaks)."""
        return isinstance(exc, BrokenProcessPool)

    @staticmethod
    def describe(exc: BaseException) -> str:
        if LocalExecutor.lost(exc):
            return "a worker process died (killed, out of memory or crashed)"
        return f"{type(exc).__name__}: {' '.join(str(exc).split())}"

    def wait(self, handles, timeout: float | None = None) -> list:
        hs = list(handles)
        while True:
            done = [h for h in hs if h.done()]
            if done or not self._running:
                return done
            self._collect(timeout)
            if timeout is not None:
                return [h for h in hs if h.done()]

    def result(self, handle):
        return handle.result()

    @property
    def max_task_cpus(self) -> int:
        """The most CPUs one task can have: this machine's."""
        return os.cpu_count() or 1

    def info(self) -> dict:
        return {"executor": "local", "workers": self.workers}

    def close(self, cancel: bool = False, wait: bool = True) -> None:
        """Shut the pool down; ``cancel``: drop queued tasks and end the running ones now
        (their workers terminated, killed after ``STOP_GRACE_S``; a task writes each output
        to a temporary name, so none is left half-written), as after a signal: joining
        workers that finish their chunks could take hours."""
        if cancel:
            for h, *_ in self._queue:
                h.cancel()
            self._queue.clear()
            _stop_workers(self._pool)
            return
        self._pool.shutdown(wait=wait, cancel_futures=cancel)

    def join(self) -> None:
        self._pool.shutdown(wait=True)


class RayExecutor:
    """Tasks as Ray remote functions with declared ``num_cpus``; results via ``ray.wait``."""

    name = "ray"

    def __init__(self, workers: int, address: str | None = None):
        try:
            import ray
        except ImportError:
            raise InputError(
                "--executor ray needs Ray: pip install 'vimsim[ray]' (or pip install ray)"
            ) from None
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        self._ray = ray
        self.address = address
        if address is not None:
            check_ray_address(address)
        kw = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        # Ray puts the driver's working folder on every worker's import path: connect from
        # the package's own root (already on it), so a worker imports nothing from the
        # folder the study was started in.
        with contextlib.chdir(_PACKAGE_ROOT), _safe_path_env():
            if address is None:  # a runtime for this machine only: keep it on loopback
                # address="local": a new runtime even if another cluster's address is on record
                ray.init(address="local", num_cpus=int(workers), _node_ip_address="127.0.0.1", **kw)
            else:
                ray.init(address=address, **kw)
        self.workers = int(ray.cluster_resources().get("CPU", workers))
        self._remote: dict = {}
        self._closing: threading.Thread | None = None

    def submit(self, fn, *args, num_cpus: int = 1, alone: bool = False):
        r = self._remote.get(fn)
        if r is None:
            r = self._remote[fn] = self._ray.remote(fn)
        # max_retries: Ray reruns a task whose worker process died, once (a task's own
        # errors are its result's status, never raised, so never retried).
        return r.options(num_cpus=num_cpus, max_retries=1).remote(*args)

    def lost(self, exc: BaseException) -> bool:
        """Ray has already rerun a task whose worker died (``max_retries``)."""
        return False

    def describe(self, exc: BaseException) -> str:
        e = self._ray.exceptions
        if isinstance(exc, (e.WorkerCrashedError, e.NodeDiedError)):
            return f"its Ray worker died twice ({type(exc).__name__})"
        return f"{type(exc).__name__}: {' '.join(str(exc).split()[:40])}"

    def wait(self, handles, timeout: float | None = None) -> list:
        hs = list(handles)
        ready, _ = self._ray.wait(hs, num_returns=1, timeout=timeout)
        return ready

    def result(self, handle):
        return self._ray.get(handle)

    @property
    def max_task_cpus(self) -> int:
        """The most CPUs one task can have: the largest node's (Ray never schedules a
        task that asks for more; it would wait for ever)."""
        cpus = [n.get("Resources", {}).get("CPU", 0) for n in self._ray.nodes() if n.get("Alive")]
        return max(1, int(max(cpus, default=1)))

    def info(self) -> dict:
        nodes = [n for n in self._ray.nodes() if n.get("Alive")]
        return {
            "executor": "ray" if self.address is None else f"ray:{self.address}",
            "workers": self.workers,
            "ray_nodes": len(nodes),
            "ray_version": self._ray.__version__,
        }

    def close(self, cancel: bool = False, wait: bool = True) -> None:
        """Disconnect (a local runtime: stop it, about 1.3 s here); ``wait=False`` in a
        background thread, so it overlaps the driver's remaining work."""
        if self._closing is None:
            self._closing = threading.Thread(target=self._ray.shutdown, name="ray-shutdown")
            self._closing.start()
        if wait:
            self.join()

    def join(self) -> None:
        if self._closing is not None:
            self._closing.join()


def make_executor(text: str, workers: int | None):
    """The executor named by ``--executor`` text with ``workers`` (default: CPU count)."""
    kind, address = parse_executor(text)
    n = int(workers or os.cpu_count() or 1)
    if n < 1:
        raise InputError(f"--workers must be >= 1; got {n}")
    if kind == "local":
        return LocalExecutor(n)
    return RayExecutor(n, address)
