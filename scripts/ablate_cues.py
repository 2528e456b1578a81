#!/usr/bin/env python
"""Which cue a trained localiser uses: permutation ablations on its test split.
Prints figures, asserts nothing.

    python scripts/ablate_cues.py RUN_DIR [RUN_DIR ...] [--results results] [--repeats 3] [--config config/config.yaml]

RUN_DIR is a location cell (`results/runs/<protocol>/<res>/<condition>/<split>/
<model>_location/seed<N>`). Its test rows are rebuilt as the cell drew them
(`conditions.condition_view`, `splits.make_split` with the cell's seed). Each
ablation shuffles one part of the input across the test samples (the part's
marginal distribution is kept, its link to the label is cut) and reports the
RMSE (m, per coordinate) against the intact input and the mean baseline:

- `zones <group>`: the histograms of a group of zones (at 8x8 each of the
  firmware's 8 subcaptures, `geometry.zone_subcapture`; at 3x3 each zone);
- `bins a-b`: the time bins a..b of every zone;
- `amplitude`: each zone's amplitude (L2 norm over time), keeping its shape (timing);
- `timing`: each zone's shape, keeping its amplitude.
A rise says the model reads that part; none says it does not.

Cited by docs/rig_zones.md, "What the localisers read, and the held-out size".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
import zarr

from denali_pipe.core import geometry as geo
from denali_pipe.core.splits import make_split
from denali_pipe.train.conditions import condition_view
from denali_pipe.train.evaluate import load_cell, predict

BIN_WINDOW = 16  # bins per time-window ablation


def rmse(pred: np.ndarray, y: np.ndarray) -> float:
    return float(np.sqrt(np.mean((pred - y) ** 2)))


def shuffled(x: np.ndarray, rng: np.random.Generator, part) -> np.ndarray:
    """x (N, Z, T) with x[:, zones, bins] (part = (zones, bins)) drawn from another test sample."""
    index = (np.s_[:], *part)
    out = x.copy()
    out[index] = x[rng.permutation(len(x))][index]
    return out


def swap_amplitude(x: np.ndarray, rng: np.random.Generator, keep: str) -> np.ndarray:
    """x (N, Z, T) with each zone's amplitude (its L2 norm over time: never
    negative, unlike the total of background-subtracted counts) taken from
    another test sample when keep='timing', or its shape (x over its norm)
    when keep='amplitude'."""
    norm = np.linalg.norm(x, axis=-1, keepdims=True)
    shape = x / np.maximum(norm, 1e-9)
    other = rng.permutation(len(x))
    return shape * norm[other] if keep == "timing" else shape[other] * norm


def ablations(n: int, t: int) -> dict:
    zones = n * n
    groups = geo.zone_subcapture(f"{n}x{n}") if n == 8 else np.arange(zones)
    label = "subcapture" if n == 8 else "zone"
    out = {f"zones {label} {g}": (np.s_[:], np.flatnonzero(groups == g)) for g in np.unique(groups)}
    for a in range(0, t, BIN_WINDOW):
        out[f"bins {a}-{min(a + BIN_WINDOW, t) - 1}"] = (np.s_[a : a + BIN_WINDOW], None)
    return out


def run(run_dir: Path, results: Path, repeats: int, axis: geo.TimeAxis) -> None:
    trained = load_cell(run_dir)
    cell = trained.cell
    if cell.task != "location":
        raise SystemExit(f"{run_dir}: a {cell.task} cell; this script ablates location cells")
    x = zarr.open_group(results / "datasets" / f"{cell.resolution}.zarr", mode="r")["x"][...]
    samples = pd.read_parquet(results / "datasets" / f"{cell.resolution}.parquet")
    x, samples = condition_view(x, samples, cell.task, cell.condition, axis)
    test = make_split(samples, cell.split, cell.seed).test
    x, y = x[test], samples.iloc[test][["x", "y"]].to_numpy(np.float64)
    n, t = x.shape[1], x.shape[-1]
    flat = x.reshape(len(x), n * n, t)
    rng = np.random.default_rng(0)

    def score(v: np.ndarray) -> float:
        return rmse(predict(trained, v.reshape(x.shape)), y)

    base = score(flat)
    mean = rmse(np.tile(trained.baseline_output, (len(y), 1)), y)
    print(f"\n{run_dir}: {len(y)} test samples, RMSE {base:.4f} m intact, {mean:.4f} m predicting the mean")
    rows = {"amplitude (shape kept)": lambda: swap_amplitude(flat, rng, "timing"), "timing (amplitude kept)": lambda: swap_amplitude(flat, rng, "amplitude")}
    for name, (bins, zones) in ablations(n, t).items():
        rows[name] = lambda bins=bins, zones=zones: shuffled(flat, rng, (zones if zones is not None else np.s_[:], bins))
    for name, make in rows.items():
        scores = [score(make()) for _ in range(repeats)]
        print(f"  shuffle {name:28s} RMSE {np.mean(scores):.4f} m (+{np.mean(scores) - base:.4f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--results", type=Path, default=Path("results"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--config", type=Path, default=Path("config/config.yaml"), help="the run's config: its time axis blurs a jitter cell's input")
    args = ap.parse_args()
    axis = geo.TimeAxis.from_config(yaml.safe_load(args.config.read_text())["sensor"]["time_axis"])
    for run_dir in args.runs:
        run(run_dir, args.results, args.repeats, axis)


if __name__ == "__main__":
    main()
