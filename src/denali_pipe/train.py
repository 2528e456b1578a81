"""One training cell: a model trained for one task on one split, one seed.

Two protocols:
- `paper`: as the reference does it: normalisation statistics over all
  samples, every epoch evaluated on the test split and the best test epoch
  kept. Kept for comparability with the paper's numbers; it leaks.
- `clean` (default): a validation part is carved out of the training split
  (the same kind of hold-out as the split itself), normalisation statistics
  come from the remaining training part only, the best validation epoch is
  kept and the test split is evaluated once, with that model.

Training follows REFERENCE Part 2 §3: Adam (betas 0.9/0.999, no weight decay,
no schedule), cross-entropy for classification, summed MSE on metre targets
for regression; the best epoch is chosen on Top-1 (classification) or MAE
(regression). Batches are drawn by indexing one in-memory tensor (no
DataLoader: its per-batch overhead halves throughput for models this small).
"""

from __future__ import annotations

import copy
import time
from dataclasses import asdict, dataclass

import numpy as np
import pandas as pd
import torch
from torch import nn

from denali_pipe import metrics as M
from denali_pipe.cells import PROTOCOLS, TASKS
from denali_pipe.conditions import ALL
from denali_pipe.models import build_model, n_params
from denali_pipe.preprocess import normalise
from denali_pipe.splits import Split, make_split, validation_split

SIZE_CLASSES = ("4inch", "8inch")
EVAL_BATCH = 1024


@dataclass(frozen=True)
class Hyper:
    """Training settings of one (model, task): learning rate, epochs, batch
    size and input normalisation ("raw" or "log_z")."""

    lr: float
    epochs: int
    batch_size: int
    norm: str


@dataclass(frozen=True)
class Cell:
    model: str
    task: str
    split: str
    resolution: str
    protocol: str
    seed: int
    condition: str = ALL  # the samples it trains and tests on (conditions.py)


@dataclass
class Result:
    metrics: dict  # JSON-ready: cell, settings, sizes, selected epoch, test metrics, timings
    curves: pd.DataFrame  # long: epoch, part, metric, value
    state: dict  # model state_dict at the selected epoch plus what evaluation needs


def targets(samples: pd.DataFrame, task: str) -> tuple[np.ndarray, list[str] | None]:
    """Labels of every sample: (N, 2) float32 metres for location; (N,) int64
    class indices and the class names (ASCII order, like sklearn's
    LabelEncoder) for shape and size."""
    if task == "location":
        return samples[["x", "y"]].to_numpy(np.float32), None
    if task == "shape":
        classes = sorted(samples["class"].unique())
        lookup = {c: i for i, c in enumerate(classes)}
        return samples["class"].map(lookup).to_numpy(np.int64), classes
    if task == "size":
        bad = sorted(set(samples["size"]) - set(SIZE_CLASSES))
        if bad:
            raise ValueError(f"unknown sizes {bad}; expected {SIZE_CLASSES}")
        return samples["size"].map({s: i for i, s in enumerate(SIZE_CLASSES)}).to_numpy(np.int64), list(SIZE_CLASSES)
    raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")


def partition(samples: pd.DataFrame, y: np.ndarray, cell: Cell, validation_fraction: float) -> tuple[Split, np.ndarray | None]:
    """(train/test split, validation rows or None). Under `clean` the
    returned train rows exclude the validation rows."""
    stratify = None if cell.task == "location" else y
    split = make_split(samples, cell.split, cell.seed, stratify)
    if cell.protocol == "paper":
        return split, None
    inner = validation_split(samples, split.train, cell.split, cell.seed, validation_fraction, stratify)
    return Split(inner.train, split.test), inner.test


def _evaluate(model: nn.Module, x: torch.Tensor, device: torch.device) -> np.ndarray:
    model.eval()
    outs = []
    with torch.no_grad():
        for i in range(0, len(x), EVAL_BATCH):
            outs.append(model(x[i : i + EVAL_BATCH].to(device)).float().cpu())
    return torch.cat(outs).numpy()


def task_metrics(task: str, out: np.ndarray, y: np.ndarray) -> dict:
    return M.regression_metrics(out, y) if task == "location" else M.classification_metrics(out, y)


def selection_key(task: str) -> tuple[str, int]:
    """(metric, sign): the best epoch maximises sign * metric."""
    return ("mae", -1) if task == "location" else ("top1", 1)


def baseline_metrics(task: str, y_train: np.ndarray, y_test: np.ndarray, n_classes: int) -> dict:
    """Predict-the-training-mean (location) or the training majority class."""
    if task == "location":
        return M.regression_metrics(M.predict_mean_baseline(y_train, len(y_test)), y_test)
    return M.classification_metrics(M.predict_majority_baseline(y_train, len(y_test), n_classes), y_test)


