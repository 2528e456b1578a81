"""A real single-node SLURM cluster on localhost, started and stopped by a test.

`local_slurm()` installs Debian's slurm-wlm and munge when missing, starts
munged, slurmctld and slurmd as child processes of the test, waits until the
node is idle and yields a `SlurmCluster` whose `snakemake_args`, beside
`--profile profiles/slurm`, make snakemake-executor-plugin-slurm 2.8 submit
to it (the partition is SLURM's default one).  On exit it cancels leftover jobs and stops exactly the processes it
started.

Logs and state live in `workdir` (use a fresh one, e.g. pytest's tmp_path),
except for what cannot:

* `/etc/slurm/slurm.conf`: the plugin's job step strips every SLURM_*
  variable, SLURM_CONF included, before its nested `srun`, so the config must
  sit where the tools look by default.  A config this module did not write is
  never overwritten: that raises `SlurmUnavailable`.
* sockets, in a short-named fresh directory under /tmp: Unix socket paths
  must stay under 108 bytes (slurmd's spool holds its steps' sockets), and
  munged runs as user munge, which cannot enter pytest's root-only tmp_path.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
import warnings
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

REPO = Path(__file__).resolve().parent.parent
CONF = Path("/etc/slurm/slurm.conf")
MARKER = "# written by tests/slurm_cluster.py for pid "
PARTITION = "debug"
START_TIMEOUT_S = 60
STOP_TIMEOUT_S = 10


class SlurmUnavailable(RuntimeError):
    """This machine cannot host the local cluster right now (a test may skip)."""


@dataclass(frozen=True)
class SlurmCluster:
    partition: str
    slurmctld_log: Path
    slurmd_log: Path
    snakemake_args: tuple[str, ...]

    def job_ids_submitted(self) -> set[int]:
        """Ids of the batch jobs slurmctld accepted."""
        return self._ids(r"_slurm_rpc_submit_batch_job: JobId=(\d+)")

    def job_ids_completed(self) -> set[int]:
        """Ids of the jobs slurmctld saw end after starting, successfully or not.

        Proves that work really ran as SLURM jobs, not locally.
        """
        return self._ids(r"_job_complete: JobId=(\d+) done")

    def _ids(self, pattern: str) -> set[int]:
        return {int(i) for i in re.findall(pattern, self.slurmctld_log.read_text(errors="replace"))}


def snakemake_args(cpus: int) -> tuple[str, ...]:
    """What this accounting-less one-node cluster needs on top of
    `--profile profiles/slurm` (executor, default mem_mb/runtime, job groups).
    """
    return (
        # Without accounting `sacct` fails and the default status check hangs;
        # squeue is reliable because MinJobAge=300 >= 3 x the initial wait below.
        "--slurm-status-command", "squeue",
        # The default first wait is 40 s: each short job would take a minute.
        "--slurm-init-seconds-before-status-checks", "2",
        # A group job asks for as many CPUs as its widest layer unless --cores
        # caps it; more than the node has would stay pending forever.
        "--cores", str(cpus),
    )  # fmt: skip


@contextmanager
def local_slurm(workdir: Path, cpus: int = 2, mem_mb: int | None = None) -> Iterator[SlurmCluster]:
    """Run a one-node cluster with `cpus` CPUs and `mem_mb` MB (default: 90% of RAM)."""
    if os.geteuid() != 0:
        raise SlurmUnavailable("a local SLURM cluster needs root (daemons, /etc/slurm)")
    workdir = Path(workdir).resolve()
    _install("slurm-wlm", "munge")
    _claim_conf()
    (workdir / "state").mkdir(parents=True, exist_ok=True)
    with ExitStack() as stack:
        rundir = Path(tempfile.mkdtemp(prefix="slurm-", dir="/tmp"))
        stack.callback(shutil.rmtree, rundir, ignore_errors=True)
        munge_dir = rundir / "munge"
        socket = munge_dir / "munge.socket.2"
        CONF.parent.mkdir(parents=True, exist_ok=True)
        CONF.write_text(_slurm_conf(workdir, rundir / "spool", socket, cpus, mem_mb or _default_mem_mb()))
        stack.callback(_release_conf)
        munged = _start(stack, workdir, "munged", _prepare_munged(munge_dir, socket), user="munge")
        _wait(socket.exists, workdir, [munged], "munged did not create its socket")
        daemons = [
            munged,
            _start(stack, workdir, "slurmctld", ["slurmctld", "-D"]),
            _start(stack, workdir, "slurmd", ["slurmd", "-D", "-N", "localhost"]),
        ]
        # Registered last so it runs first: jobs must end while slurmd still
        # runs, or their slurmstepd would outlive the cluster.
        stack.callback(_cancel_jobs)
        _wait(_node_idle, workdir, daemons, "the node did not become idle")
        yield SlurmCluster(
            partition=PARTITION,
            slurmctld_log=workdir / "slurmctld.log",
            slurmd_log=workdir / "slurmd.log",
            snakemake_args=snakemake_args(cpus),
        )


def _install(*packages: str) -> None:
    ensure = REPO / "scripts" / "ensure-debs"
    proc = subprocess.run([str(ensure), *packages], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{ensure} {' '.join(packages)} failed ({proc.returncode}); cannot start a local SLURM cluster:\n{proc.stderr[-2000:]}")
    if not Path("/etc/munge/munge.key").exists():
        warnings.warn("/etc/munge/munge.key was missing: creating one with mungekey", stacklevel=2)
        subprocess.run(["runuser", "-u", "munge", "--", "mungekey", "--create"], check=True)


def _claim_conf() -> None:
    """Refuse to replace a config we did not write, or one a live run still uses.

    A marked config whose writer is dead is a leftover of a killed run and may go.
    """
    if not CONF.exists():
        return
    first = CONF.read_text(errors="replace").partition("\n")[0]
    if not first.startswith(MARKER):
        raise SlurmUnavailable(f"{CONF} exists and was not written by {__name__}; not overwriting it")
    pid = int(first.removeprefix(MARKER))
    if Path(f"/proc/{pid}").exists():
        raise SlurmUnavailable(f"{CONF} is in use by another local cluster (pid {pid})")


def _release_conf() -> None:
    if CONF.exists() and CONF.read_text(errors="replace").startswith(f"{MARKER}{os.getpid()}\n"):
        CONF.unlink()


def _default_mem_mb() -> int:
    """A bit under MemTotal: room for the test itself and the daemons."""
    meminfo = Path("/proc/meminfo").read_text()
    kib = int(re.search(r"MemTotal:\s+(\d+) kB", meminfo).group(1))
    return kib // 1024 * 9 // 10


def _slurm_conf(workdir: Path, spool: Path, socket: Path, cpus: int, mem_mb: int) -> str:
    return f"""{MARKER}{os.getpid()}
