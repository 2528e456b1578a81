"""Table 2 of the 1D CNN alone (the tiny preset cut to REDUCED) on a real
single-node SLURM cluster, through `profiles/slurm`: every job is a SLURM
job, a job killed by SLURM fails alone (--keep-going), and the rerun runs
exactly that job and its dependents. One model's three cells, not Table 5's
thirteen: every kind of submission is there, and each cell's submission
costs a fresh Snakemake and a fresh `denali` (no warm start on a cluster)."""

import json
import re
import subprocess
import threading
import time
from datetime import datetime

import pandas as pd
import pytest
from slurm_cluster import SlurmUnavailable, local_slurm
from workflow import copy_workflow, job_counts, merged_config, reduced_configfiles, snakemake

from denali_pipe.core.geometry import N_BINS
from denali_pipe.workflow import costs

pytestmark = pytest.mark.slurm
TABLE2 = "results/table2.csv"
# Table 2 of the 1D CNN only: the other models left out of the config
ONE_MODEL = {"models": {"mlp": None, "cnn3d": None, "transformer": None}}
# the cell SLURM kills: nothing but Table 2 depends on it
VICTIM = "clean_3x3_all_random_cnn1d_location_42"
VICTIM_DIR = "results/runs/clean/3x3/all/random/cnn1d_location/seed42"
# Requests follow the measured costs, not the floors (config `cluster`); a
# shared test machine can stretch a job's wall time far past its CPU time.
CLUSTER = {"min_runtime_min": 1, "min_mem_mb": 1, "runtime_headroom": 100}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    try:
        with local_slurm(tmp_path_factory.mktemp("slurm")) as c:
            yield c
    except SlurmUnavailable as e:
        pytest.skip(str(e))


def submissions(log: str) -> dict[int, str]:
    """{SLURM job id: rule_<name> or group_<name>_<rules>} of every submission Snakemake logged."""
    return {int(m[1]): m[2] for m in re.finditer(r"submitted with SLURM jobid (\d+) \(log: \S*/slurm_logs/(\w+)/", log)}


def cancel_when_queued(comment: str, stop: threading.Event) -> list[int]:
    """scancel the SLURM job whose comment names `comment` as soon as it is queued."""
    cancelled = []
    while not stop.is_set() and not cancelled:
        queue = subprocess.run(["squeue", "-h", "-o", "%i %k"], capture_output=True, text=True).stdout
        for line in queue.splitlines():
            job_id, _, job_comment = line.partition(" ")
            if job_comment.endswith(comment):
                subprocess.run(["scancel", job_id], check=True)
                cancelled.append(int(job_id))
        time.sleep(0.5)
    return cancelled


def expected_requests(wd, configfiles: tuple[str, ...], cell_dir: str) -> tuple[int, int]:
    """(runtime minutes, mem MB) a 3x3 1D CNN cell should ask for: its rule's
    cost table entry (config/costs.yaml) for its dataset (every planned sample
    is in the random split's train, validation or test part) times its epochs."""
    cfg = merged_config(wd, *configfiles)
    table = costs.load_costs(wd / cfg["cluster"]["costs"])
    m = json.loads((wd / cell_dir / "metrics.json").read_text())
    samples = m["n_train"] + m["n_validation"] + m["n_test"]
    work = costs.training_work(samples * m["hyper"]["epochs"])
    work["hist"] = float(samples * 9 * N_BINS)
    model = costs.cost_model(table, "train", m["cell"]["model"], m["cell"]["task"])
    return (
        costs.runtime_minutes(costs.predict(model["cpu_s"], work), cfg["cluster"]),
        costs.mem_mb(costs.predict(model["rss_mb"], work), cfg["cluster"]),
    )


def slurm_time(field: str, job: str) -> datetime:
    return datetime.fromisoformat(re.search(rf"\b{field}=(\S+)", job)[1])


def mtimes(wd) -> dict[str, int]:
    return {str(p.relative_to(wd)): p.stat().st_mtime_ns for p in (wd / "results").rglob("*") if p.is_file()}


