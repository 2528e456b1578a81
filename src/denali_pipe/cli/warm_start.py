"""Warm start: `denali` jobs fork from one interpreter that has already imported the heavy libraries.

Each Snakemake job is a fresh `python -m denali_pipe.cli ...`, and before it
does any work it spends seconds importing: a training cell 4-5 s (torch
1.4 s, the `torch._dynamo` that Adam's constructor pulls in 1.2 s,
scikit-learn 1.2 s, pandas 0.5 s), a poses job ~1 s. Over the demo's ~1,200
jobs that is about a quarter of `rule all`'s CPU time on 2 cores.

So a local run starts one server (`start`, from the Snakefile's `onstart`)
that imports `PRELOAD` once and listens on a UNIX socket named in the
environment variable `ENV`, which the jobs inherit. A job's `denali` (the
client, `hand_off`) sends the server its arguments, working directory,
environment and its stdin/stdout/stderr; the server forks a watcher, which
forks the worker that runs `denali_pipe.cli.main` with them and reports its
exit status back. The client forwards SIGINT/SIGTERM/SIGHUP to the worker,
and the watcher kills the worker if the client dies, so cancelling a job
cancels its work. Whenever no server answers (none started, still
importing, gone, or a cluster node that cannot see it), the client runs the
job itself, so a job never depends on the server.

The worker is the same code on the same inputs in a process whose imports
are done and nothing else: the server runs nothing before it forks, and the
worker resizes the loaded thread pools to the job's `threads:`
(`_limit_threads`), since the order in which threads add decides the last
digits (`tests/test_cli_warm_start.py` holds a training cell's metrics and
weights equal both ways).
What differs is what Snakemake's `benchmark:` files see: they measure the
job's own process tree, which now holds the client only. The worker
therefore appends its own CPU time and peak memory to the job's log
(`USAGE_PREFIX`), and `scripts/bench_stages.py` reads them from there.

Linux only (fork after importing torch is unsafe on macOS); config
`warm_start: false` turns it off.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import resource
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

ENV = "DENALI_WARM_START"
# What a stage job imports that costs more than ~0.1 s, and the stage modules
# themselves. Not mitsuba or drjit: their JIT starts thread pools, which must
# not be forked (the mitransient renderer's jobs import them fresh).
PRELOAD = (
    "numpy",
    "pandas",
    "pyarrow.parquet",
    "zarr",
    "torch",
    "torch._dynamo",
    "torch.utils.flop_counter",
    "sklearn.model_selection",
    "cv2",
    "pyapriltags",
    "trimesh",
    "matplotlib.pyplot",
    "matplotlib.textpath",
    "denali_pipe.train.training",
    "denali_pipe.train.classical",
    "denali_pipe.train.evaluate",
    "denali_pipe.train.dataset",
    "denali_pipe.ingest.capture_set",
    "denali_pipe.poses.estimate",
    "denali_pipe.poses.calibrate",
    "denali_pipe.preprocess.histograms",
    "denali_pipe.rig.capture",
    "denali_pipe.twin.analytic",
    "denali_pipe.transforms.sim_to_real",
)
# The environment variables that size a job's thread pools (Snakemake sets
# them to the rule's threads), by threadpoolctl's name for the pool.
THREAD_VARIABLES = {"openmp": "OMP_NUM_THREADS", "blas": "OPENBLAS_NUM_THREADS"}
# How the worker's resource use reaches the job's log (stderr), one line.
USAGE_PREFIX = "denali warm start: worker usage "
# The server exits within this many seconds of the Snakemake process that
# started it ending, whatever way it ended.
OWNER_POLL_S = 1.0
_LENGTH = 8  # bytes of the request's length prefix

_server: subprocess.Popen | None = None
_socket_dir: Path | None = None  # the folder `start` made for the socket: the only one `stop` removes


def start(enabled: bool, log: Path) -> None:
    """Start the server for this (local, Linux) Snakemake run and point the
    jobs at it through `ENV`; its own messages go to `log`. Nothing when not
    `enabled`, off Linux, or when a server is already running."""
    global _server, _socket_dir
    if not enabled or not sys.platform.startswith("linux") or _server is not None:
        return
    _socket_dir = Path(tempfile.mkdtemp(prefix="denali-warm-"))
    socket_path = _socket_dir / "socket"
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as out:
        _server = subprocess.Popen(
            [sys.executable, "-m", "denali_pipe.cli.warm_start", str(socket_path), "--owner", str(os.getpid())],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    os.environ[ENV] = str(socket_path)


def stop() -> None:
    """Stop the server `start` started, if any, and remove its socket. A
    socket named in the environment that `start` did not make (inherited
    from the shell, a crashed run's) is left alone, as is the variable."""
    global _server, _socket_dir
    if _socket_dir is None:
        return
    os.environ.pop(ENV, None)
    if _server is not None:
        _server.terminate()
        try:
            _server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            _server.kill()
            _server.wait()
        _server = None
    shutil.rmtree(_socket_dir, ignore_errors=True)
    _socket_dir = None


def hand_off(argv: list[str]) -> int | None:
    """Run `denali argv` in the server's worker and return its exit status;
    None when no server takes the job (the caller then runs it itself)."""
    socket_path = os.environ.get(ENV)
    if not socket_path:
        return None
    conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        conn.connect(socket_path)
    except OSError:
        conn.close()
        return None
    request = json.dumps({"argv": argv, "cwd": os.getcwd(), "env": dict(os.environ)}).encode()
    with conn, conn.makefile("rb") as replies:
        try:
            socket.send_fds(conn, [len(request).to_bytes(_LENGTH, "big") + request], [0, 1, 2])
            first = replies.readline()
        except OSError:
            return None
        if not first:
            # the server took the request but started nothing: run it here
            return None
        worker = int(first)

        def forward(signum, _frame):
            try:
                os.kill(worker, signum)
            except ProcessLookupError:
                pass

        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(signum, forward)
        status = replies.readline()
    if not status:
        print(f"denali warm start: lost the server running job {worker}", file=sys.stderr)
        return 1
    code = int(status)
    # a worker killed by signal N exits as a shell reports it, 128 + N
    return code if code >= 0 else 128 - code


def worker_usage(log_text: str) -> dict | None:
    """The usage a warm worker appended to its job's log ({"cpu_s": CPU
    seconds, "max_rss_mb": peak resident MB, the server's pages it maps
    included}), or None for a job that ran afresh."""
    _, found, rest = log_text.rpartition(USAGE_PREFIX)
    return json.loads(rest.splitlines()[0]) if found else None


def serve(socket_path: Path, owner: int) -> None:
    """Import `PRELOAD`, then serve jobs on `socket_path` until process
    `owner` (the Snakemake run) ends or SIGTERM arrives."""
    started = time.perf_counter()
    for name in PRELOAD:
        importlib.import_module(name)
    threads = len(os.listdir("/proc/self/task"))
    print(f"imported {len(PRELOAD)} modules in {time.perf_counter() - started:.1f} s; {threads} threads", flush=True)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    # the watchers are reaped by the kernel; each waits for its own worker
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(socket_path))
    listener.listen(64)
    listener.settimeout(OWNER_POLL_S)
    served = 0
    try:
        while _alive(owner):
            try:
                conn, _ = listener.accept()
            except TimeoutError:
                continue
            sys.stdout.flush()
            if os.fork() == 0:
                listener.close()
                _watch(conn)
            conn.close()
            served += 1
    finally:
        listener.close()
        socket_path.unlink(missing_ok=True)
        print(f"served {served} jobs", flush=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def _watch(conn: socket.socket) -> None:
    """The watcher: read one request, fork its worker, tell the client the
    worker's pid, then its exit status. Never returns."""
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    conn.settimeout(None)
    data, fds, _, _ = socket.recv_fds(conn, 1 << 16, 3)
    while len(data) < _LENGTH or len(data) < _LENGTH + int.from_bytes(data[:_LENGTH], "big"):
        chunk = conn.recv(1 << 16)
        if not chunk:
            os._exit(1)
        data += chunk
    request = json.loads(data[_LENGTH:])
    worker = os.fork()
    if worker == 0:
        conn.close()
        _work(request, fds)
    for fd in fds:
        os.close(fd)
    conn.sendall(f"{worker}\n".encode())
    done = os.pidfd_open(worker)
    while done not in select.select([done, conn], [], [])[0]:
        if not conn.recv(1):
            # the client is gone (Snakemake killed the job): so is the job
            os.kill(worker, signal.SIGKILL)
            break
    _, status = os.waitpid(worker, 0)
    try:
        conn.sendall(f"{os.waitstatus_to_exitcode(status)}\n".encode())
    except OSError:
        pass
    os._exit(0)


def _work(request: dict, fds: list[int]) -> None:
    """The worker: become the client's job (its stdio, directory,
    environment and arguments), run it, report its usage. Never returns."""
    for target, fd in zip((0, 1, 2), fds):
        os.dup2(fd, target)
        os.close(fd)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)
    os.chdir(request["cwd"])
    os.environ.clear()
    os.environ.update(request["env"])
    _limit_threads(request["env"])
    code = 1
    try:
        from denali_pipe.cli import main

        code = main(request["argv"])
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        traceback.print_exc()
    finally:
        own = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu_s = own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime
        usage = {"cpu_s": round(cpu_s, 2), "max_rss_mb": round(max(own.ru_maxrss, children.ru_maxrss) / 1024, 1)}
        print(f"{USAGE_PREFIX}{json.dumps(usage)}", file=sys.stderr)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def _limit_threads(env: dict[str, str]) -> None:
    """Give the loaded thread pools the job's sizes. Snakemake tells a job its
    `threads:` through OMP_NUM_THREADS and OPENBLAS_NUM_THREADS, which
    OpenMP and OpenBLAS read when they load, and the server loaded them
    before any job: without this a 1-thread job's linear algebra would run
    on every core, and add in another order than the same job afresh."""
    from threadpoolctl import threadpool_limits

    limits = {api: int(env[var]) for api, var in THREAD_VARIABLES.items() if env.get(var, "").isdigit()}
    if limits:
        threadpool_limits(limits)
    if "openmp" in limits and "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(limits["openmp"])


def main() -> None:
    p = argparse.ArgumentParser(description="the warm-start server (started by the workflow; see the module docstring)")
    p.add_argument("socket", type=Path, help="UNIX socket to listen on")
    p.add_argument("--owner", type=int, required=True, help="pid of the Snakemake run; the server exits with it")
    args = p.parse_args()
    serve(args.socket, args.owner)


if __name__ == "__main__":
    main()
