"""A classical reference point for the speed-vs-accuracy chart: linear models
on log histograms (ridge regression for location, logistic regression for
shape and size), trained under the same splits and protocols as the networks.

The regularisation strength is the one "epoch-like" choice: it is picked from
REGULARISATION on the validation part (`clean`) or on the test split (`paper`),
exactly as the networks pick their epoch.
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
import pandas as pd
from sklearn.linear_model import LogisticRegression, Ridge

from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import Cell
from denali_pipe.train.training import Result, baseline_metrics, metric_rows, partition, selection_key, targets, task_metrics

# Ridge alpha / inverse logistic C, on z-scored log histograms.
REGULARISATION = (0.1, 1.0, 10.0, 100.0)
MAX_ITER = 300


def _fit(task: str, strength: float, x: np.ndarray, y: np.ndarray):
    if task == "location":
        return Ridge(alpha=strength).fit(x, y)
    return LogisticRegression(C=1.0 / strength, max_iter=MAX_ITER).fit(x, y)


def _scores(task: str, model, x: np.ndarray, n_classes: int) -> np.ndarray:
    if task == "location":
        return model.predict(x)
    d = model.decision_function(x)
    if d.ndim == 1:  # binary: one score for classes_[1]
        d = np.c_[-d, d]
    out = np.full((len(x), n_classes), -np.inf)  # classes absent from training never win
    out[:, model.classes_] = d
    return out


def run_linear(x: np.ndarray, samples: pd.DataFrame, cell: Cell, validation_fraction: float) -> Result:
    """Fit one linear cell on (N, n, n, T) features; the Result mirrors `train.run_cell`'s."""
    y, classes = targets(samples, cell.task)
    split, val = partition(samples, y, cell, validation_fraction)
    _, stats = normalise(x if cell.protocol == "paper" else x[split.train], "log_z")
    xf = normalise(x, "log_z", stats)[0].reshape(len(x), -1)
    n_classes = 2 if cell.task == "location" else len(classes)
    sel_name, sel_rows = ("test", split.test) if val is None else ("validation", val)
    metric, sign = selection_key(cell.task)

    rows, best, train_seconds = [], (-np.inf, None, None), 0.0
    for i, strength in enumerate(REGULARISATION, start=1):
        t0 = time.perf_counter()
        model = _fit(cell.task, strength, xf[split.train], y[split.train])
        train_seconds += time.perf_counter() - t0
        sel = task_metrics(cell.task, _scores(cell.task, model, xf[sel_rows], n_classes), y[sel_rows])
        rows += metric_rows(i, sel_name, sel)
        if sign * sel[metric] > best[0]:
            best = (sign * sel[metric], strength, model)

    t0 = time.perf_counter()
    out = _scores(cell.task, best[2], xf[split.test], n_classes)
    infer_seconds = time.perf_counter() - t0
    test = task_metrics(cell.task, out, y[split.test])
    metrics = CellMetrics(
        cell=cell,
        hyper={"regularisation": list(REGULARISATION), "norm": "log_z"},
        selected_on=sel_name,
        selected_regularisation=best[1],
        n_train=int(len(split.train)),
        n_validation=int(0 if val is None else len(val)),
        n_test=int(len(split.test)),
        n_classes=n_classes,
        input_shape=tuple(int(d) for d in x.shape[1:]),
        params=int(best[2].coef_.size + np.size(best[2].intercept_)),
        test=test,
        baseline=baseline_metrics(cell.task, y[split.train], y[split.test], n_classes),
        train_seconds=train_seconds,
        inference_seconds=infer_seconds,
        train_samples_per_second=len(split.train) * len(REGULARISATION) / train_seconds,
        inference_samples_per_second=len(split.test) / infer_seconds if infer_seconds > 0 else None,
        device="cpu",
    )
    state = {"model": best[2], "norm_stats": stats, "classes": classes, "cell": asdict(cell)}
    return Result(metrics, pd.DataFrame(rows, columns=["epoch", "part", "metric", "value"]), state)