def test_table2_on_slurm_and_a_killed_job_reruns_alone(cluster, tmp_path):
    wd = copy_workflow(tmp_path)
    config = reduced_configfiles(wd, cluster=CLUSTER, train=ONE_MODEL)
    run = ("--profile", "profiles/slurm", *cluster.snakemake_args, "--jobs", "4")

    stop = threading.Event()
    cancelled: list[int] = []
    killer = threading.Thread(target=lambda: cancelled.extend(cancel_when_queued(VICTIM, stop)))
    killer.start()
    start = time.perf_counter()
    try:
        first = snakemake(wd, TABLE2, *run, "--keep-going", *config, check=False)
    finally:
        stop.set()
        killer.join()
    first_s = time.perf_counter() - start
    log = first.stdout + first.stderr
    assert first.returncode != 0 and len(cancelled) == 1, log[-3000:]
    assert f"SLURM-job '{cancelled[0]}' failed" in log
    assert not (wd / TABLE2).exists() and not (wd / VICTIM_DIR / "metrics.json").exists()

    # every job ran as a SLURM job: slurmctld accepted each submission and saw
    # each end (the killed one may have been cancelled before it started)
    jobs = submissions(log)
    assert set(jobs) == cluster.job_ids_submitted() and cancelled[0] in jobs
    assert set(jobs) - set(cancelled) <= cluster.job_ids_completed()
    # the profile's groups batch the DAG's capture and feature jobs into fewer submissions
    kinds = {re.sub(r"_(ingest|poses|rig|preprocess)", "", name) for name in jobs.values()}
    assert {"group_capture", "group_features", "rule_crop_window", "rule_calibrate", "rule_dataset", "rule_train"} == kinds
    assert len(jobs) < 30

    # the rerun: exactly the killed cell and Table 2, nothing else touched
    dry = snakemake(wd, TABLE2, "-n", *config).stdout
    counts = job_counts(dry)
    assert counts == {"train": 1, "table2": 1, "total": 2}
    assert VICTIM_DIR in dry
    before = mtimes(wd)
    start = time.perf_counter()
    second = snakemake(wd, TABLE2, *run, *config)
    print(f"SLURM: first run {len(jobs)} SLURM jobs in {first_s:.0f} s; rerun {time.perf_counter() - start:.0f} s")
    rerun = submissions(second.stdout + second.stderr)
    assert sorted(rerun.values()) == ["rule_table2", "rule_train"]
    assert set(rerun) <= cluster.job_ids_completed() and not set(rerun) & set(jobs)
    # the cell asked SLURM for its rule's measured cost at this scale (slurmctld keeps it MinJobAge = 300 s)
    train_id = next(i for i, name in rerun.items() if name == "rule_train")
    job = subprocess.run(["scontrol", "show", "job", str(train_id)], capture_output=True, text=True, check=True).stdout
    runtime, mem = expected_requests(wd, config[1:], VICTIM_DIR)
    assert f"TimeLimit={runtime // 60:02d}:{runtime % 60:02d}:00" in job and re.search(rf"TRES=cpu=1,mem={mem}M", job), (runtime, mem, job)
    # a submission's cost: SLURM's queueing and the job step's own Snakemake around the cell's command
    bench = pd.read_csv(wd / "benchmarks" / f"{VICTIM_DIR}.tsv", sep="\t").iloc[0]
    queued = (slurm_time("StartTime", job) - slurm_time("SubmitTime", job)).total_seconds()
    ran = (slurm_time("EndTime", job) - slurm_time("StartTime", job)).total_seconds()
    print(f"SLURM: the cell's job queued {queued:.0f} s, ran {ran:.0f} s, of which its command {bench.s:.1f} s ({bench.cpu_time:.1f} CPU-s)")
    after = mtimes(wd)
    touched = {k for k in before if after.get(k) != before[k]}
    assert touched == set(), sorted(touched)
    assert (wd / TABLE2).exists() and (wd / VICTIM_DIR / "metrics.json").exists()
