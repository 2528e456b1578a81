"""Faults survived, each run for real on one small target of the cut-down
tiny preset (`workflow.REDUCED`): one capture set's rig job and its ingest.

- a second run in a folder a run holds is refused with Snakemake's lock message;
- one job killed (SIGKILL) mid-write: the run fails, leaving none of that job's
  outputs, and the rerun redoes it and clears its temporary;
- a file-size limit hit while a store is written: the job fails, no store
  (whole or partial) is left, and a rerun completes;
- Snakemake killed (SIGKILL) mid-job: its warm-start server follows it out,
  the rerun is refused until `--unlock`, then completes with the bytes of an
  uninterrupted run;
- the warm-start server killed (SIGKILL) mid-run, leaving its socket behind:
  the jobs run themselves and the run completes with the same bytes;
- that stale socket named in the next run's environment: that run completes.
"""

from __future__ import annotations

import os
import resource
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
from workflow import copy_workflow, reduced_configfiles, snakemake, snakemake_command, start_snakemake

from denali_pipe.cli.warm_start import ENV, worker_usage

pytestmark = pytest.mark.e2e

SET = "A_4inch_3x3_lighton"
OTHER_SET = "A_8inch_3x3_lighton"
TARGET = f"results/index/{SET}.parquet"
OUTPUTS = (f"data/raw/{SET}_NLOSdata", f"results/store/{SET}.zarr", TARGET)
RIG_LOG, INGEST_LOG = "logs/rig/A_4inch_3x3.log", f"logs/ingest/{SET}.log"
LOCK_MESSAGE = "Directory cannot be locked"
WAIT_S = 300  # a bound against a hung run, never a speed requirement


def job_logs(wd: Path) -> list[str]:
    """The rig and ingest jobs' logs that exist (a job's log appears as it starts)."""
    return [str(p.relative_to(wd)) for d in ("logs/rig", "logs/ingest") for p in sorted((wd / d).glob("*.log"))]


def run_args(wd: Path, *more: str, options: tuple[str, ...] = ()) -> tuple[str, ...]:
    """TARGET and the targets `more`, one core, `options`, the cut-down tiny
    preset (targets first: Snakemake's list options take every argument up to the next option)."""
    return (TARGET, *more, "--cores", "1", *options, *reduced_configfiles(wd))


def wait_for(condition, what: str, run=None) -> None:
    """Poll `condition` until true; fail naming `what` if `run` (a Popen) ends first or WAIT_S pass."""
    deadline = time.monotonic() + WAIT_S
    while not condition():
        if run is not None and run.poll() is not None:
            pytest.fail(f"the run ended ({run.returncode}) before {what}")
        if time.monotonic() > deadline:
            pytest.fail(f"no {what} within {WAIT_S} s")
        time.sleep(0.05)


def outputs(wd: Path) -> dict[str, bytes]:
    """Every file of the target's outputs (Snakemake's own timestamp markers left out)."""
    files = {}
    for out in OUTPUTS:
        root = wd / out
        for p in [root] if root.is_file() else sorted(root.rglob("*")):
            if p.is_file() and p.name != ".snakemake_timestamp":
                files[str(p.relative_to(wd))] = p.read_bytes()
    return files


