#!/usr/bin/env python
"""Benchmark the sim-to-real transform fit; prints figures, asserts nothing.

    python scripts/bench_fit.py                 # results/ of the demo run (features and twins must exist)
    python scripts/bench_fit.py --root /work/scratch_fit --threads 1

Times, on the 3x3 light-on base-object features under <root>/results/features
and their twins under <root>/results/twin, what `denali fit-transforms` does:
reading and pairing the stores with the split, and the fit (scale, blur,
noise); prints the fitted parameters and the peak resident memory.
The issue's target: the whole fit in at most 2 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np
import torch
import yaml

from denali_pipe.capture_sets import parse_set_name
from denali_pipe.objects import load_catalogue
from denali_pipe.transforms import build_pairs, fit_transforms, split_pairs

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    p = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    p.add_argument("--root", default=str(REPO), help="workflow folder holding results/ (default: the repository)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    root = Path(args.root)
    catalogue = load_catalogue(REPO / cfg["objects_sheet"])
    features, twins = [], set()
    for path in sorted((root / "results/features").glob("*_3x3_lighton.zarr")):
        cs = parse_set_name(path.name.removesuffix(".zarr"))
        if cs.object in catalogue and catalogue[cs.object].variant == "base":
            features.append(path)
            twins.add(root / f"results/twin/{cs.object}_{cs.size}.zarr")
    twins = sorted(twins)
    if not features or not all(t.exists() for t in twins):
        raise SystemExit(f"{root}/results: needs 3x3 light-on features and their twins (missing: {[str(t) for t in twins if not t.exists()][:5]})")
    fit = cfg["fit"]

    t0 = time.perf_counter()
    pairs = build_pairs(features, twins)
    split = split_pairs(pairs.keys, cfg["seed"], fit["test_fraction"])
    train = pairs.subset(split.train)
    t1 = time.perf_counter()
    t = fit_transforms(train)
    t2 = time.perf_counter()

    print(f"{len(features)} sets, {len(pairs.real)} captures x {pairs.real.shape[1]} repeats, {pairs.bins} bins from {pairs.crop_start}; fit on {len(split.train)} training captures")
    print(f"read + pair + split  {t1 - t0:7.2f} s")
    print(f"fit                  {t2 - t1:7.2f} s   a = {t.a:.6g}, gamma = {t.gamma:.4f}, a_noise = {t.a_noise:.4f}, b_noise = {t.b_noise:.1f} counts^2")
    print(f"                                kernel = {np.round(t.kernel, 4).tolist()}")
    print(f"total                {t2 - t0:7.2f} s   ({args.threads} torch threads; target <= 120 s on 2 cores)")
    print(f"peak RSS             {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.0f} MiB")


if __name__ == "__main__":
    main()
