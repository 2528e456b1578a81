#!/usr/bin/env python
"""Benchmark the sim-to-real transform fit; prints figures, asserts nothing.

    python scripts/bench_fit.py                 # results/ of the demo run (features and twins must exist)
    OMP_NUM_THREADS=1 python scripts/bench_fit.py --root /work/scratch_fit   # one BLAS thread
    python scripts/bench_fit.py --recovery      # synthetic pairs of known transforms, no results/ needed
    python scripts/bench_fit.py --recovery --captures 1050 --seeds 5

Default: times, on the 3x3 light-on base-object features under
<root>/results/features and their twins under <root>/results/twin, what
`denali transforms` does: reading and pairing the stores with the split,
the fit (scale, blur, noise) and its check (the bootstrap of `fit.bootstrap`);
prints the fitted parameters, the check and the peak resident memory.
The issue's target: the whole fit in at most 2 minutes on 2 cores.

--recovery: the tests' synthetic pairs (tests/test_transforms.py's generators:
twin-like transients, a Gaussian pulse kernel 2 bins late, gamma 1.2,
a_noise 1.5, a noise floor of sd 25 counts) at median peak SNRs from 0.25 to
50, fitted and checked; per SNR, over seeds: the RMS error of each parameter
(relative; the kernel's mean L1), the mean bootstrap standard error (same
units), how often the percentile intervals cover the truth, how often each
parameter is flagged as not identified, and the seconds per fit and per check.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.core.objects import load_catalogue
from denali_pipe.transforms.sim_to_real import SCALARS, build_pairs, check_fit, fit_transforms, split_pairs

REPO = Path(__file__).resolve().parents[1]
SNRS = (0.25, 0.5, 1, 2, 3, 5, 10, 20, 50)
PARAMETERS = (*SCALARS, "kernel")


def recovery_row(snr: float, captures: int, seeds: int, boot: dict, seed: int) -> dict:
    """Per parameter of PARAMETERS, over `seeds` synthetic data sets at `snr`:
    RMS error, mean bootstrap standard error, interval coverage and flag rate,
    plus the mean seconds per fit and per check."""
    from test_transforms import rendered_like, synthetic_pairs, truth_at_snr

    err, se, cover, flagged, seconds = [], [], [], [], []
    for s in range(seeds):
        rng = np.random.default_rng(s)
        sim = rendered_like(captures, rng)
        truth = truth_at_snr(snr, sim)
        pairs = synthetic_pairs(sim, truth, rng)
        t0 = time.perf_counter()
        fit = fit_transforms(pairs)
        t1 = time.perf_counter()
        check = check_fit(pairs, fit, boot["resamples"], seed, boot["level"], boot["max_rel_se"])
        t2 = time.perf_counter()
        b = check.bootstrap
        true_kernel = np.array(truth.kernel)
        err.append([getattr(fit, p) / getattr(truth, p) - 1 for p in SCALARS] + [np.abs(np.array(fit.kernel) - true_kernel).sum()])
        se.append([b.se[p] / getattr(fit, p) for p in SCALARS] + [b.kernel_l1])
        lows, highs = np.array(b.interval["kernel"]).T
        cover.append([b.interval[p][0] <= getattr(truth, p) <= b.interval[p][1] for p in SCALARS] + [((lows <= true_kernel) & (true_kernel <= highs)).mean()])
        flagged.append([p in check.unidentified for p in PARAMETERS])
        seconds.append((t1 - t0, t2 - t1))
    err, se = np.array(err), np.array(se)
    return {
        "rms": np.sqrt((err[:, :4] ** 2).mean(axis=0)).tolist() + [err[:, 4].mean()],
        "se": se.mean(axis=0).tolist(),
        "cover": np.mean(cover, axis=0).tolist(),
        "flagged": np.mean(flagged, axis=0).tolist(),
        "seconds": np.mean(seconds, axis=0).tolist(),
    }


def recovery(captures: int, seeds: int, boot: dict, seed: int) -> None:
    # the synthetic pairs are the tests' own, so the benchmark and the tests measure one experiment
    sys.path.insert(0, str(REPO / "tests"))
    print(
        f"{captures} captures x 3 repeats per data set, {seeds} data sets per SNR; bootstrap {boot['resamples']} resamples, {boot['level']:.0%} intervals, max_rel_se {boot['max_rel_se']}"
    )
    print("error: RMS relative error (kernel: mean L1); se: mean bootstrap SE (relative; kernel: mean L1 of the refits);")
    print("cover: share of intervals holding the truth (kernel: of taps); flag: share of fits flagging it as not identified\n")
    print(f"{'SNR':>5} | " + " | ".join(f"{p:^22}" for p in PARAMETERS) + " | fit s  check s")
    print(f"{'':>5} | " + " | ".join(f"{'error    se  cov flag':^22}" for _ in PARAMETERS) + " |")
    for snr in SNRS:
        r = recovery_row(snr, captures, seeds, boot, seed)
        cells = [f"{r['rms'][i]:6.3f} {r['se'][i]:6.3f} {r['cover'][i]:4.2f} {r['flagged'][i]:4.2f}" for i in range(len(PARAMETERS))]
        print(f"{snr:5.2f} | " + " | ".join(cells) + f" | {r['seconds'][0]:5.2f}  {r['seconds'][1]:6.2f}", flush=True)


def demo(root: Path, cfg: dict) -> None:
    catalogue = load_catalogue(REPO / cfg["objects_sheet"])
    features, twins = [], set()
    for path in sorted((root / "results/features").glob("*_3x3_lighton.zarr")):
        cs = parse_set_name(path.name.removesuffix(".zarr"))
        if cs.object in catalogue and catalogue[cs.object].variant == "base":
            features.append(path)
            twins.add(root / f"results/twin_calibrated/{cs.object}_{cs.size}.zarr")
    twins = sorted(twins)
    if not features or not all(t.exists() for t in twins):
        raise SystemExit(f"{root}/results: needs 3x3 light-on features and their twins (missing: {[str(t) for t in twins if not t.exists()][:5]})")
    fit, boot = cfg["fit"], cfg["fit"]["bootstrap"]

    t0 = time.perf_counter()
    pairs = build_pairs(features, twins)
    split = split_pairs(pairs.keys, cfg["seed"], fit["test_fraction"])
    train = pairs.subset(split.train)
    t1 = time.perf_counter()
    t = fit_transforms(train)
    t2 = time.perf_counter()
    check = check_fit(train, t, boot["resamples"], cfg["seed"], boot["level"], boot["max_rel_se"])
    t3 = time.perf_counter()

    print(
        f"{len(features)} sets, {len(pairs.real)} captures x {pairs.real.shape[1]} repeats, {pairs.bins} bins from {pairs.crop_start}; fit on {len(split.train)} training captures"
    )
    print(f"read + pair + split  {t1 - t0:7.2f} s")
    print(f"fit                  {t2 - t1:7.2f} s   a = {t.a:.6g}, gamma = {t.gamma:.4f}, a_noise = {t.a_noise:.4f}, b_noise = {t.b_noise:.1f} counts^2")
    print(f"                                kernel = {np.round(t.kernel, 4).tolist()}")
    b = check.bootstrap
    print(
        f"check                {t3 - t2:7.2f} s   {b.resamples} resamples; SE: "
        + ", ".join(f"{p} {b.se[p]:.4g}" for p in SCALARS)
        + f", kernel L1 {b.kernel_l1:.4f}"
    )
    print(f"                                peak SNR {check.peak_snr:.2f}; identifiable: {check.identifiable} {check.unidentified or ''}")
    print(f"total                {t3 - t0:7.2f} s   (target <= 120 s on 2 cores)")
    print(f"peak RSS             {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:7.0f} MiB")


def main() -> None:
    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    p = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    p.add_argument("--root", default=str(REPO), help="workflow folder holding results/ (default: the repository)")
    p.add_argument("--recovery", action="store_true", help="recovery of known transforms on synthetic pairs against SNR")
    p.add_argument("--captures", type=int, default=150, help="--recovery: captures per synthetic data set")
    p.add_argument("--seeds", type=int, default=3, help="--recovery: data sets per SNR")
    args = p.parse_args()
    if args.recovery:
        recovery(args.captures, args.seeds, cfg["fit"]["bootstrap"], cfg["seed"])
    else:
        demo(Path(args.root), cfg)


if __name__ == "__main__":
    main()
