#!/usr/bin/env python
"""Benchmark the DAG at paper scale; prints figures, asserts nothing.

    python scripts/bench_dag.py [--repeats 3]

`snakemake -n` for the paper preset with every table and figure (`rule all`)
in a scratch copy of the workflow with no outputs yet: wall time of the whole
command (interpreter start, parsing, config validation, DAG build), the job
count per rule.
"""

from __future__ import annotations

import argparse
import re
import shutil
import statistics

from bench_rig import run, scratch


def job_counts(out: str) -> dict[str, int]:
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, re.M)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    wd = scratch()
    try:
        times = []
        for _ in range(args.repeats):
            secs, out = run(wd, "-n", "--quiet", "rules", "--configfile", "config/presets/paper.yaml")
            times.append(secs)
        counts = job_counts(out)
        print(
            f"paper preset, every table and figure: `snakemake -n` builds a DAG of {counts['total']} jobs "
            f"in {statistics.median(times):.1f} s (median of {len(times)}; min {min(times):.1f}, max {max(times):.1f}); "
            f"targets: <= 30 s, <= 2,000 jobs"
        )
        print("jobs per rule: " + ", ".join(f"{r} {n}" for r, n in counts.items() if r != "total"))
    finally:
        shutil.rmtree(wd)


if __name__ == "__main__":
    main()
