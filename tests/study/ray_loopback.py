"""A two-node Ray cluster on loopback for tests and benches (``ray start --head`` plus a
second ``ray start --address``), always stopped afterwards.

Each node is a ``ray start --block`` process started in its own session; stopping it is
SIGTERM (then SIGKILL) to that process group, i.e. only the processes this helper
started (the effect of ``ray stop`` without touching any other Ray on the machine).
Token authentication is disabled for this throwaway loopback cluster only.

Loopback only: Ray replaces 127.0.0.1 by the address of the machine's network interface
(its "node IP", found in ``ray._private.services``) so that clusters span machines. Here
every process -- both ``ray start`` and the driver -- gets that lookup answered with
127.0.0.1 (:func:`use_loopback`; the nodes run Ray's CLI through a two-line wrapper
doing the same), so no traffic goes to any other address.
"""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


#: Environment of the nodes and the driver: no usage stats, no token (throwaway cluster).
RAY_ENV = {"RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "disabled"}

_PATCH = (
    "import ray._private.services as s; "
    "s.node_ip_address_from_perspective = lambda *a, **k: '127.0.0.1'"
)
#: ``ray start ...`` as ``python -c WRAPPER start ...`` with the node IP lookup on loopback.
_WRAPPER = (
    f"{_PATCH}; import sys; sys.argv[0] = 'ray'; from ray.scripts.scripts import main; main()"
)


def use_loopback() -> None:
    """This process: :data:`RAY_ENV`, and Ray's node IP lookup answering 127.0.0.1."""
    os.environ.update(RAY_ENV)
    from ray._private import services

    services.node_ip_address_from_perspective = lambda *a, **k: "127.0.0.1"


def ray_env() -> dict:
    return {**os.environ, **RAY_ENV}


def _stop(p: subprocess.Popen) -> None:
    """SIGTERM to the node's process group, SIGKILL to whatever is left of it after 5 s."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(p.pid, signal.SIGTERM)
    with contextlib.suppress(subprocess.TimeoutExpired):
        p.wait(5)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 5:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    with contextlib.suppress(subprocess.TimeoutExpired):
        p.wait(5)


@contextlib.contextmanager
def loopback_cluster(
    log_dir: Path,
    *,
    cpus_per_node: int = 1,
    nodes: int = 2,
    timeout_s: float = 90,
    node_procs: list | None = None,
):
    """Yield ``"127.0.0.1:PORT"`` of a cluster of ``nodes`` nodes, ``cpus_per_node`` CPUs each.

    ``node_procs``: a list that receives each node's ``ray start`` process (head first),
    e.g. for :func:`kill_raylet`.

    :data:`RAY_ENV` must be in ``os.environ`` before ``ray`` is first imported in this
    process (Ray reads it at import): call :func:`use_loopback` at the top of the module.
    """
    use_loopback()
    import ray

    port = free_port()
    log_dir.mkdir(parents=True, exist_ok=True)
    common = ["--block", f"--num-cpus={cpus_per_node}", "--node-ip-address=127.0.0.1",
              "--disable-usage-stats"]  # fmt: skip
    ray_cli = [sys.executable, "-c", _WRAPPER]
    cmds = [[*ray_cli, "start", "--head", f"--port={port}", "--include-dashboard=false", *common]]
    cmds += [[*ray_cli, "start", f"--address=127.0.0.1:{port}", *common]] * (nodes - 1)
    procs: list[subprocess.Popen] = []
    env = ray_env()
    t_up = time.monotonic()
    try:
        for i, cmd in enumerate(cmds):
            log = open(log_dir / f"ray_node{i}.log", "w")  # noqa: SIM115
            procs.append(subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT,
                                          start_new_session=True))  # fmt: skip
            if node_procs is not None:
                node_procs.append(procs[-1])
            if i == 0:  # the head's GCS must listen before a node can join
                t0 = time.monotonic()
                while True:
                    with (
                        contextlib.suppress(OSError),
                        socket.create_connection(("127.0.0.1", port), 1),
                    ):
                        break
                    if time.monotonic() - t0 > timeout_s or procs[0].poll() is not None:
                        raise RuntimeError(f"ray head did not start; see {log_dir}/ray_node0.log")
                    time.sleep(0.5)
        ray.init(address=f"127.0.0.1:{port}", include_dashboard=False, log_to_driver=False)
        try:
            t0 = time.monotonic()
            while sum(n["Alive"] for n in ray.nodes()) < nodes:
                if time.monotonic() - t0 > timeout_s:
                    raise RuntimeError(f"only {sum(n['Alive'] for n in ray.nodes())} Ray nodes up")
                time.sleep(0.5)
        finally:
            ray.shutdown()
        print(f"ray loopback cluster up in {time.monotonic() - t_up:.1f} s", file=sys.stderr)
        yield f"127.0.0.1:{port}"
    finally:
        for p in reversed(procs):
            _stop(p)
        # What `ray stop` also does: forget this cluster's address (only if it is ours).
        rec = Path("/tmp/ray/ray_current_cluster")
        with contextlib.suppress(OSError):
            if rec.read_text().strip() == f"127.0.0.1:{port}":
                rec.unlink()


def raylet_pid(node: subprocess.Popen) -> int | None:
    """The pid of the raylet of ``node`` (a ``ray start`` process of :func:`loopback_cluster`):
    the process named ``raylet`` in its process group (read from /proc)."""
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if os.getpgid(int(d.name)) != node.pid:
                continue
            exe = (d / "cmdline").read_bytes().split(b"\0")[0]
        except OSError:
            continue
        if exe == b"raylet" or exe.endswith(b"/raylet"):
            return int(d.name)
    return None


def kill_raylet(node: subprocess.Popen) -> int:
    """SIGKILL the raylet of ``node`` (a node failure: its workers lose their raylet and
    exit); returns the pid killed."""
    pid = raylet_pid(node)
    if pid is None:
        raise RuntimeError("no raylet found in the node's process group")
    os.kill(pid, signal.SIGKILL)
    return pid
