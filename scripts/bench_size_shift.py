#!/usr/bin/env python
"""What makes `size_held_out` localisation extrapolate; prints a table, asserts nothing.

    python scripts/bench_size_shift.py results/datasets/3x3 --epochs 30 --seeds 42 43

The 1D CNN localiser trained on one object size and tested on the other, both
ways (4 in -> 8 in, 8 in -> 4 in), under each combination of
- the input: `raw` counts (the config's), `log_z` (signed log, z-scored on the
  training part), `per_sample` (each sample over its own summed |counts|,
  scaled by the number of values: blind to a uniform gain, but the sum is
  mostly noise and the background's residue), or `per_sample_rms` /
  `per_sample_peak` (over its root mean square / its largest |count|, which
  the object's return dominates: blind to the return's amplitude, which
  scales with the object's area);
- the targets: `metres` (the reference's), `standardised` (z-scored on
  the training part, the predictions mapped back) or `bounded` (standardised
  through the clean protocol's bounded head, `train.training.position_head`:
  a tanh into the training positions' box and half a gantry step).
With `--test-gains`, the held-out size's inputs are multiplied by each gain
before the input transform (the training part's statistics unchanged): how
the localiser would fare if the held-out size's returns were that much
dimmer or brighter against the training size's. The noise scales with them,
so a gain below 1 also makes its inputs quieter than a capture's;
`--keep-noise` adds it back: Gaussian noise of each capture's own variance
over its repeats (per zone and bin) times 1 - gain^2.
The validation part is 20 % of the training size's (set, location) capture
groups, as the clean protocol draws it for this split (`splits.validation_split`):
it shares the training size, so it cannot show the size shift itself. Each row:
validation and test RMSE (m), the training-mean predictor's test RMSE, the share
of test predictions outside the gantry's workspace and the furthest one (m), and
the test errors' mean (`bias_x`, `bias_y`, m) and slope against the true
coordinate (`slope_x`, `slope_y`): a shift, and a pull toward the middle of
the training positions when below 0.

Cited by docs/rig_zones.md, "What the localisers read, and the held-out size";
docs/deviations.md, "Training protocol" (the clean protocol's targets and head).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from denali_pipe.experiments.fig9 import localiser_precision
from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train.dataset import read_dataset
from denali_pipe.train.metrics import regression_metrics, workspace_metrics
from denali_pipe.train.models import cnn1d
from denali_pipe.train.precision import cpu_has_native_bf16
from denali_pipe.train.training import (
    Hyper,
    fit,
    infer,
    loss_for,
    position_head,
    standardise,
    target_statistics,
    to_metres,
)

INPUTS = ("raw", "log_z", "per_sample", "per_sample_rms", "per_sample_peak")
TARGETS = ("metres", "standardised", "bounded")


def model_input(kind: str, x: np.ndarray, train: np.ndarray) -> np.ndarray:
    if kind in ("raw", "log_z"):
        _, stats = normalise(x[train], kind)
        return normalise(x, kind, stats)[0]
    flat = np.abs(x).reshape(len(x), -1)
    scale = {"per_sample": flat.mean(axis=1), "per_sample_rms": np.sqrt((flat**2).mean(axis=1)), "per_sample_peak": flat.max(axis=1)}[kind]
    return (x / np.maximum(scale, 1e-6).reshape(-1, 1, 1, 1)).astype(np.float32)


def dimmed(x: np.ndarray, samples: pd.DataFrame, rows: np.ndarray, gain: float, keep_noise: bool, seed: int) -> np.ndarray:
    """x with `rows` times `gain`; with `keep_noise` (gain <= 1), plus Gaussian
    noise of each row's capture group's variance over its repeats (set,
    location; per zone and bin) times 1 - gain^2, so the noise keeps its level."""
    out = x.copy()
    out[rows] *= gain
    if keep_noise:
        group = samples.iloc[rows].groupby(["set", "location"]).ngroup().to_numpy()
        var = np.stack([x[rows[group == g]].var(axis=0, ddof=1) for g in range(group.max() + 1)])
        noise = np.random.default_rng(seed).standard_normal(out[rows].shape) * np.sqrt((1 - gain**2) * var[group])
        out[rows] += noise.astype(out.dtype)
    return out


def error_trend(pred: np.ndarray, y: np.ndarray) -> dict:
    """The errors' (N, 2) mean per coordinate (m) and their slope against the truth y (N, 2) m."""
    err = pred - y
    return {
        **{f"bias_{c}": float(err[:, k].mean()) for k, c in enumerate("xy")},
        **{f"slope_{c}": float(np.polyfit(y[:, k], err[:, k], 1)[0]) for k, c in enumerate("xy")},
    }


