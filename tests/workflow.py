"""Helpers to run the real Snakemake workflow in a scratch copy of the repository."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from conftest import REPO

WORKFLOW_FILES = ("Snakefile", "rules", "config", "profiles", "envs", "report")


def copy_workflow(dest: Path) -> Path:
    """A scratch working copy of the workflow (code comes from the installed package)."""
    for name in WORKFLOW_FILES:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dest / name)
        else:
            shutil.copy2(src, dest / name)
    return dest


def snakemake(workdir: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    """Run the venv's snakemake in `workdir` by its path, the venv left OFF
    PATH (as for a user who never activated it): the rules must reach the
    project through the interpreter that runs the workflow."""
    venv_bin = str(Path(sys.executable).parent)
    env = {**os.environ, "PATH": os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep) if p != venv_bin)}
    proc = subprocess.run(
        [str(Path(sys.executable).parent / "snakemake"), *args],
        cwd=workdir, env=env, capture_output=True, text=True,
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}")
    return proc


def job_counts(out: str) -> dict[str, int]:
    """{rule: jobs, "total": n} from the job-stats table Snakemake prints."""
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, re.M)}