def warm_servers(owner: int) -> list[tuple[int, int]]:
    """(pid, parent pid) of the warm-start processes of the run `owner`: the
    server (a child of the run) and the watchers and workers forked from it."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
            parent = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if b"denali_pipe.cli.warm_start" in cmd and str(owner).encode() in cmd:
            found.append((int(proc.name), parent))
    return found


def server_of(owner: int) -> tuple[int, Path] | None:
    """(pid, socket) of run `owner`'s warm-start server (its command line names the socket), or None."""
    for pid, parent in warm_servers(owner):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if parent == owner:
            return pid, Path(cmd[cmd.index(b"denali_pipe.cli.warm_start") + 1].decode())
    return None


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run of TARGET, and the result of a second run of it
    started in the same folder while the first held its lock."""
    wd = copy_workflow(tmp_path_factory.mktemp("reference"))
    first = start_snakemake(wd, *run_args(wd))
    wait_for(lambda: any((wd / ".snakemake/locks").glob("*")), "lock of the first run", first)
    second = snakemake(wd, *run_args(wd), check=False)
    assert first.wait(timeout=WAIT_S) == 0, (wd / "snakemake.out").read_text()[-3000:]
    return wd, second


def test_a_second_run_in_a_folder_a_run_holds_is_refused_with_the_lock_message(reference):
    wd, second = reference
    assert second.returncode != 0 and LOCK_MESSAGE in second.stdout + second.stderr
    # and the first run finished undisturbed
    got = outputs(wd)
    assert TARGET in got and any(k.endswith("spad_histogram/000.npy") for k in got) and any(k.endswith("zarr.json") for k in got)


def test_snakemake_killed_mid_job_then_rerun_writes_the_same_bytes(reference, tmp_path):
    wd = copy_workflow(tmp_path)
    run = start_snakemake(wd, *run_args(wd))
    server = {}

    def rig_started():
        server["socket"] = (server_of(run.pid) or (None, server.get("socket")))[1]
        return (wd / RIG_LOG).exists()

    wait_for(rig_started, "rig job", run)
    run.send_signal(signal.SIGKILL)
    run.wait()
    # the warm-start server sees its owner gone and exits (OWNER_POLL_S), removing its socket
    wait_for(lambda: server_of(run.pid) is None, "exit of the warm-start server")
    if server["socket"] is not None:
        assert not server["socket"].exists()
        server["socket"].parent.rmdir()  # the empty folder the killed run could not remove
    assert not (wd / TARGET).exists()
    refused = snakemake(wd, *run_args(wd), check=False)
    assert refused.returncode != 0 and LOCK_MESSAGE in refused.stdout + refused.stderr and "--unlock" in refused.stdout + refused.stderr
    snakemake(wd, "--unlock", *run_args(wd))
    snakemake(wd, *run_args(wd))
    assert outputs(wd) == outputs(reference[0])


def job_processes(wd: Path, verb: str) -> list[int]:
    """The `denali <verb>` job processes running in `wd` (their working directory names the run's)."""
    pids = []
    for proc in Path("/proc").iterdir():
        try:
            cmd = (proc / "cmdline").read_bytes().split(b"\0")
            cwd = Path(os.readlink(proc / "cwd"))
        except (OSError, ValueError):
            continue
        if cwd == wd and cmd[1:4] == [b"-m", b"denali_pipe.cli", verb.encode()]:
            pids.append(int(proc.name))
    return pids


def debris(wd: Path) -> list[str]:
    """Temporary outputs (`core.atomic`'s .<name>.tmp-<pid> / .old-<pid>) left beside the outputs."""
    return sorted(
        str(p.relative_to(wd)) for d in ("data/raw", "results/store", "results/index") for p in (wd / d).glob(".*") if ".tmp-" in p.name or ".old-" in p.name
    )


def test_a_killed_job_fails_its_run_and_the_rerun_redoes_it(reference, tmp_path):
    wd = copy_workflow(tmp_path)
    run = start_snakemake(wd, *run_args(wd))
    # killed mid-write: its capture set half written under its temporary name
    wait_for(lambda: debris(wd), "rig job's temporary output", run)
    for pid in job_processes(wd, "rig"):
        os.kill(pid, signal.SIGKILL)
    assert run.wait(timeout=WAIT_S) != 0
    assert not (wd / OUTPUTS[0]).exists() and not (wd / TARGET).exists()
    snakemake(wd, *run_args(wd))
    assert outputs(wd) == outputs(reference[0])
    assert debris(wd) == []  # the redone job cleared what the killed one left


def test_a_file_size_limit_hit_in_a_store_write_fails_the_job_leaves_no_store_and_a_rerun_completes(reference, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(reference[0], wd, symlinks=True)
    # 256 KiB: a store's frame chunks are ~0.5 MB; the run's own files (logs, Snakemake's records) stay below
    limit = 256 * 1024
    command, env = snakemake_command(*run_args(wd, options=("--forcerun", "ingest")))
    limited = subprocess.run(
        command, cwd=wd, env=env, capture_output=True, text=True, preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    )
    assert limited.returncode != 0, limited.stdout[-2000:]
    assert "File too large" in (wd / INGEST_LOG).read_text()
    assert not (wd / OUTPUTS[1]).exists() and not (wd / TARGET).exists() and debris(wd) == []
    snakemake(wd, *run_args(wd))
    assert outputs(wd) == outputs(reference[0])


@pytest.fixture(scope="module")
def server_killed(tmp_path_factory):
    """A run whose warm-start server was killed (SIGKILL) once it listened.
    (workdir, the run's exit status, its socket, whether the socket was left
    behind by the kill, whether it was still there when the run ended)."""
    wd = copy_workflow(tmp_path_factory.mktemp("server_killed"))
    # a second capture set's jobs, so that there are jobs left to start after the kill
    run = start_snakemake(wd, *run_args(wd, f"results/index/{OTHER_SET}.parquet"))
    found = {}

    def server_started():
        server = server_of(run.pid)
        if server is not None:
            found["pid"], found["socket"] = server
        return server is not None

    wait_for(server_started, "warm-start server", run)
    # Snakemake held (SIGSTOP) while the server imports: on a loaded machine the
    # run could otherwise start all four jobs before it listens, leaving none to
    # meet the stale socket. One core: at most one job runs while held.
    run.send_signal(signal.SIGSTOP)
    try:
        wait_for(lambda: found["socket"].exists(), "warm-start server listening")
        os.kill(found["pid"], signal.SIGKILL)
        # a killed process runs no cleanup: its socket stays
        left = found["socket"].exists()
        started = set(job_logs(wd))
    finally:
        run.send_signal(signal.SIGCONT)
    code = run.wait(timeout=WAIT_S)
    after = {p: worker_usage((wd / p).read_text()) for p in job_logs(wd) if p not in started}
    yield wd, code, found["socket"], left, found["socket"].exists(), after
    shutil.rmtree(found["socket"].parent, ignore_errors=True)


def test_the_jobs_run_themselves_when_the_warm_start_server_is_killed(reference, server_killed):
    wd, code, _, left, at_end, after = server_killed
    assert code == 0, (wd / "snakemake.out").read_text()[-3000:]
    # the kill left the socket behind; the run's end removed it (`warm_start.stop`)
    assert left and not at_end
    # the jobs started after the kill met the stale socket and ran afresh (no warm worker's usage in their logs)
    assert after and all(usage is None for usage in after.values()), after
    assert outputs(wd) == outputs(reference[0])


def test_a_stale_socket_in_the_next_runs_environment_does_not_stop_it(reference, server_killed, monkeypatch):
    """A crashed run's socket (bound, nobody listening, as the kill above
    left it) named in the environment of the next run: with the warm start
    on, the run's own server replaces it; off, every job meets it and runs afresh."""
    import socket as sockets

    wd, _, stale, _, _, _ = server_killed
    stale.parent.mkdir(exist_ok=True)
    s = sockets.socket(sockets.AF_UNIX, sockets.SOCK_STREAM)
    s.bind(str(stale))
    s.close()
    monkeypatch.setenv(ENV, str(stale))
    for warm in ("True", "False"):  # Snakemake reads --config values as Python literals
        (wd / INGEST_LOG).unlink()
        snakemake(wd, *run_args(wd, options=("--forcerun", "ingest", "--config", f"warm_start={warm}")))
        assert (wd / INGEST_LOG).exists() and outputs(wd) == outputs(reference[0])
    assert worker_usage((wd / INGEST_LOG).read_text()) is None and stale.exists()