def size_split(samples: pd.DataFrame, train_size: str, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(train, validation, test) rows: train and validation of `train_size`, by capture group; test the other size."""
    own = np.flatnonzero(samples["size"] == train_size)
    groups = samples.iloc[own].groupby(["set", "location"]).ngroup().to_numpy()
    held = np.random.default_rng(seed).choice(np.unique(groups), int(0.2 * groups.max() + 0.2), replace=False)
    return own[~np.isin(groups, held)], own[np.isin(groups, held)], np.flatnonzero(samples["size"] != train_size)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path, help="results/datasets/<res> (the .zarr and .parquet beside each other)")
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--seeds", type=int, nargs="+", default=[42])
    p.add_argument("--inputs", nargs="+", choices=INPUTS, default=list(INPUTS))
    p.add_argument("--targets", nargs="+", choices=TARGETS, default=list(TARGETS))
    p.add_argument("--train-sizes", nargs="+", choices=["4inch", "8inch"], default=["4inch", "8inch"])
    p.add_argument("--test-gains", type=float, nargs="+", default=[1.0], help="factors on the held-out size's inputs")
    p.add_argument("--keep-noise", action="store_true", help="a dimmed held-out size keeps its noise's level")
    p.add_argument("--precision", choices=["auto", "float32", "bfloat16"], default="auto", help="as config train.precision")
    args = p.parse_args()
    if args.keep_noise and max(args.test_gains) > 1:
        p.error("--keep-noise adds noise back to a dimmed size; it cannot take it out of a brightened one (a gain above 1)")
    x, samples, _ = read_dataset(args.dataset.with_suffix(".zarr"), args.dataset.with_suffix(".parquet"))
    precision = localiser_precision(args.precision, cpu_has_native_bf16(), tuple(x.shape[1:]))
    y = samples[["x", "y"]].to_numpy(np.float32)
    totals = samples.assign(total=x.reshape(len(x), -1).sum(axis=1)).groupby("size")["total"].mean()
    print(f"mean summed counts of a sample: {totals.round(0).to_dict()}")
    rows = []
    for seed in args.seeds:
        for train_size, gain in [(size, g) for size in args.train_sizes for g in args.test_gains]:
            tr, va, te = size_split(samples, train_size, seed)
            xg = x if gain == 1.0 else dimmed(x, samples, te, gain, args.keep_noise, seed)
            for kind in args.inputs:
                xn = torch.from_numpy(np.ascontiguousarray(model_input(kind, xg, tr)))
                for targets in args.targets:
                    # the clean protocol's own standardisation and box (train.training); its first two rows alone map without the bound
                    stats = None if targets == "metres" else target_statistics("location", "clean", y[tr])[: 2 if targets == "standardised" else 4]
                    torch.manual_seed(seed)
                    model = cnn1d("location", 2, x.shape[1:])

                    def score(epoch, rows_seen, out, model=model, xn=xn, stats=stats, va=va):
                        return -regression_metrics(to_metres(infer(model, xn[va]), stats), y[va])["rmse"]

                    yt = torch.from_numpy(np.array(standardise(y, stats)))
                    fit(model, xn[tr], yt[tr], Hyper(1e-3, args.epochs, 64, kind), seed, loss_for("location"), score, name="size shift", precision=precision,
                        head=position_head(stats))  # fmt: skip
                    pv, pt = to_metres(infer(model, xn[va]), stats), to_metres(infer(model, xn[te]), stats)
                    rows.append(
                        {
                            "seed": seed, "train": train_size, "test_gain": gain, "input": kind, "targets": targets,
                            "val_rmse": regression_metrics(pv, y[va])["rmse"], "test_rmse": regression_metrics(pt, y[te])["rmse"],
                            "mean_rmse": regression_metrics(np.tile(y[tr].mean(0), (len(te), 1)), y[te])["rmse"],
                            **workspace_metrics(pt), **error_trend(pt, y[te]),
                        }
                    )  # fmt: skip
    table = pd.DataFrame(rows)
    print(table.round(3).to_string(index=False))
    print(
        table.groupby(["train", "test_gain", "input", "targets"])[
            ["val_rmse", "test_rmse", "outside_workspace", "max_outside_workspace", "bias_x", "bias_y", "slope_x", "slope_y"]
        ]
        .mean()
        .round(3)
        .to_string()
    )


if __name__ == "__main__":
    main()
