"""The warm-start server: a job handed to it behaves as the same job run
afresh (output, exit status, files), and cancelling the client cancels it."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from denali_pipe.cli import warm_start
from denali_pipe.core import geometry as geo
from denali_pipe.train.dataset import write_dataset

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="warm start is Linux only")

# A server whose jobs sleep: `denali SECONDS CODE` sleeps, writes its pid to
# ./pid, prints to both streams and exits CODE. Nothing preloaded (fast).
SLEEPER = """
import os, sys, time
from pathlib import Path
import denali_pipe.cli as cli
from denali_pipe.cli import warm_start

def main(argv):
    Path("pid").write_text(str(os.getpid()))
    print("out", os.environ.get("JOB_NAME"))
    print("err", file=sys.stderr)
    time.sleep(float(argv[0]))
    return int(argv[1])

cli.main = main
warm_start.PRELOAD = ()
warm_start.serve(Path(sys.argv[1]), int(sys.argv[3]))
"""


def start_server(socket_path: Path, command: list[str], owner: int | None = None) -> subprocess.Popen:
    """`command SOCKET --owner PID` (this process unless `owner`), once it listens."""
    server = subprocess.Popen([*command, str(socket_path), "--owner", str(owner or os.getpid())])
    deadline = time.monotonic() + 120
    while not socket_path.exists():
        assert server.poll() is None, "the server died while starting"
        assert time.monotonic() < deadline, "the server did not start"
        time.sleep(0.1)
    return server


@pytest.fixture
def sleeper(tmp_path):
    socket_path = tmp_path / "socket"
    server = start_server(socket_path, [sys.executable, "-c", SLEEPER])
    yield socket_path
    server.terminate()
    server.wait(10)


def client(socket_path: Path | None, cwd: Path, *argv: str, env: dict | None = None, **popen) -> subprocess.Popen:
    env = {**os.environ, "JOB_NAME": "job7", **(env or {})}
    env.pop(warm_start.ENV, None)
    if socket_path is not None:
        env[warm_start.ENV] = str(socket_path)
    return subprocess.Popen([sys.executable, "-m", "denali_pipe.cli", *argv], cwd=cwd, env=env, text=True, **popen)


def test_no_server_means_the_job_runs_itself(tmp_path, monkeypatch):
    monkeypatch.delenv(warm_start.ENV, raising=False)
    assert warm_start.hand_off(["targets"]) is None
    monkeypatch.setenv(warm_start.ENV, str(tmp_path / "nobody-listens"))
    assert warm_start.hand_off(["targets"]) is None


def test_the_worker_takes_the_clients_streams_directory_environment_and_exit_status(sleeper, tmp_path):
    job = client(sleeper, tmp_path, "0", "3", stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = job.communicate(timeout=60)
    assert job.returncode == 3
    assert out == "out job7\n"
    assert err.startswith("err\n") and warm_start.USAGE_PREFIX in err
    usage = warm_start.worker_usage(err)
    assert set(usage) == {"cpu_s", "max_rss_mb"} and usage["max_rss_mb"] > 0
    assert warm_start.worker_usage("a job that ran afresh\n") is None
    assert int((tmp_path / "pid").read_text()) != job.pid  # it ran in the server's worker


# A server that preloaded numpy and torch (their pools sized for every core):
# its jobs print the pool sizes they run with.
POOLS = """
import sys
from pathlib import Path
import denali_pipe.cli as cli
from denali_pipe.cli import warm_start

def main(argv):
    import torch
    from threadpoolctl import threadpool_info
    blas = {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}
    print(sorted(blas), torch.get_num_threads())
    return 0

