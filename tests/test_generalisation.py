"""Figs 10 and 11: scores of the base cells beside their references, and the
non-RR histograms beside a retroreflective object's."""

import numpy as np
import pandas as pd
import pytest

from denali_pipe.experiments.generalisation import ANY_DATA, BASE_TEST, CHANCE, MEAN_BASELINE, MODEL, NONRR, RR, fig10, fig11, histogram_table, score_table
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import Cell
from denali_pipe.train.evaluate import Evaluation

NONRR_DATA = "results/datasets/nonrr_3x3.zarr"


def _cell(task, seed, model="cnn1d"):
    return Cell(model=model, task=task, split="random", resolution="3x3", protocol="clean", seed=seed)


def _metrics(task, seed, value, baseline, model="cnn1d"):
    key = "rmse" if task == "location" else "top1"
    return CellMetrics(cell=_cell(task, seed, model), hyper={}, selected_on="validation", n_train=70, n_validation=10, n_test=30,
                       n_classes=2 if task != "shape" else 30, input_shape=(3, 3, 50), params=1, test={key: value}, baseline={key: baseline},
                       train_seconds=1.0, inference_seconds=0.1, train_samples_per_second=70.0, inference_samples_per_second=300.0, device="cpu")  # fmt: skip


def _evaluation(task, seed, value, baseline, dataset=NONRR_DATA):
    key = "rmse" if task == "location" else "top1"
    return Evaluation(_cell(task, seed), f"runs/{task}/seed{seed}", dataset, 24, 2 if task != "shape" else 30, {key: value}, {key: baseline})


CELLS = [_metrics("location", 1, 0.04, 0.10), _metrics("location", 2, 0.06, 0.10), _metrics("shape", 1, 0.3, 0.03), _metrics("shape", 2, 0.5, 0.03)]
EVALS = [_evaluation("location", 1, 0.08, 0.11), _evaluation("location", 2, 0.10, 0.13), _evaluation("shape", 1, 0.2, 0.0), _evaluation("shape", 2, 0.0, 0.0)]


def test_scores_stand_beside_the_cells_own_and_their_references():
    t = score_table(CELLS, EVALS, "non-RR sets").set_index(["task", "data", "predictor"])
    assert list(dict.fromkeys(t.index.get_level_values("task"))) == ["location", "shape"]
    own = t.loc[("location", BASE_TEST, MODEL)]
    assert own["value"] == pytest.approx(0.05) and own["std"] == pytest.approx(np.std([0.04, 0.06], ddof=1)) and own["n_samples"] == 30
    assert t.loc[("location", "non-RR sets", MODEL), "value"] == pytest.approx(0.09)
    assert t.loc[("location", "non-RR sets", MEAN_BASELINE), "value"] == pytest.approx(0.12)
    assert t.loc[("location", BASE_TEST, MEAN_BASELINE), ["value", "std"]].tolist() == pytest.approx([0.10, 0.0])
    # shape: chance, not the majority class of a balanced training set (class "0", which a plate of class "1" never is)
    assert t.loc[("shape", ANY_DATA, CHANCE), "value"] == pytest.approx(1 / 30)
    assert t.loc[("shape", "non-RR sets", MODEL), "value"] == pytest.approx(0.1)
    assert set(t["panel"]) == {"score"} and (t.loc[("shape", "non-RR sets", MODEL), "n_seeds"] == 2)


def test_scores_refuse_evaluations_that_do_not_match_the_cells():
    with pytest.raises(ValueError, match="mix datasets"):
        score_table(CELLS, [*EVALS[:3], _evaluation("shape", 2, 0.0, 0.0, "results/datasets/italic_3x3.zarr")], "x")
    with pytest.raises(ValueError, match="whose metrics were not given"):
        score_table(CELLS, [*EVALS, _evaluation("location", 3, 0.1, 0.1)], "x")
    with pytest.raises(ValueError, match="shape: 2 cells but 1 evaluations"):
        score_table(CELLS, EVALS[:3], "x")
    with pytest.raises(ValueError, match="the cells of one model"):
        score_table([*CELLS, _metrics("size", 1, 0.9, 0.5, model="mlp")], EVALS, "x")


def _dataset(objects, classes, sizes, lights, locations=(0, 3, 5, 9), repeats=3, T=20, seed=0):
    """A dataset whose centre zone carries a recognisable value per sample."""
    rng = np.random.default_rng(seed)
    rows = [{"object": o, "class": c, "size": s, "light": li, "location": k, "repeat": r, "x": 1.0 + 0.03 * k, "y": 0.3}
            for o, c in zip(objects, classes) for s in sizes for li in lights for k in locations for r in range(repeats)]  # fmt: skip
    return rng.normal(size=(len(rows), 3, 3, T)).astype(np.float32), pd.DataFrame(rows)


def test_histograms_pair_each_variant_with_a_base_object_at_the_same_place():
    xv, variant = _dataset(["generalization1white", "generalization1cardstock"], ["1", "1"], ["4inch", "8inch"], ["lighton", "lightoff"])
    xb, base = _dataset(["A", "1"], ["A", "1"], ["8inch"], ["lightoff", "lighton"], locations=(0, 3, 5), seed=1)
    h = histogram_table(xv, variant, xb, base, crop_start=70)
    assert sorted(set(h["pair"])) == ["generalization1cardstock", "generalization1white"]
    assert set(h["size"]) == {"8inch"} and set(h["light"]) == {"lightoff"}
    # the middle of the variant's locations (mean x at location 4.25) that the base captured too
    assert set(h["location"]) == {5}
    white = h[h["pair"] == "generalization1white"]
    assert set(white.loc[white["data"] == RR, "object"]) == {"1"}  # the same class, not the first base object "A"
    rows = variant.index[
        (variant["object"] == "generalization1white") & (variant["size"] == "8inch") & (variant["light"] == "lightoff") & (variant["location"] == 5)
    ]
    mine = white[white["data"] == NONRR]
    assert mine["bin"].tolist() == list(range(70, 90))
    assert np.allclose(mine["value"], xv[rows, 1, 1].mean(axis=0)) and (mine["n_samples"] == 3).all()


def test_figures_write_their_table(tmp_path):
    xv, variant = _dataset(["generalization1white"], ["1"], ["8inch"], ["lightoff"])
    xb, base = _dataset(["1"], ["1"], ["8inch"], ["lightoff"], seed=1)
    cells = [*CELLS, _metrics("size", 1, 0.9, 0.5), _metrics("size", 2, 0.8, 0.5)]
    evals = [*EVALS, _evaluation("size", 1, 0.5, 0.5), _evaluation("size", 2, 0.6, 0.5)]
    table = fig10(cells, evals, histogram_table(xv, variant, xb, base, 70), tmp_path / "fig10.png")
    written = pd.read_csv(tmp_path / "fig10.csv")
    assert len(written) == len(table) and set(written["panel"]) == {"histogram", "score"} and "pair" not in written
    assert set(written.loc[written["panel"] == "score", "task"]) == {"location", "shape", "size"}
    fig11(CELLS, [_evaluation(e.cell.task, e.cell.seed, 0.1, 0.1, "results/datasets/italic_3x3.zarr") for e in EVALS], tmp_path / "fig11.png")
    assert set(pd.read_csv(tmp_path / "fig11.csv")["task"]) == {"location", "shape"}
    assert (tmp_path / "fig10.png").stat().st_size > 10_000 and (tmp_path / "fig11.png").stat().st_size > 10_000
