"""Training cells for the explorer: loaded on demand and kept, their
outputs for one capture, and their test error per gantry location.

A cell's test error per location scores the cell on its own test split, as
training did: the dataset it was trained on, the split `train.partition`
draws again from the cell (split, seed) and the sample table.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.explore.outputs import CellChoice, Inventory, dataset_paths
from denali_pipe.train.cell_metrics import METRICS_FILE, CellMetrics
from denali_pipe.train.dataset import read_dataset
from denali_pipe.train.evaluate import TrainedCell, load_cell, predict, score
from denali_pipe.train.predict import softmax
from denali_pipe.train.saved_cell import MODEL_FILE
from denali_pipe.train.training import partition, targets

# What the per-location heat map shows for each task: the `evaluate.score`
# metric (m or a share, shown x 100), its name and unit.
ERROR_METRIC = {"location": ("rmse_euclidean", "RMS error", "cm"), "shape": ("top1", "top-1 accuracy", "%"), "size": ("top1", "accuracy", "%")}


def _stamp(path: Path) -> int:
    return path.stat().st_mtime_ns


@lru_cache(maxsize=32)
def _cell(run_dir: Path, _stamp: int) -> TrainedCell:
    return load_cell(run_dir)


def trained_cell(inv: Inventory, choice: CellChoice, task: str) -> TrainedCell:
    """The choice's `task` cell, loaded once per saved model."""
    run_dir = inv.path(choice.run_path(task))
    return _cell(run_dir, _stamp(run_dir / MODEL_FILE))


def capture_output(trained: TrainedCell, x: np.ndarray) -> np.ndarray:
    """The cell's output for one capture repeat x (n, n, T): (2,) x, y in
    metres for location, (C,) class probabilities otherwise."""
    out = predict(trained, x[None])[0]
    return out if trained.cell.task == "location" else softmax(out[None])[0]


@lru_cache(maxsize=2)
def _dataset(x_path: Path, table_path: Path, _stamps: tuple[int, int]) -> tuple[np.ndarray, pd.DataFrame]:
    x, samples, _ = read_dataset(x_path, table_path)
    return x, samples


@lru_cache(maxsize=64)
def _error_by_location(run_dir: Path, x_path: Path, table_path: Path, _stamps: tuple[int, int, int]) -> pd.DataFrame:
    trained = _cell(run_dir, _stamps[0])
    x, samples = _dataset(x_path, table_path, _stamps[1:])
    y, _ = targets(samples, trained.cell.task)
    test = partition(samples, y, trained.cell, CellMetrics.read(run_dir / METRICS_FILE).validation_fraction)[0].test
    metric = ERROR_METRIC[trained.cell.task][0]
    rows = []
    for location, idx in samples.iloc[test].groupby("location").indices.items():
        picked = test[idx]
        rows.append((int(location), 100 * score(trained, x[picked], samples.iloc[picked])[metric], len(picked)))
    return pd.DataFrame(rows, columns=["location", "value", "n"]).set_index("location")


def error_by_location(inv: Inventory, choice: CellChoice, task: str) -> pd.DataFrame:
    """The `task` cell's test error per gantry location (index): `value`,
    its ERROR_METRIC (RMS distance of the predictions from the labels in cm,
    or the share of test samples classified right in %) over the location's
    `n` test samples; locations without test samples are absent. Computed
    once per saved model and dataset."""
    run_dir = inv.path(choice.run_path(task))
    x_path, table_path = (inv.path(p) for p in dataset_paths(choice.resolution, choice.protocol))
    return _error_by_location(run_dir, x_path, table_path, (_stamp(run_dir / MODEL_FILE), _stamp(x_path), _stamp(table_path)))