cli.main = main
warm_start.PRELOAD = ("numpy", "torch")
warm_start.serve(Path(sys.argv[1]), int(sys.argv[3]))
"""


def test_the_worker_runs_with_the_thread_pools_its_job_was_given(tmp_path):
    socket_path = tmp_path / "socket"
    server = start_server(socket_path, [sys.executable, "-c", POOLS])
    try:
        sizes = {}
        for threads in ("1", "2"):
            job = client(
                socket_path, tmp_path, env={"OMP_NUM_THREADS": threads, "OPENBLAS_NUM_THREADS": threads}, stdout=subprocess.PIPE, stderr=subprocess.PIPE
            )
            out, err = job.communicate(timeout=60)
            assert job.returncode == 0 and warm_start.USAGE_PREFIX in err, err
            sizes[threads] = out.strip()
    finally:
        server.terminate()
        server.wait(10)
    assert sizes == {"1": "[1] 1", "2": "[2] 2"}


def test_a_signal_to_the_client_stops_the_worker(sleeper, tmp_path):
    job = client(sleeper, tmp_path, "60", "0", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = wait_for_pid(tmp_path / "pid")
    job.send_signal(signal.SIGTERM)
    assert job.wait(timeout=20) == 128 + signal.SIGTERM
    assert not alive(worker)


def test_a_killed_client_takes_its_worker_with_it(sleeper, tmp_path):
    job = client(sleeper, tmp_path, "60", "0", stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = wait_for_pid(tmp_path / "pid")
    job.kill()
    job.wait(timeout=20)
    deadline = time.monotonic() + 20
    while alive(worker):
        assert time.monotonic() < deadline, "the worker outlived its killed client"
        time.sleep(0.1)


def test_the_server_exits_with_its_owner(tmp_path):
    owner = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    socket_path = tmp_path / "socket"
    server = start_server(socket_path, [sys.executable, "-c", SLEEPER], owner=owner.pid)
    owner.kill()
    owner.wait()
    assert server.wait(timeout=10 * warm_start.OWNER_POLL_S) == 0
    assert not socket_path.exists()


def test_stop_leaves_a_socket_it_did_not_make_alone(tmp_path, monkeypatch):
    """A run with the warm start off ends with `stop` too: a socket named in
    the environment it inherited (a crashed run's, or anything a shell set)
    is not its to remove, nor is the folder around it."""
    inherited = tmp_path / "inherited" / "socket"
    inherited.parent.mkdir()
    inherited.touch()
    (inherited.parent / "other file").touch()
    monkeypatch.setenv(warm_start.ENV, str(inherited))
    warm_start.start(False, tmp_path / "warm_start.log")
    warm_start.stop()
    assert inherited.exists() and (inherited.parent / "other file").exists() and os.environ[warm_start.ENV] == str(inherited)


def test_a_training_cell_run_warm_writes_what_it_writes_afresh(tmp_path):
    """The real server (PRELOAD imported) against a fresh interpreter, on one
    small cell: the same metrics, curves and weights."""
    rng = np.random.default_rng(3)
    rows = [
        {"set": f"A_{size}_3x3_lighton", "object": "A", "class": "A", "type": "letter", "size": size, "light": "lighton", "location": k, "repeat": r}
        for size in ("4inch", "8inch") for k in range(0, geo.N_LOCATIONS, 5) for r in range(2)
    ]  # fmt: skip
    samples = pd.DataFrame(rows)
    xy = geo.tag1_position(samples["location"].to_numpy())
    samples = samples.assign(x=xy[:, 0], y=xy[:, 1])
    x = rng.poisson(5.0, size=(len(samples), 3, 3, 16)).astype(np.float32)
    write_dataset(x, samples, tmp_path / "3x3.zarr", tmp_path / "3x3.parquet", crop_start=70)
    cell = {"model": "cnn1d", "task": "location", "split": "random", "resolution": "3x3", "condition": "all", "protocol": "clean", "seed": 42}
    hyper = {"lr": 1e-3, "epochs": 2, "batch_size": 16, "norm": "raw"}
    argv = ["train", "3x3.zarr", "--table", "3x3.parquet", "--cell", json.dumps(cell), "--hyper", json.dumps(hyper)]
    argv += ["--factory", "denali_pipe.train.models:cnn1d", "--validation-fraction", "0.2", "--threads", "1"]

    socket_path = tmp_path / "socket"
    server = start_server(socket_path, [sys.executable, "-m", "denali_pipe.cli.warm_start"])
    try:
        runs = {}
        for name, path in (("fresh", None), ("warm", socket_path)):
            job = client(path, tmp_path, *argv, "--outdir", name, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            _, err = job.communicate(timeout=300)
            assert job.returncode == 0, err
            assert (warm_start.USAGE_PREFIX in err) == (path is not None)
            runs[name] = tmp_path / name
    finally:
        server.terminate()
        server.wait(10)
    timings = ("train_seconds", "inference_seconds", "train_samples_per_second", "inference_samples_per_second")
    fresh, warm = ({k: v for k, v in json.loads((runs[n] / "metrics.json").read_text()).items() if k not in timings} for n in ("fresh", "warm"))
    assert fresh == warm
    assert (runs["fresh"] / "curves.csv").read_text() == (runs["warm"] / "curves.csv").read_text()
    a, b = (torch.load(runs[n] / "model.pt", weights_only=True)["model"] for n in ("fresh", "warm"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def wait_for_pid(path: Path) -> int:
    deadline = time.monotonic() + 30
    while not path.exists() or not path.read_text():
        assert time.monotonic() < deadline, "the job never started"
        time.sleep(0.05)
    return int(path.read_text())


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie waiting for its watcher counts as gone
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except (FileNotFoundError, ProcessLookupError):  # reaped between the two looks: /proc answers ESRCH mid-read
        return False