ClusterName=local
SlurmctldHost=localhost
SlurmUser=root
# Auth and job credentials both use munge (the defaults), through our private munged.
AuthInfo=socket={socket}
StateSaveLocation={workdir}/state
SlurmdSpoolDir={spool}
SlurmctldPidFile={workdir}/slurmctld.pid
SlurmdPidFile={workdir}/slurmd.pid
SlurmctldLogFile={workdir}/slurmctld.log
SlurmdLogFile={workdir}/slurmd.log
# No cgroups: they are not usable in every container or VM this runs in.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
# Finished jobs stay visible to squeue this long; the plugin's squeue status check needs that.
MinJobAge=300
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
# Trust CPUs/RealMemory below even beyond the hardware, instead of draining the node.
SlurmdParameters=config_overrides
NodeName=localhost NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={mem_mb}
PartitionName={PARTITION} Nodes=localhost Default=YES MaxTime=INFINITE State=UP
"""


def _prepare_munged(munge_dir: Path, socket: Path) -> list[str]:
    """Make munged's directory; return its command, all files private to it.

    Private files leave a system munged (and /run, /var) alone.
    """
    # munged insists that every client may enter the socket's directories.
    munge_dir.parent.chmod(0o755)
    munge_dir.mkdir(mode=0o755)
    shutil.chown(munge_dir, "munge", "munge")
    return [
        "munged",
        "--foreground",
        f"--socket={socket}",
        f"--pid-file={munge_dir}/munged.pid",
        f"--log-file={munge_dir}/munged.log",
        f"--seed-file={munge_dir}/munged.seed",
    ]


def _start(stack: ExitStack, workdir: Path, name: str, cmd: list[str], user: str | None = None) -> subprocess.Popen:
    """Start a daemon and register its stop.

    Its own process group keeps a Ctrl-C in the terminal from killing it
    before the orderly stop; its output goes to `<name>.out` for errors.
    """
    with open(workdir / f"{name}.out", "wb") as out:
        proc = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            process_group=0,
            user=user,
            group=user,
            extra_groups=[] if user else None,
        )
    stack.callback(_stop, proc)
    return proc


def _stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    try:
        proc.wait(STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _cancel_jobs() -> None:
    """Cancel what a test left queued or running, and give it time to end."""
    subprocess.run(["scancel", f"--partition={PARTITION}"], capture_output=True)
    deadline = time.monotonic() + STOP_TIMEOUT_S
    while (
        time.monotonic() < deadline
        and subprocess.run(["squeue", "-h", "-o", "%i", "--states=PENDING,RUNNING,COMPLETING"], capture_output=True, text=True).stdout.strip()
    ):
        time.sleep(0.25)


def _node_idle() -> bool:
    sinfo = subprocess.run(["sinfo", "-h", "-o", "%t"], capture_output=True, text=True)
    return sinfo.stdout.strip() == "idle"


def _wait(ready: Callable[[], bool], workdir: Path, daemons: list[subprocess.Popen], what: str) -> None:
    """Poll `ready()`; fail fast when a daemon died, showing the daemons' output."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline and all(d.poll() is None for d in daemons):
        if ready():
            return
        time.sleep(0.25)
    tails = "\n".join(f"--- {out.name} ---\n" + "\n".join(out.read_text(errors="replace").splitlines()[-15:]) for out in sorted(workdir.glob("*.out")))
    raise RuntimeError(f"local SLURM failed to start: {what}\n{tails}")