def run_cell(x: np.ndarray, samples: pd.DataFrame, cell: Cell, hp: Hyper, validation_fraction: float, device: str = "cpu", budget_seconds: float | None = None) -> Result:
    """Train one cell on (N, n, n, T) features `x` with sample table `samples`.

    budget_seconds: stop training (mid-epoch if need be; that epoch is still
    evaluated) once this much training time is spent, so that models too slow
    for the machine still give a measured point; None trains every epoch."""
    if cell.protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {cell.protocol!r}; expected one of {PROTOCOLS}")
    torch.manual_seed(cell.seed)
    np.random.seed(cell.seed)
    dev = torch.device(device)
    y, classes = targets(samples, cell.task)
    split, val = partition(samples, y, cell, validation_fraction)

    # normalisation statistics: training part only (clean) or everything (paper)
    _, stats = normalise(x if cell.protocol == "paper" else x[split.train], hp.norm)
    xn = torch.from_numpy(normalise(x, hp.norm, stats)[0])
    regression = cell.task == "location"
    yt = torch.from_numpy(np.array(y))  # pandas hands out read-only views
    n_classes = 2 if regression else len(classes)

    model = build_model(cell.model, cell.task, n=x.shape[1], bins=x.shape[-1], n_classes=n_classes).to(dev)
    opt = torch.optim.Adam(model.parameters(), lr=hp.lr)
    loss_fn = nn.MSELoss(reduction="sum") if regression else nn.CrossEntropyLoss()
    select_on = ("test", split.test) if val is None else ("validation", val)
    metric, sign = selection_key(cell.task)

    x_train, y_train = xn[split.train].to(dev), yt[split.train].to(dev)
    x_sel, y_sel = xn[select_on[1]], y[select_on[1]]
    gen = torch.Generator().manual_seed(cell.seed)
    rows, best, train_seconds, n_seen, over_budget = [], (-np.inf, 0, None), 0.0, 0, False
    for epoch in range(1, hp.epochs + 1):
        model.train()
        t0 = time.perf_counter()
        outs, order = [], torch.randperm(len(x_train), generator=gen)
        for i in range(0, len(order), hp.batch_size):
            idx = order[i : i + hp.batch_size].to(dev)
            opt.zero_grad(set_to_none=True)
            out = model(x_train[idx])
            loss_fn(out, y_train[idx]).backward()
            opt.step()
            outs.append((idx.cpu(), out.detach().float().cpu()))
            n_seen += len(idx)
            over_budget = budget_seconds is not None and train_seconds + time.perf_counter() - t0 > budget_seconds
            if over_budget:
                break
        train_seconds += time.perf_counter() - t0
        # training metrics from the epoch's own (train-mode) outputs: free, as the paper's curves
        idx = torch.cat([i for i, _ in outs]).numpy()
        rows += metric_rows(epoch, "train", task_metrics(cell.task, torch.cat([o for _, o in outs]).numpy(), y[split.train][idx]))
        sel = task_metrics(cell.task, _evaluate(model, x_sel, dev), y_sel)
        rows += metric_rows(epoch, select_on[0], sel)
        if sign * sel[metric] > best[0]:
            best = (sign * sel[metric], epoch, copy.deepcopy(model.state_dict()))
        if over_budget:
            break

    model.load_state_dict(best[2])
    t0 = time.perf_counter()
    test_out = _evaluate(model, xn[split.test], dev)
    infer_seconds = time.perf_counter() - t0
    test = task_metrics(cell.task, test_out, y[split.test])
    if val is not None:
        rows += metric_rows(best[1], "test", test)

    result = {
        "cell": asdict(cell),
        "hyper": asdict(hp),
        "validation_fraction": validation_fraction if val is not None else None,
        "selected_on": select_on[0],
        "n_train": int(len(split.train)),
        "n_validation": int(0 if val is None else len(val)),
        "n_test": int(len(split.test)),
        "n_classes": n_classes,
        "input_shape": list(x.shape[1:]),
        "params": n_params(model),
        "best_epoch": int(best[1]),
        "epochs_run": epoch,
        "samples_seen": n_seen,
        "budget_seconds": budget_seconds,
        "stopped_by_budget": over_budget,
        "test": test,
        "baseline": baseline_metrics(cell.task, y[split.train], y[split.test], n_classes),
        "train_seconds": train_seconds,
        "inference_seconds": infer_seconds,
        "train_samples_per_second": n_seen / train_seconds if train_seconds > 0 else None,
        "inference_samples_per_second": len(split.test) / infer_seconds if infer_seconds > 0 else None,
        "device": str(dev),
        "threads": torch.get_num_threads(),
    }
    state = {"model": best[2], "norm_stats": stats, "classes": classes, "cell": asdict(cell), "hyper": asdict(hp)}
    return Result(result, pd.DataFrame(rows, columns=["epoch", "part", "metric", "value"]), state)


def metric_rows(epoch: int, part: str, values: dict) -> list[tuple]:
    return [(epoch, part, k, float(v)) for k, v in values.items()]
