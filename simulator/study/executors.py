"""Executors of the study's task graph: a local process pool (default) and Ray (optional).

Both take the same calls -- ``submit(fn, *args, num_cpus=)`` returning a handle,
``wait(handles, timeout)`` returning the finished ones, ``result(handle)`` and
``close()`` -- so the runner schedules one graph either way and the results are the same
bytes. ``num_cpus`` is the task's declared CPU need: Ray schedules by it; the local pool
runs ``workers`` tasks at a time and uses it only for the task's own thread count.

Ray is imported only here, only when asked for (``pip install vimsim[ray]``).
``ray`` starts a local Ray runtime with ``workers`` CPUs; ``ray:ADDRESS`` joins a running
cluster (``ray start --head`` ...), whose resources then decide the parallelism. The
address is checked (a TCP connection, 3 s) before Ray is initialised, so an unreachable
cluster is one line, not a hang.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import signal
import socket

from simulator.errors import InputError

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


def _on_sigint(signum, frame) -> None:
    """A pool worker's Ctrl-C: interrupt the task it runs (a paper-mode preprocess then
    saves its checkpoint); while idle, nothing (the driver shuts the pool down), so no
    worker prints a traceback."""
    if _IN_TASK[0]:
        raise KeyboardInterrupt


def _worker_init() -> None:
    signal.signal(signal.SIGINT, _on_sigint)


def _run_task(fn, args):
    _IN_TASK[0] = True
    try:
        return fn(*args)
    finally:
        _IN_TASK[0] = False


class LocalExecutor:
    """A pool of ``workers`` processes.

    Workers come from a fork server where the platform has one (a fresh single-threaded
    process that has imported the task module once, then forks each worker): no
    re-import per worker, and none of the caller's threads (decoders, encoders, a test
    runner's) are forked with a lock held, which can deadlock a plain ``fork``.
    Elsewhere ``spawn``.
    """

    name = "local"

    def __init__(self, workers: int):
        self.workers = int(workers)
        if "forkserver" in multiprocessing.get_all_start_methods():
            ctx = multiprocessing.get_context("forkserver")
            # What every task needs, imported once in the server (no GL context is made there).
            ctx.set_forkserver_preload(
                [
                    "simulator.study.tasks",
                    "simulator.sphere",
                    "simulator.preprocess",
                    "simulator.render",
                ]
            )
        else:
            ctx = multiprocessing.get_context("spawn")
        self._pool = cf.ProcessPoolExecutor(
            max_workers=self.workers, mp_context=ctx, initializer=_worker_init
        )

    def submit(self, fn, *args, num_cpus: int = 1):
        return self._pool.submit(_run_task, fn, args)

    def wait(self, handles, timeout: float | None = None) -> list:
        done, _ = cf.wait(list(handles), timeout=timeout, return_when=cf.FIRST_COMPLETED)
        return list(done)

    def result(self, handle):
        return handle.result()

    def info(self) -> dict:
        return {"executor": "local", "workers": self.workers}

    def close(self, cancel: bool = False) -> None:
        self._pool.shutdown(wait=True, cancel_futures=cancel)


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
        if address is None:  # a runtime for this machine only: keep it on loopback
            # address="local": a new runtime even if another cluster's address is on record
            ray.init(address="local", num_cpus=int(workers), _node_ip_address="127.0.0.1", **kw)
        else:
            ray.init(address=address, **kw)
        self.workers = int(ray.cluster_resources().get("CPU", workers))
        self._remote: dict = {}

    def submit(self, fn, *args, num_cpus: int = 1):
        r = self._remote.get(fn)
        if r is None:
            r = self._remote[fn] = self._ray.remote(fn)
        return r.options(num_cpus=num_cpus, max_retries=0).remote(*args)

    def wait(self, handles, timeout: float | None = None) -> list:
        hs = list(handles)
        ready, _ = self._ray.wait(hs, num_returns=1, timeout=timeout)
        return ready

    def result(self, handle):
        return self._ray.get(handle)

    def info(self) -> dict:
        nodes = [n for n in self._ray.nodes() if n.get("Alive")]
        return {
            "executor": "ray" if self.address is None else f"ray:{self.address}",
            "workers": self.workers,
            "ray_nodes": len(nodes),
            "ray_version": self._ray.__version__,
        }

    def close(self, cancel: bool = False) -> None:
        self._ray.shutdown()


def make_executor(text: str, workers: int | None):
    """The executor named by ``--executor`` text with ``workers`` (default: CPU count)."""
    kind, address = parse_executor(text)
    n = int(workers or os.cpu_count() or 1)
    if n < 1:
        raise InputError(f"--workers must be >= 1; got {n}")
    if kind == "local":
        return LocalExecutor(n)
    return RayExecutor(n, address)
