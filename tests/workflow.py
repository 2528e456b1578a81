"""Helpers to run the real Snakemake workflow in a scratch copy of the repository."""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

from conftest import REPO

WORKFLOW_FILES = ("Snakefile", "rules", "config", "profiles", "envs", "report", "examples")
TABLE5 = "results/table5.csv"
# The tiny preset cut to what still draws every Table 5 split and task: three
# base shapes (shape_held_out tests one and carves validation from the other
# two), both sizes (size_held_out), one resolution and lighting (Table 5 is
# 3x3 and pools lightings; the calibration needs lights on), six gantry
# locations (location_held_out: 4 train, 1 of them validation, 2 test), one
# epoch. The end-to-end runs that need Table 5 only (the sources, SLURM) use it.
REDUCED = {
    "objects": ["1", "A", "circle"],
    "resolutions": ["3x3"],
    "lightings": ["lighton"],
    "rig": {"n_locations": 6},
    "train": {"max_epochs": 1},
}


def copy_workflow(dest: Path) -> Path:
    """A scratch working copy of the workflow (code comes from the installed package)."""
    for name in WORKFLOW_FILES:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dest / name)
        else:
            shutil.copy2(src, dest / name)
    return dest


def reduced_configfiles(workdir: Path, **settings) -> tuple[str, ...]:
    """`--configfile` arguments for a Table 5 run on REDUCED: the tiny preset,
    then REDUCED with `settings` merged over it key by key (written to
    `workdir`/reduced.yaml)."""
    import copy

    import yaml
    from snakemake.utils import update_config

    config = copy.deepcopy(REDUCED)
    update_config(config, settings)
    (workdir / "reduced.yaml").write_text(yaml.safe_dump(config))
    return ("--configfile", "config/presets/tiny.yaml", "reduced.yaml")


def snakemake_command(*args: str, env: dict[str, str] | None = None) -> tuple[list[str], dict[str, str]]:
    """The venv's snakemake by its path with `args`, and the environment
    (`env` or this one) with the venv left OFF PATH (as for a user who never
    activated it): the rules must reach the project through the interpreter
    that runs the workflow."""
    venv_bin = str(Path(sys.executable).parent)
    env = dict(os.environ if env is None else env)
    env["PATH"] = os.pathsep.join(p for p in env["PATH"].split(os.pathsep) if p != venv_bin)
    return [str(Path(sys.executable).parent / "snakemake"), *args], env


def snakemake(workdir: Path, *args: str, check: bool = True, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run snakemake (`snakemake_command`) in `workdir` to its end."""
    command, env = snakemake_command(*args, env=env)
    proc = subprocess.run(command, cwd=workdir, env=env, capture_output=True, text=True)
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    return proc


def start_snakemake(workdir: Path, *args: str) -> subprocess.Popen:
    """Start snakemake (`snakemake_command`) in `workdir` and return at once;
    its output goes to `workdir`/snakemake.out."""
    command, env = snakemake_command(*args)
    with open(workdir / "snakemake.out", "w") as out:
        return subprocess.Popen(command, cwd=workdir, env=env, stdout=out, stderr=subprocess.STDOUT, text=True)


def job_counts(out: str) -> dict[str, int]:
    """{rule: jobs, "total": n} from the job-stats table Snakemake prints."""
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, re.M)}


def dry_run_jobs(workdir: Path, *args: str) -> dict[str, int]:
    """Job counts of `snakemake -n --quiet rules <args>` in `workdir`, run
    inside this process (see `dry_runs`). AssertionError with Snakemake's
    output when the DAG does not build."""
    from snakemake import cli

    out, code = io.StringIO(), None
    with contextlib.chdir(workdir), contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            cli.main(["-n", "--quiet", "rules", *args])
        except SystemExit as e:
            code = e.code
    if code != 0:
        raise AssertionError(f"snakemake -n {' '.join(args)} failed ({code}):\n{out.getvalue()[-4000:]}")
    return job_counts(out.getvalue())


def _jobs_or_failure(workdir: Path, args: tuple[str, ...]) -> dict[str, int] | str:
    try:
        return dry_run_jobs(workdir, *args)
    except AssertionError as e:
        return str(e)


def dry_runs(workdir: Path, argsets: list[tuple[str, ...]], workers: int = 2) -> list[dict[str, int] | str]:
    """`dry_run_jobs` for each argument list: job counts, or the failure's
    text for a DAG that does not build. `workers` fresh interpreters (spawned:
    none of this process's state, threads or locks comes along) build the
    DAGs one after another without restarting: a DAG then costs 0.3-1.5
    CPU-seconds instead of the 3-4 of a `snakemake` command, whose
    interpreter start and imports dominate."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=context) as pool:
        return list(pool.map(partial(_jobs_or_failure, workdir), argsets))


def merged_config(workdir: Path, *configfiles: str) -> dict:
    """config/config.yaml with `configfiles` (relative to `workdir`) merged
    over it in order and the schema's defaults filled in: the config a run's
    jobs see."""
    import yaml
    from snakemake.utils import update_config, validate

    cfg = yaml.safe_load((workdir / "config/config.yaml").read_text())
    for path in configfiles:
        update_config(cfg, yaml.safe_load((workdir / path).read_text()))
    validate(cfg, str(workdir / "config/schema.yaml"))
    return cfg
