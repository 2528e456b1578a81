"""Test metrics exactly as the reference computes them (docs/deviations.md), in numpy.

Regression (location): d = prediction - target, (N, 2) in metres (x, y).
- mse = mean(d^2) over all N*2 entries; rmse = sqrt(mse) is a per-coordinate RMSE,
  which is what the paper reports;
- mae = mean|d| over the same entries; per-axis mse_x, mse_y, mae_x, mae_y;
- rmse_euclidean = sqrt(mean(dx^2 + dy^2)) = sqrt(2) * rmse, the RMS distance
  between predicted and true points, for readers who expect that one.
Beside them, what no error shows (`workspace_metrics`): how many predictions
lie outside the gantry's workspace (`geometry.gantry_workspace`, margin
`geometry.WORKSPACE_MARGIN`), where no object can be, and how far out.

Classification (shape, size), from logits (N, C) and integer labels (N,):
- top1 = accuracy of argmax; top5 = the label is among the min(5, C) largest
  logits (for size, C = 2, so it is always 1.0);
- precision, recall, f1: macro averages with scikit-learn's semantics
  (`average="macro"`, `zero_division=0`) over the union of the labels present in
  the targets and the predictions. A class that is only predicted, or only a
  target, counts with precision, recall and F1 all 0; classes in neither are
  left out of the averages.

Baselines give predictions in the same shapes, to be scored with the same metrics.
"""

from __future__ import annotations

import numpy as np

from denali_pipe.core.geometry import outside_workspace

TOP_K = 5


def regression_metrics(pred: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """Metrics of predicted against true (N, 2) positions in metres (errors in m, squared errors in m^2)."""
    d = np.asarray(pred, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 2:
        raise ValueError(f"expected (N, 2) predictions and targets, got {d.shape}")
    sq, ab = d**2, np.abs(d)
    mse = float(sq.mean())
    return {
        "mse": mse,
        "rmse": float(np.sqrt(mse)),
        "mae": float(ab.mean()),
        "mse_x": float(sq[:, 0].mean()),
        "mse_y": float(sq[:, 1].mean()),
        "mae_x": float(ab[:, 0].mean()),
        "mae_y": float(ab[:, 1].mean()),
        "rmse_euclidean": float(np.sqrt(sq.sum(axis=1).mean())),
    }


def workspace_metrics(pred: np.ndarray) -> dict[str, float]:
    """Of (N, 2) predicted positions (m): outside_workspace, the share lying
    outside the gantry's workspace; max_outside_workspace, the furthest
    one's distance beyond it (m, 0 when none is outside)."""
    pred = np.asarray(pred, dtype=np.float64)
    if pred.ndim != 2 or pred.shape[1] != 2:
        raise ValueError(f"expected (N, 2) predictions, got {pred.shape}")
    beyond = outside_workspace(pred)
    return {"outside_workspace": float((beyond > 0).mean()), "max_outside_workspace": float(beyond.max(initial=0.0))}


def top_k_accuracy(logits: np.ndarray, target: np.ndarray, k: int) -> float:
    """Share of rows whose target is among the min(k, C) largest logits.

    Like the reference's argpartition, ties at the k-th largest value are broken
    arbitrarily; with float logits from a network they do not occur.
    """
    k = min(k, logits.shape[1])
    top = np.argpartition(-logits, k - 1, axis=1)[:, :k]
    return float((top == target[:, None]).any(axis=1).mean())


def macro_prf(target: np.ndarray, pred: np.ndarray) -> tuple[float, float, float]:
    """Macro precision, recall and F1 over the labels in `target` or `pred`, 0 where undefined."""
    labels = np.union1d(target, pred)
    tp = np.array([np.sum((pred == c) & (target == c)) for c in labels], dtype=np.float64)
    n_pred = np.array([np.sum(pred == c) for c in labels], dtype=np.float64)
    n_true = np.array([np.sum(target == c) for c in labels], dtype=np.float64)
    # Every label in the union is predicted or true, so the F1 denominator is never 0;
    # F1 = 2tp / (n_pred + n_true) is sklearn's harmonic mean of P and R, and 0 when tp = 0.
    precision = np.divide(tp, n_pred, out=np.zeros_like(tp), where=n_pred > 0)
    recall = np.divide(tp, n_true, out=np.zeros_like(tp), where=n_true > 0)
    f1 = 2 * tp / (n_pred + n_true)
    return float(precision.mean()), float(recall.mean()), float(f1.mean())


def classification_metrics(logits: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """top1, top5, and macro precision, recall, f1 of (N, C) logits against (N,) integer labels."""
    logits = np.asarray(logits, dtype=np.float64)
    target = np.asarray(target)
    if logits.ndim != 2 or target.shape != (logits.shape[0],):
        raise ValueError(f"expected (N, C) logits and (N,) targets, got {logits.shape} and {target.shape}")
    pred = logits.argmax(axis=1)
    precision, recall, f1 = macro_prf(target, pred)
    return {
        "top1": float((pred == target).mean()),
        "top5": top_k_accuracy(logits, target, TOP_K),
        "precision": precision,
        "recall": recall,
        "f1": f1,
    }


def predict_mean_baseline(train_targets: np.ndarray, n_test: int) -> np.ndarray:
    """(n_test, 2) predictions that are all the mean training position, metres."""
    mean = np.asarray(train_targets, dtype=np.float64).mean(axis=0)
    return np.broadcast_to(mean, (n_test, mean.shape[0])).copy()


def predict_majority_baseline(train_labels: np.ndarray, n_test: int, n_classes: int) -> np.ndarray:
    """(n_test, n_classes) scores ranking the classes by training frequency.

    Top-1 is the majority class, top-k the k most frequent classes. Scores are
    distinct (C for the first, 1 for the last), equal counts ranked by lower
    label first, so that the ranking is deterministic on balanced training sets.
    """
    counts = np.bincount(np.asarray(train_labels), minlength=n_classes)
    order = np.lexsort((np.arange(n_classes), -counts))  # by count descending, then label
    scores = np.empty(n_classes)
    scores[order] = np.arange(n_classes, 0, -1)
    return np.broadcast_to(scores, (n_test, n_classes)).copy()
