#!/usr/bin/env python
"""The 1D CNN's three main-table cells trained by the `paper` protocol and by the release's own code, side by side; asserts nothing.

    snakemake --cores all results/datasets/paper/3x3.zarr               # the paper dataset of the tree, whatever train.protocol says
    python scripts/bench_paper_parity.py data/raw                       # the tree the workflow ran on, seeds 42 43 44
    python scripts/bench_paper_parity.py data/raw --epochs 5 --seeds 42 # a quick look: every cell capped at 5 epochs
    python scripts/bench_paper_parity.py data/raw --tasks shape --seeds 43 --device cuda   # one process per task and seed, as on a GPU

Both sides read the same capture tree. Ours: the workflow's `paper` dataset
of it (`--dataset`, what rule paper_dataset wrote from the tree's 3x3
base-object stores and what the workflow's `paper` cells train on) and
`train.run_cell` under `paper` with `train.models.cnn1d`'s settings. Theirs:
the release's `main_table` (`--reference`, MIT; imported here only, never by
the project), run unmodified: `DataSet.from_raw_captures` on the raw tree,
`query_data` as its `build_query` calls it, and `train_regression_experiment`
/ `train_classification_experiment` with its `reg_1dcnn`, `obj_1dcnn` and
`size_1dcnn` cells' settings. Location labels are the dataset's (our
calibration's tag-1 positions), handed to the reference as its
`tag1_positions.json`. Each seed is the split's random_state and the weights'
seed on both sides (as the reference's code does with one number). Its object
cell always has 30 outputs; ours has one per shape in the tree (the same on
the release's 30).

Prints location RMSE (m, per coordinate), shape top-1 and size accuracy with
the best epoch (on the test split, as both select it), per seed, then the mean
and std over seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
import yaml

from denali_pipe.train.cells import TASKS, Cell
from denali_pipe.train.dataset import read_dataset
from denali_pipe.train.training import Hyper, run_cell

REPO = Path(__file__).resolve().parents[1]
MODEL, RESOLUTION = "cnn1d", "3x3"
# task -> (the reference's cell, its metric, ours, the reported name)
CELLS = {
    "location": ("reg_1dcnn", "rmse", "rmse", "location RMSE (m)"),
    "shape": ("obj_1dcnn", "top1_acc", "top1", "shape top-1"),
    "size": ("size_1dcnn", "top1_acc", "top1", "size accuracy"),
}


def reference_modules(path: Path):
    """The release's main_table package, its data and its training modules, imported from `path`."""
    if not (path / "main_table" / "data.py").exists():
        raise FileNotFoundError(f"{path}: not the release's benchmark folder (no main_table/data.py)")
    sys.path.insert(0, str(path))
    try:
        return tuple(importlib.import_module(m) for m in ("main_table", "main_table.data", "main_table.training"))
    finally:
        sys.path.remove(str(path))


def reference_cell(main_table, training, query, task: str, seed: int, epochs: int | None, device: str) -> dict:
    cell = main_table.CELLS[CELLS[task][0]]
    cfg = cell.config
    common = dict(
        query=query, model_factory=cell.arch_factory, num_epochs=cfg.num_epochs if epochs is None else min(epochs, cfg.num_epochs),
        batch_size=cfg.batch_size, lr=cfg.lr, log_transform=cfg.log_transform, normalize=cfg.normalize,
        test_size=cfg.test_size, random_state=seed, device=device, checkpoint_path=None,
    )  # fmt: skip
    if cell.task == "regression":
        r = training.train_regression_experiment(**common)
        value = float(np.sqrt(r.test_metrics["mse"]))
    else:
        r = training.train_classification_experiment(**common, y_key=cell.y_key, num_classes=cell.n_outputs)
        value = r.test_metrics[CELLS[task][1]]
    return {"value": value, "best_epoch": r.best_epoch}


def main() -> None:
    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("raw", type=Path, help="the capture tree in the release layout (<set>_NLOSdata/ folders)")
    p.add_argument("--dataset", type=Path, default=Path(f"results/datasets/paper/{RESOLUTION}"), help="the workflow's paper dataset of it (.zarr, .parquet)")
    p.add_argument("--reference", type=Path, default=REPO.parent / "shared/reference/benchmark", help="the release's benchmark folder")
    p.add_argument("--seeds", type=int, nargs="+", default=[42, 43, 44])
    p.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS)
    p.add_argument("--epochs", type=int, default=None, help="cap every cell's epochs on both sides (default: the paper's)")
    p.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    main_table, data, training = reference_modules(args.reference)

    x, samples, _ = read_dataset(args.dataset.with_suffix(".zarr"), args.dataset.with_suffix(".parquet"))
    labels = samples.groupby("location")[["x", "y"]].first()
    with tempfile.TemporaryDirectory() as tmp:
        tag1 = Path(tmp) / "tag1_positions.json"
        tag1.write_text(json.dumps({f"frame{k}_tag1": [x_, y_, 0.0] for k, x_, y_ in labels.itertuples()}))
        query = data.DataSet.from_raw_captures(args.raw).query_data(
            capture_resolutions=[RESOLUTION], average_spad_histograms=False,
            location_mapping=data.load_capture_number_to_location_mapping(tag1), included_objects=data.BASE_OBJECTS,
        )  # fmt: skip
    if len(query["names"]) != len(samples):
        raise ValueError(f"the reference's query holds {len(query['names'])} samples, {args.dataset} {len(samples)}: not the same tree")
    print(f"{len(samples):,} samples ({samples['set'].nunique()} sets); device {args.device}, {args.threads} thread(s), float32; "
          f"epochs {'the paper' if args.epochs is None else f'capped at {args.epochs}'}; torch {torch.__version__}", flush=True)  # fmt: skip

    rows = []
    for task in args.tasks:
        full = Hyper(**cfg["train"]["models"][MODEL][task])
        hp = full if args.epochs is None else dataclasses.replace(full, epochs=min(args.epochs, full.epochs))
        for seed in args.seeds:
            t0 = time.perf_counter()
            m = run_cell(x, samples, Cell(MODEL, task, "random", RESOLUTION, "paper", seed), hp, cfg["train"]["validation_fraction"],
                         cfg["train"]["models"][MODEL]["factory"], args.device).metrics  # fmt: skip
            t1 = time.perf_counter()
            ref = reference_cell(main_table, training, query, task, seed, args.epochs, args.device)
            t2 = time.perf_counter()
            rows.append({"metric": CELLS[task][3], "seed": seed, "ours": m.test[CELLS[task][2]], "reference": ref["value"],
                         "ours_best_epoch": m.best_epoch, "ref_best_epoch": ref["best_epoch"], "ours_s": t1 - t0, "ref_s": t2 - t1})  # fmt: skip
            print(pd.DataFrame(rows[-1:]).round(4).to_string(index=False, header=len(rows) == 1), flush=True)
    df = pd.DataFrame(rows)
    summary = df.groupby("metric", sort=False)[["ours", "reference"]].agg(["mean", "std"])
    summary[("difference", "of means")] = summary[("ours", "mean")] - summary[("reference", "mean")]
    print("\nmean and std over seeds", args.seeds)
    print(summary.round(4).to_string())


if __name__ == "__main__":
    main()
