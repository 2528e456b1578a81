"""Metrics against hand-computed cases and against scikit-learn as an independent oracle."""

import numpy as np
import pytest
from sklearn.metrics import accuracy_score, precision_recall_fscore_support, top_k_accuracy_score

from denali_pipe.core.geometry import gantry_workspace
from denali_pipe.train.metrics import (
    classification_metrics,
    predict_majority_baseline,
    predict_mean_baseline,
    regression_metrics,
    workspace_metrics,
)


def test_regression_by_hand():
    # Errors (3, 4) and (0, 0): per-coordinate RMSE over the 4 entries, not the distance.
    m = regression_metrics([[1.0, 2.0], [0.5, 0.5]], [[-2.0, -2.0], [0.5, 0.5]])
    assert m["mse"] == pytest.approx((9 + 16) / 4)
    assert m["rmse"] == pytest.approx(2.5)
    assert m["mae"] == pytest.approx(7 / 4)
    assert (m["mse_x"], m["mse_y"], m["mae_x"], m["mae_y"]) == pytest.approx((4.5, 8.0, 1.5, 2.0))
    assert m["rmse_euclidean"] == pytest.approx(np.sqrt((25 + 0) / 2))  # RMS of distances 5 and 0


def test_regression_euclidean_is_sqrt2_larger_and_mean_baseline():
    rng = np.random.default_rng(0)
    target = rng.uniform([0.97, 0.17], [1.31, 0.51], size=(1000, 2))
    pred = predict_mean_baseline(target, len(target))
    assert pred.shape == (1000, 2) and np.allclose(pred, target.mean(axis=0))
    m = regression_metrics(pred, target)
    assert m["rmse_euclidean"] == pytest.approx(np.sqrt(2) * m["rmse"])
    assert m["mse"] == pytest.approx((m["mse_x"] + m["mse_y"]) / 2)
    assert m["rmse"] == pytest.approx(np.sqrt(target.var(axis=0).mean()))


def test_regression_rejects_wrong_shape():
    with pytest.raises(ValueError):
        regression_metrics(np.zeros(4), np.zeros(4))


def test_topk_by_hand():
    logits = np.array([
        [0.9, 0.1, 0.8, 0.7, 0.6, 0.5, 0.0],  # target 0 is top-1
        [0.9, 0.1, 0.8, 0.7, 0.6, 0.5, 0.0],  # target 5 is 5th largest: top-5 only
        [0.9, 0.1, 0.8, 0.7, 0.6, 0.5, 0.0],  # target 1 is 6th: neither
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],  # target 6 is top-1
    ])  # fmt: skip
    m = classification_metrics(logits, np.array([0, 5, 1, 6]))
    assert (m["top1"], m["top5"]) == (0.5, 0.75)


def test_two_classes_top5_is_one():
    rng = np.random.default_rng(1)
    logits, target = rng.normal(size=(50, 2)), rng.integers(0, 2, 50)
    m = classification_metrics(logits, target)
    assert m["top5"] == 1.0
    assert m["top1"] == pytest.approx(accuracy_score(target, logits.argmax(1)))


def test_macro_prf_union_of_labels_by_hand():
    # Class 3 occurs only as a target, class 2 only as a prediction.
    target = np.array([0, 0, 1, 1, 3])
    pred = np.array([0, 1, 1, 2, 0])
    logits = np.eye(5)[pred]
    m = classification_metrics(logits, target)
    # Per class (labels 0, 1, 2, 3): P = 1/2, 1/2, 0, 0; R = 1/2, 1/2, 0, 0; F1 = 1/2, 1/2, 0, 0.
    assert (m["precision"], m["recall"], m["f1"]) == pytest.approx((0.25, 0.25, 0.25))
    # Class 4 is in neither, so it is not averaged in (it would give 0.2).
    assert m["top1"] == pytest.approx(2 / 5)


def test_f1_is_mean_of_per_class_harmonic_means_not_harmonic_mean_of_macros():
    target = np.array([0, 0, 0, 1])
    pred = np.array([0, 1, 1, 1])  # class 0: P 1, R 1/3; class 1: P 1/3, R 1
    m = classification_metrics(np.eye(2)[pred], target)
    assert (m["precision"], m["recall"]) == pytest.approx((2 / 3, 2 / 3))
    assert m["f1"] == pytest.approx(0.5)  # mean of 2*(1*1/3)/(4/3) = 1/2 each, not 2/3


@pytest.mark.parametrize("n_classes, n_labels_used", [(30, 30), (30, 12), (2, 2)])
# sklearn warns that its top-2 of 2 classes is trivially 1; so is ours, which is the point.
@pytest.mark.filterwarnings("ignore:'k' \\(2\\) greater:sklearn.exceptions.UndefinedMetricWarning")
def test_against_sklearn(n_classes, n_labels_used):
    rng = np.random.default_rng(n_classes + n_labels_used)
    n = 400
    target = rng.integers(0, n_labels_used, n)
    logits = rng.normal(size=(n, n_classes))
    logits[np.arange(n), target] += 1.5  # better than chance, so P/R/F1 are not trivial
    m = classification_metrics(logits, target)
    pred = logits.argmax(1)
    assert m["top1"] == pytest.approx(accuracy_score(target, pred))
    # sklearn wants the positive class's score alone for binary targets.
    scores = logits[:, 1] if n_classes == 2 else logits
    k = min(5, n_classes)
    assert m["top5"] == pytest.approx(top_k_accuracy_score(target, scores, k=k, labels=np.arange(n_classes)))
    p, r, f, _ = precision_recall_fscore_support(target, pred, average="macro", zero_division=0)
    assert (m["precision"], m["recall"], m["f1"]) == pytest.approx((p, r, f))


def test_majority_baseline():
    train = np.array([2, 2, 2, 0, 0, 1, 3, 3])  # counts 2, 1, 3, 2: ranking 2, then 0 and 3 by label, then 1
    scores = predict_majority_baseline(train, 4, n_classes=4)
    assert scores.shape == (4, 4)
    assert list(np.argsort(-scores[0])) == [2, 0, 3, 1]
    m = classification_metrics(scores, np.array([2, 0, 3, 1]))
    assert m["top1"] == 0.25 and m["top5"] == 1.0
    # Predicts class 2 only: P = (1/4, 0, 0, 0) over the union {0, 1, 2, 3}.
    assert m["precision"] == pytest.approx(1 / 16)


def test_workspace_metrics_count_the_predictions_outside_and_the_furthest():
    lo, hi = gantry_workspace()
    inside = np.tile((lo + hi) / 2, (3, 1))
    assert workspace_metrics(inside) == {"outside_workspace": 0.0, "max_outside_workspace": 0.0}
    out = np.vstack([inside, [hi[0] + 0.5, hi[1]], [lo[0], lo[1] - 0.25]])
    assert workspace_metrics(out) == pytest.approx({"outside_workspace": 0.4, "max_outside_workspace": 0.5})
    with pytest.raises(ValueError, match=r"expected \(N, 2\) predictions"):
        workspace_metrics(np.zeros(4))
