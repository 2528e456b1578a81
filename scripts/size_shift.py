#!/usr/bin/env python
"""Why a localiser trained on one object size misses on the other: its test
errors' bias, and whether an input blind to amplitude removes it. Prints
figures, asserts nothing.

    python scripts/size_shift.py [--results results] [--seeds 42 43 44] [--splits random size_held_out]

Retrains the benchmark model's clean 3x3 location cells (config `train`'s
settings for it, its `max_epochs`, bfloat16 where the CPU has AMX, as the
workflow's cells) on `results/datasets/3x3.*`, twice per split and seed:

- `raw`: the workflow's input (the model's configured normalisation);
- `rms`: each sample divided by its own root mean square over zones and
  bins, so that a uniformly brighter object (a larger one: its return
  scales with its area) gives the same input.

For each it prints the test and the best validation RMSE (m), and the test
errors' mean (m, x and y) and slope against the true coordinate: a slope
below 0 is a prediction drawn toward the middle of the workspace as the
truth moves away from it. Validation picks between the two inputs; the test
only measures (issue 40's rule).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import torch
import yaml

from denali_pipe.train import training as T
from denali_pipe.train.cells import Cell
from denali_pipe.train.conditions import condition_view
from denali_pipe.train.dataset import read_dataset
from denali_pipe.train.evaluate import load_cell, predict
from denali_pipe.train.saved_cell import MODEL_FILE

REPO = Path(__file__).resolve().parents[1]


def rms_normalised(x: np.ndarray) -> np.ndarray:
    """x (N, ...) over each sample's root mean square (float32)."""
    flat = x.reshape(len(x), -1).astype(np.float64)
    scale = np.sqrt((flat**2).mean(1)).reshape(-1, *[1] * (x.ndim - 1))
    return (x / np.maximum(scale, 1e-9)).astype(np.float32)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, default=Path("results"))
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--seeds", type=int, nargs="+", default=[42, 43, 44])
    ap.add_argument("--splits", nargs="+", default=["random", "size_held_out"])
    args = ap.parse_args()
    train = yaml.safe_load(args.config.read_text())["train"]
    model = train["benchmark_model"]
    entry = train["models"][model]
    settings = dict(entry["location"])
    if train["max_epochs"] is not None:
        settings["epochs"] = min(settings["epochs"], train["max_epochs"])
    hp = T.Hyper(**settings)
    torch.set_num_threads(1)
    precision = T.training_precision(train["precision"], "cpu", T.cpu_has_amx())
    x, samples, _ = read_dataset(args.results / "datasets/3x3.zarr", args.results / "datasets/3x3.parquet")
    x, samples = condition_view(x, samples, "location", "all")
    y, _ = T.targets(samples, "location")
    for name, inputs in (("raw", np.asarray(x)), ("rms", rms_normalised(np.asarray(x)))):
        for split in args.splits:
            for seed in args.seeds:
                cell = Cell(model=model, task="location", split=split, resolution="3x3", protocol="clean", seed=seed, condition="all")
                r = T.run_cell(inputs, samples, cell, hp, train["validation_fraction"], entry["factory"], "cpu", None, precision)
                part, _ = T.partition(samples, y, cell, train["validation_fraction"])
                with tempfile.TemporaryDirectory() as tmp:
                    torch.save(r.state, Path(tmp) / MODEL_FILE)
                    err = predict(load_cell(Path(tmp)), inputs[part.test]) - y[part.test]
                val = r.curves[(r.curves.part == "validation") & (r.curves.metric == "rmse")].value.min()
                slopes = [np.polyfit(y[part.test][:, k], err[:, k], 1)[0] for k in (0, 1)]
                print(
                    f"{name:4s} {split:14s} seed {seed}: test {r.metrics.test['rmse']:.4f}, validation {val:.4f}; "
                    f"bias x {err[:, 0].mean():+.3f} y {err[:, 1].mean():+.3f}; slope x {slopes[0]:+.2f} y {slopes[1]:+.2f}",
                    flush=True,
                )


if __name__ == "__main__":
    main()
