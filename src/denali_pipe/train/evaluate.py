"""A saved training cell, loaded to predict, embed or score other data.

A cell's run directory holds `model.pt` (a `saved_cell.SavedCell` record:
the selected epoch's weights, the model's factory, its input shape, the
normalisation statistics, the class names, the cell and its settings).
`load_cell` rebuilds the model from it through its factory; the
functions below take (N, n, n, T) background-subtracted features, the same
kind of array the cell was trained on, and return per-sample arrays.

Used by `denali evaluate` (a cell scored on another dataset, e.g. the
variant sets of Figs 10/11: an `Evaluation` record), the t-SNE figures and
the explorer.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from torch import nn

from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train.cells import Cell
from denali_pipe.train.registry import build
from denali_pipe.train.saved_cell import SavedCell
from denali_pipe.train.training import EVAL_BATCH, SIZE_CLASSES, Hyper, infer, task_metrics, to_metres


@dataclass(frozen=True)
class TrainedCell:
    """A cell's model in eval mode and what feeding it needs.

    classes: class names in output order (None for location, whose two
    outputs are x, y in metres); norm_stats: `preprocess.normalise`'s (mu,
    sigma) of the cell's training part (None for raw input);
    baseline_output: what the cell's mean / majority baseline answers for
    every sample (`train.baseline_output`: (2,) m or (C,) scores);
    target_stats: the positions' (mean, std) per coordinate in m, and the
    box (lo, hi) its bounded head keeps them in, that map a clean location
    network's standardised outputs back to metres (`train.target_statistics`;
    None for metre outputs and classifiers)."""

    model: nn.Module
    cell: Cell
    hyper: Hyper
    norm_stats: tuple[float, float] | None
    classes: list[str] | None
    input_shape: tuple[int, int, int]  # (n, n, T)
    baseline_output: np.ndarray
    target_stats: tuple[tuple[float, float], ...] | None = None


def load_cell(run_dir: Path) -> TrainedCell:
    """The cell saved in `run_dir` (a network cell; the linear reference
    model's model.pt is not a cell record), rebuilt through the factory the
    record names. ValueError naming the file if it is missing or not a cell
    record, or naming the config key if the factory does not resolve."""
    saved = SavedCell.load(run_dir)
    classes = saved.classes
    model = build(saved.cell.model, saved.factory, saved.cell.task, saved.input_shape, 2 if classes is None else len(classes))
    model.load_state_dict(saved.model)
    model.eval()
    baseline = np.asarray(saved.baseline_output, np.float64)
    return TrainedCell(model, saved.cell, Hyper(**saved.hyper), saved.norm_stats, classes, saved.input_shape, baseline, saved.target_stats)


def _inputs(trained: TrainedCell, x: np.ndarray) -> torch.Tensor:
    if x.ndim != 4 or x.shape[1:] != trained.input_shape:
        raise ValueError(f"features {x.shape} do not fit a {trained.cell.resolution} cell: expected (N, {', '.join(map(str, trained.input_shape))})")
    return torch.from_numpy(np.ascontiguousarray(normalise(x, trained.hyper.norm, trained.norm_stats)[0]))


def predict(trained: TrainedCell, x: np.ndarray) -> np.ndarray:
    """(N, C) outputs for x (N, n, n, T): positions in metres (location) or logits."""
    return to_metres(infer(trained.model, _inputs(trained, x)), trained.target_stats)


def embed(trained: TrainedCell, x: np.ndarray) -> np.ndarray:
    """(N, D) penultimate-layer features for x (N, n, n, T): the input of the
    last Linear layer the forward pass calls (the output head), e.g. the
    1D CNN's 32 features after its hidden Linear-GELU."""
    seen: list[torch.Tensor] = []
    hooks = [m.register_forward_hook(lambda _m, inp, _out: seen.append(inp[0])) for m in trained.model.modules() if isinstance(m, nn.Linear)]
    xn, outs = _inputs(trained, x), []
    try:
        with torch.no_grad():
            for i in range(0, len(xn), EVAL_BATCH):
                seen.clear()
                trained.model(xn[i : i + EVAL_BATCH])
                outs.append(seen[-1].float().flatten(1))
    finally:
        for h in hooks:
            h.remove()
    return torch.cat(outs).numpy()


def labels(trained: TrainedCell, samples: pd.DataFrame) -> np.ndarray:
    """The cell's targets for `samples` (a dataset's sample table): (N, 2)
    metres, or (N,) indices into the cell's classes. ValueError for a class
    the cell never learnt."""
    task = trained.cell.task
    if task == "location":
        return samples[["x", "y"]].to_numpy(np.float32)
    column = "class" if task == "shape" else "size"
    classes = trained.classes if task == "shape" else list(SIZE_CLASSES)
    unknown = sorted(set(samples[column]) - set(classes))
    if unknown:
        raise ValueError(f"{task} classes {unknown} were never learnt by the cell (it knows {classes})")
    return samples[column].map({c: i for i, c in enumerate(classes)}).to_numpy(np.int64)


def score(trained: TrainedCell, x: np.ndarray, samples: pd.DataFrame) -> dict:
    """The cell's test metrics (`train.task_metrics`) on x (N, n, n, T) with
    sample table `samples` (N rows)."""
    if len(samples) != len(x):
        raise ValueError(f"{len(x)} samples but {len(samples)} table rows")
    return task_metrics(trained.cell.task, predict(trained, x), labels(trained, samples))


def baseline_score(trained: TrainedCell, samples: pd.DataFrame) -> dict:
    """`train.task_metrics` of the cell's mean / majority baseline (its
    training labels' mean position or majority class) on `samples`."""
    y = labels(trained, samples)
    return task_metrics(trained.cell.task, np.tile(trained.baseline_output, (len(y), 1)), y)


@dataclass(frozen=True)
class Evaluation:
    """A saved cell scored on a dataset it was not trained on: the JSON
    `denali evaluate` writes. metrics / baseline: `train.task_metrics` of the
    cell and of its mean / majority baseline on the dataset's n_samples
    (metres for location); n_classes: the head's outputs (chance Top-1 is
    1 / n_classes)."""

    cell: Cell
    run: str
    dataset: str
    n_samples: int
    n_classes: int
    metrics: dict[str, float]
    baseline: dict[str, float]

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1) + "\n"

    @classmethod
    def read(cls, path: Path) -> Evaluation:
        """ValueError naming the file when it is not an evaluation."""
        try:
            record = json.loads(Path(path).read_text())
            return cls(**{**record, "cell": Cell(**record["cell"])})
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise ValueError(f"{path}: not a cell's evaluation ({e!r})") from None


def evaluate_run(run_dir: Path, x: np.ndarray, samples: pd.DataFrame, dataset: Path) -> Evaluation:
    """The cell saved in `run_dir` scored on x (N, n, n, T) with sample table
    `samples` (N rows), read from `dataset`."""
    trained = load_cell(run_dir)
    n_classes = 2 if trained.classes is None else len(trained.classes)
    return Evaluation(trained.cell, str(run_dir), str(dataset), len(samples), n_classes, score(trained, x, samples), baseline_score(trained, samples))
