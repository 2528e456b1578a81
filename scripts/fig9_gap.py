#!/usr/bin/env python
"""Where Fig 9's sim-to-real gap lies: in the twin or in the localiser.
Prints figures, asserts nothing.

    python scripts/fig9_gap.py [--results results] [--configfile config/config.yaml]

On Fig 9's split (`transforms.split_pairs`, the calibration's and the
transforms' seed) and per panel (`experiments.fig9.PANELS`), the test RMSE
(m) of:

- the predict-the-mean baseline;
- a 1-nearest-neighbour localiser (L2 over the panel's bins) from the
  training captures' noisy twins (`transforms` at fidelity `noisy`) to the
  real test repeats, and from the real training repeats to the same: if the
  first is near the second, the twins hold the real captures' location cue;
- Fig 9's 1D CNN (its hyperparameters, its twins' copies) trained on the
  noisy twins alone, scored on the test captures' noisy twins and on their
  real repeats: sim->sim bounds what the localiser learns from twins at all;
- on the all-zone panel, the same CNN with one zone zeroed in its twins and
  in the real test captures, zone by zone: a zone whose removal lowers the
  error on the real captures is one whose twin teaches the localiser what
  the real zone does not show.

The twins are `results/twin_calibrated`'s of the base objects, the real
captures the 3x3 light-on feature stores that have one (the fit's sets).

Cited by docs/twin.md, "Transforms and Fig 9".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import yaml

from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.core.floor import kept_bins
from denali_pipe.core.objects import load_catalogue
from denali_pipe.experiments import fig9
from denali_pipe.train.dataset import location_labels
from denali_pipe.train.metrics import predict_mean_baseline, regression_metrics
from denali_pipe.train.training import Hyper
from denali_pipe.transforms.sim_to_real import build_pairs, read_transforms, split_pairs

SEED = 42  # the model's and the noise draws' seed (Fig 9's first)


def rmse(pred: np.ndarray, y: np.ndarray) -> float:
    return regression_metrics(pred, y)["rmse"]


def nearest(train_x: np.ndarray, train_y: np.ndarray, test_x: np.ndarray) -> np.ndarray:
    """(N_test, 2) the label of each test sample's nearest training sample
    (L2 over every feature); x (N, ...) flattened per sample."""
    a, b = train_x.reshape(len(train_x), -1), test_x.reshape(len(test_x), -1)
    d = (b**2).sum(1)[:, None] - 2 * b @ a.T + (a**2).sum(1)[None, :]
    return train_y[d.argmin(1)]


def zero_zone(x: np.ndarray, row: int, col: int) -> np.ndarray:
    """A copy of samples x (N, n, n, T) with zone (row, col) zeroed."""
    out = x.copy()
    out[:, row, col] = 0
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--results", type=Path, default=Path("results"))
    p.add_argument("--configfile", type=Path, default=Path("config/config.yaml"))
    args = p.parse_args()
    cfg = yaml.safe_load(args.configfile.read_text())
    torch.set_num_threads(cfg["train"]["threads"])
    # Fig 9's sets: the base objects' (a full run also calibrates the variants' twins)
    base = {name for name, spec in load_catalogue(Path(cfg["objects_sheet"])).items() if spec.variant == "base"}
    twins = sorted(t for t in (args.results / "twin_calibrated").glob("*.zarr") if t.stem.rsplit("_", 1)[0] in base)
    with_twin = {t.stem for t in twins}
    features = []
    for f in sorted((args.results / "features").glob("*_3x3_lighton.zarr")):
        cs = parse_set_name(f.stem)
        if f"{cs.object}_{cs.size}" in with_twin:
            features.append(f)
    pairs = build_pairs(features, twins)
    zt = read_transforms(args.results / "transforms.json")
    real, sim, keys = pairs.captures()
    labels = location_labels(pd.read_parquet(args.results / "calibration/tag1_positions.parquet"))
    xy = np.array([labels[int(k)] for k in keys["location"]], np.float32)
    split = split_pairs(keys, cfg["seed"], cfg["fit"]["test_fraction"])
    f9 = cfg["fit"]["fig9"]
    hp = Hyper(**{**cfg["train"]["models"]["cnn1d"]["location"], "epochs": f9["epochs"]})
    crop = (pairs.crop_start, pairs.bins)
    repeats = real.shape[1]
    y_train, y_test = xy[split.train], np.repeat(xy[split.test], repeats, axis=0)
    print(
        f"{len(features)} sets, {len(keys)} captures ({len(split.train)} train, {len(split.test)} test) x {repeats} repeats; Fig 9's 1D CNN at {hp.epochs} epochs"
    )
    for panel in fig9.PANELS:
        r_view, s_view, zones = fig9.panel_view(real, sim, panel)
        x_test = r_view[split.test].reshape(-1, *r_view.shape[2:])
        r_train = r_view[split.train].reshape(-1, *r_view.shape[2:])
        kept = kept_bins(r_train, axis=0)
        x_sim, y_sim = fig9.sim_samples(s_view[split.train], zones, y_train, zt, "noisy", f9["sim_copies"], SEED, crop, kept)
        x_sim_test, y_sim_test = fig9.sim_samples(s_view[split.test], zones, xy[split.test], zt, "noisy", 1, SEED + 1, crop, kept)
        localiser = fig9.train_localiser(x_sim, y_sim, hp, SEED, torch.float32)
        box = fig9.workspace(y_sim)
        cnn = {name: rmse(fig9.bound_to_workspace(localiser.predict(x), *box), y) for name, x, y in (("sim", x_sim_test, y_sim_test), ("real", x_test, y_test))}
        rows = {
            "predict the mean": rmse(predict_mean_baseline(y_train, len(y_test)), y_test),
            "1-NN, noisy twins -> real": rmse(nearest(x_sim, y_sim, x_test), y_test),
            "1-NN, real -> real": rmse(nearest(r_train, np.repeat(y_train, repeats, axis=0), x_test), y_test),
            "1D CNN on noisy twins -> twins": cnn["sim"],
            "1D CNN on noisy twins -> real": cnn["real"],
        }
        print(f"\n{panel} (test RMSE, m)")
        for name, value in rows.items():
            print(f"  {name:<32}{value:.3f}")
        if len(zones) > 1:
            print("  1D CNN on noisy twins -> real, one zone zeroed in both (row, column: RMSE):")
            for r, c in np.ndindex(x_sim.shape[1:3]):
                localiser = fig9.train_localiser(zero_zone(x_sim, r, c), y_sim, hp, SEED, torch.float32)
                real_rmse = rmse(fig9.bound_to_workspace(localiser.predict(zero_zone(x_test, r, c)), *box), y_test)
                print(f"    ({r}, {c}): {real_rmse:.3f}")


if __name__ == "__main__":
    main()
