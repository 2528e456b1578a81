#!/usr/bin/env python
"""Time Table 2's training cells at the paper preset's size; prints a table, asserts nothing.

    python scripts/bench_cells.py --device cuda                  # every model and task, 2 epochs each, on the first GPU
    python scripts/bench_cells.py --models cnn1d mlp --epochs 1  # on the CPU (train.precision auto)

Each row is one real cell (`train.run_cell`: normalisation, the clean
protocol's validation part scored after every epoch, the test split scored
once) of one (model, task) with the config's hyperparameters, on a synthetic
benchmark of the paper's 3x3 size: 30 shapes x 2 sizes x 2 lights x 100
locations x 3 repeats = 36,000 samples (the release's 3x3 captures; 20,160
train, 5,040 validation and 10,800 test under the clean protocol's random
split), each a (3, 3, BINS) histogram of Poisson counts. Only the epochs are cut (`--epochs`): the cell's wall time
per epoch (training, the validation pass, its share of the set-up) times the
model's full schedule is the projection of the paper preset's cell, which
trains every epoch (`train.max_epochs: null`). The labels are random, so the
scores mean nothing; the times are what the paper preset pays.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import yaml

from denali_pipe.train.cells import TASKS, Cell
from denali_pipe.train.precision import cpu_has_native_bf16
from denali_pipe.train.training import Hyper, run_cell, training_device

REPO = Path(__file__).resolve().parents[1]
SHAPES, SIZES, LIGHTS, LOCATIONS, REPEATS = 30, ("4inch", "8inch"), ("on", "off"), 100, 3
BINS = 78  # the cropped window of the demo's and the paper preset's 3x3 datasets


def paper_benchmark(seed: int) -> tuple[np.ndarray, pd.DataFrame]:
    """(x (36000, 3, 3, BINS) float32 counts, samples table) in the reference's row order."""
    rng = np.random.default_rng(seed)
    grid = [(s, z, light, loc, r) for s in range(SHAPES) for z in SIZES for light in LIGHTS for loc in range(LOCATIONS) for r in range(REPEATS)]
    samples = pd.DataFrame(grid, columns=["shape", "size", "light", "location", "repeat"])
    samples["class"] = "shape" + samples["shape"].astype(str).str.zfill(2)
    samples["set"] = samples["class"] + "_" + samples["size"] + "_light" + samples["light"]
    xy = rng.uniform(-0.5, 0.5, (LOCATIONS, 2)).astype(np.float32)
    samples["x"], samples["y"] = xy[samples["location"], 0], xy[samples["location"], 1]
    x = rng.poisson(50.0, (len(samples), 3, 3, BINS)).astype(np.float32)
    return x, samples


def main() -> None:
    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    models = cfg["train"]["models"]
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default=training_device(torch.cuda.is_available()), help="torch device (default: cuda when torch sees a GPU)")
    p.add_argument("--precision", default=cfg["train"]["precision"], help="train.precision: auto, float32 or bfloat16")
    p.add_argument("--epochs", type=int, default=2, help="epochs each cell trains (the projection scales them to the full schedule)")
    p.add_argument("--models", nargs="+", default=list(models), choices=list(models))
    p.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    p.add_argument("--threads", type=int, default=cfg["train"]["threads"], help="torch CPU threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    where = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else f"CPU, {args.threads} thread(s)"
    x, samples = paper_benchmark(cfg["seed"])
    print(f"Table 2 cells at the paper's 3x3 size ({len(samples):,} samples, {BINS} bins), {args.epochs} epoch(s) each; {where}; "
          f"train.precision {args.precision}; torch {torch.__version__}")  # fmt: skip
    rows = []
    for name in args.models:
        for task in args.tasks:
            full = Hyper(**models[name][task])
            hp = dataclasses.replace(full, epochs=min(args.epochs, full.epochs))
            cell = Cell(name, task, "random", "3x3", cfg["train"]["protocol"], cfg["seed"])
            t0 = time.perf_counter()
            m = run_cell(x, samples, cell, hp, cfg["train"]["validation_fraction"], models[name]["factory"], args.device, None, args.precision,
                         cpu_has_native_bf16()).metrics  # fmt: skip
            wall = time.perf_counter() - t0
            per_epoch = wall / m.epochs_run
            rows.append({"model": name, "task": task, "precision": m.precision, "batch": hp.batch_size, "n_train": m.n_train, "epochs_run": m.epochs_run,
                         "train_s_per_epoch": m.train_seconds / m.epochs_run, "wall_s_per_epoch": per_epoch,
                         "train_samples_per_s": m.train_samples_per_second, "paper_epochs": full.epochs,
                         "projected_cell_min": per_epoch * full.epochs / 60})  # fmt: skip
            print(f"{name} {task}: {per_epoch:.2f} s/epoch", flush=True)
    df = pd.DataFrame(rows)
    print(df.round(3).to_string(index=False))
    print(f"projected: every (model, task) cell of one seed {df.projected_cell_min.sum():.1f} min; "
          f"Table 2's {len(cfg['train']['seeds'])} seeds {len(cfg['train']['seeds']) * df.projected_cell_min.sum():.1f} min")  # fmt: skip


if __name__ == "__main__":
    main()
