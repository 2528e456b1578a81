#!/usr/bin/env python
"""Benchmark the synthetic capture rig; prints figures, asserts nothing.

    python scripts/bench_rig.py            # tiny preset
    python scripts/bench_rig.py --demo     # also the demo preset's full raw tree (minutes)

Each preset runs in a scratch copy of the workflow. Per-job peak memory comes
from the rig rule's Snakemake `benchmark:` files (max_rss, MB).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def run(wd: Path, *args: str) -> tuple[float, str]:
    env = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}"}
    t = time.perf_counter()
    proc = subprocess.run([str(BIN / "snakemake"), *args], cwd=wd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"snakemake {' '.join(args)} failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return time.perf_counter() - t, proc.stdout


def scratch() -> Path:
    wd = Path(tempfile.mkdtemp(prefix="denali-bench-"))
    for name in ("Snakefile", "rules", "config", "profiles", "envs", "report"):
        (shutil.copytree if (REPO / name).is_dir() else shutil.copy2)(REPO / name, wd / name)
    return wd


def tree_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def bench_tree(preset: list[str], label: str, cores: int) -> None:
    wd = scratch()
    try:
        # the default target, cut after the rig: only the raw tree is written
        secs, _ = run(wd, "--cores", str(cores), "--until", "rig", *preset)
        rss = pd.concat([pd.read_csv(p, sep="\t") for p in (wd / "benchmarks/rig").glob("*.tsv")])
        raw = wd / "data/raw"
        n_sets = sum(1 for _ in raw.iterdir())
        print(
            f"{label}: raw tree of {n_sets} sets, {tree_bytes(raw) / 1e9:.2f} GB, "
            f"written in {secs:.1f} s on {cores} cores ({len(rss)} rig jobs); "
            f"peak memory per rig job {rss.max_rss.max():.0f} MB (median {rss.max_rss.median():.0f} MB), "
            f"job wall time median {rss.s.median():.1f} s, max {rss.s.max():.1f} s"
        )
    finally:
        shutil.rmtree(wd)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", action="store_true", help="also write the demo preset's raw tree")
    ap.add_argument("--cores", type=int, default=2)
    args = ap.parse_args()
    bench_tree(["--configfile", "config/presets/tiny.yaml"], "tiny", args.cores)
    if args.demo:
        bench_tree([], "demo", args.cores)


if __name__ == "__main__":
    main()
