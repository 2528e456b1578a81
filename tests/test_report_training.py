"""Training tables and figures from cells' metrics.json and curves.csv."""

import json

import pandas as pd
import pytest

from denali_pipe.core.splits import SPLITS
from denali_pipe.experiments.jitter import jitter_curve
from denali_pipe.report.condition_table import condition_table, write_condition_table
from denali_pipe.report.jitter import plot_jitter
from denali_pipe.report.paper import CONDITION_TABLES, TABLE5, TABLE10
from denali_pipe.report.speed_vs_accuracy import pareto, write_speed_vs_accuracy
from denali_pipe.report.table2 import write_table2
from denali_pipe.report.table5 import write_table5
from denali_pipe.report.table10 import write_table10
from denali_pipe.report.training_curves import write_training_curves
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import TASKS, Cell, is_ill_posed
from denali_pipe.train.conditions import CONDITION_GROUPS, TABLES
from denali_pipe.train.jitter import jitter_condition
from denali_pipe.train.models import PAPER_MODELS
from denali_pipe.train.runs import load_runs

MODELS = tuple(PAPER_MODELS)
REG = {"mse": 0.0025, "rmse": 0.05, "mae": 0.04, "outside_workspace": 0.1, "max_outside_workspace": 0.02}
CLS = {"top1": 0.5, "top5": 0.9, "precision": 0.45, "recall": 0.5, "f1": 0.47}


def _write_cell(root, model, task, split, seed, protocol="clean", score=0.0, resolution="3x3", condition="all"):
    d = root / protocol / resolution / condition / split / f"{model}_{task}" / f"seed{seed}"
    d.mkdir(parents=True)
    test = {k: v + score for k, v in (REG if task == "location" else CLS).items()}
    m = CellMetrics(
        cell=Cell(model=model, task=task, split=split, resolution=resolution, protocol=protocol, seed=seed, condition=condition),
        hyper={"lr": 1e-3, "epochs": 10, "batch_size": 64, "norm": "raw"},
        selected_on="validation", n_train=700, n_validation=140, n_test=300, n_classes=30, input_shape=(3, 3, 57), params=82340, flops=164000,
        best_epoch=7, test=test, baseline={k: v / 2 for k, v in test.items()},
        train_seconds=36.0 * (1 + MODELS.index(model) if model in MODELS else 0.1), inference_seconds=0.36,
        train_samples_per_second=700.0, inference_samples_per_second=833.0, device="cpu",
    )  # fmt: skip
    (d / "metrics.json").write_text(m.to_json())
    curves = [(e, part, k, v + 0.01 * e) for e in range(1, 11) for part in ("train", "validation") for k, v in test.items()]
    curves.append((7, "test", list(test)[0], 0.1))
    pd.DataFrame(curves, columns=["epoch", "part", "metric", "value"]).to_csv(d / "curves.csv", index=False)
    return d


def test_table5_has_every_split_na_for_ill_posed_and_the_paper_beside(tmp_path):
    paths = [
        _write_cell(tmp_path, "cnn1d", t, s, seed, score=0.01 * i) / "metrics.json"
        for s in SPLITS for t in TASKS for i, seed in enumerate((42, 43)) if not is_ill_posed(s, t)
    ]  # fmt: skip
    write_table5(paths, tmp_path / "table5.csv")
    t = pd.read_csv(tmp_path / "table5.csv", keep_default_na=False).set_index("split")
    assert list(t.index) == list(SPLITS)
    assert t.loc["shape_held_out", "shape_top1"] == "n/a" and t.loc["size_held_out", "size_accuracy"] == "n/a"
    assert t.loc["shape_held_out", "paper_shape_top1"] == "n/a"
    assert float(t.loc["random", "loc_rmse"]) == pytest.approx(0.055)
    assert float(t.loc["random", "loc_rmse_std"]) == pytest.approx(0.00707, abs=1e-4)
    assert float(t.loc["random", "paper_loc_rmse"]) == TABLE5["random"]["loc_rmse"]
    assert (t["protocol"] == "clean").all() and (t["n_seeds"] == 2).all()
    cols = list(t.columns)
    assert cols.index("paper_loc_rmse") == cols.index("loc_rmse") + 2
    # the share of predictions outside the gantry's workspace, which the paper does not publish
    assert float(t.loc["size_held_out", "loc_outside_workspace"]) == pytest.approx(0.105)
    assert float(t.loc["size_held_out", "loc_outside_workspace_std"]) == pytest.approx(0.00707, abs=1e-4)
    assert "paper_loc_outside_workspace" not in cols


def test_tables_read_n_a_for_the_workspace_share_of_cells_that_predate_it(tmp_path):
    paths = [_write_cell(tmp_path, "cnn1d", "location", "random", 42, condition=c) / "metrics.json" for c in ("all", "light_on", "light_off")]
    m = json.loads(paths[1].read_text())
    del m["test"]["outside_workspace"]
    paths[1].write_text(json.dumps(m))
    t9 = condition_table(load_runs(paths), "table9", ["lighting"]).set_index("condition")
    assert t9.loc["all", "loc_outside_workspace"] == pytest.approx(0.1) and t9.loc["light_on", "loc_outside_workspace"] == "n/a"
    write_table5(paths[1:2], tmp_path / "table5.csv")
    assert pd.read_csv(tmp_path / "table5.csv", keep_default_na=False).set_index("split").loc["random", "loc_outside_workspace"] == "n/a"


def test_table5_shows_one_model_of_one_protocol(tmp_path):
    a = _write_cell(tmp_path, "mlp", "location", "random", 42) / "metrics.json"
    write_table5([a], tmp_path / "t.csv")
    assert set(pd.read_csv(tmp_path / "t.csv")["model"]) == {"mlp"}  # any registered model (train.benchmark_model)
    b = _write_cell(tmp_path, "cnn1d", "location", "random", 42) / "metrics.json"
    with pytest.raises(ValueError, match=r"Table 5 shows one model; got models \['cnn1d', 'mlp'\]"):
        write_table5([a, b], tmp_path / "t.csv")
    c = _write_cell(tmp_path, "cnn1d", "location", "random", 43, protocol="paper") / "metrics.json"
    with pytest.raises(ValueError, match="mix"):
        write_table5([b, c], tmp_path / "t.csv")


def test_table2_table10_speed_accuracy_and_curves(tmp_path):
    paths = [_write_cell(tmp_path, m, t, "random", s) for m in [*MODELS, "linear"] for t in TASKS for s in (42, 43)]
    nets = [p / "metrics.json" for p in paths if "linear" not in str(p)]
    write_table2(nets, tmp_path / "table2.csv")
    t2 = pd.read_csv(tmp_path / "table2.csv", keep_default_na=False).set_index("model")
    assert list(t2.index) == list(MODELS)
    assert t2.loc["mlp", "paper_shape_top1"] == "" and float(t2.loc["cnn1d", "paper_shape_top1"]) == TABLE5["random"]["shape_top1"]

    write_table10(nets, tmp_path / "table10.csv")
    t10 = pd.read_csv(tmp_path / "table10.csv").set_index(["model", "task"])
    assert len(t10) == 12
    assert t10.loc[("cnn3d", "shape"), "paper_params"] == TABLE10[("cnn3d", "shape")]["params"]
    assert t10.loc[("cnn1d", "size"), "train_hours"] == pytest.approx(72 / 3600)
    assert (t10["flops"] == 164000).all() and list(t10.columns).index("flops") == list(t10.columns).index("paper_params") + 1
    # models in the order given (config order): a user's model first stays first
    write_table2(nets[::-1], tmp_path / "table2_reversed.csv")
    assert list(pd.read_csv(tmp_path / "table2_reversed.csv")["model"]) == list(MODELS)[::-1]

    write_speed_vs_accuracy([p / "metrics.json" for p in paths], tmp_path / "sva.png")
    sva = pd.read_csv(tmp_path / "sva.csv")
    assert (tmp_path / "sva.png").stat().st_size > 10_000
    assert set(sva["model"]) == {*MODELS, "linear"} and len(sva) == 15
    # every model has the same metric here, so only the fastest is on the front
    assert sva[sva["pareto"]]["model"].unique().tolist() == ["linear"]

    curves = [p / "curves.csv" for p in paths if "cnn1d_location" in str(p)]
    write_training_curves(curves, "location", "1D CNN", tmp_path / "fig16.png")
    assert (tmp_path / "fig16.png").stat().st_size > 10_000
    assert set(pd.read_csv(tmp_path / "fig16.csv")["part"]) == {"train", "validation", "test"}


def test_left_out_models_keep_their_rows_with_the_reason(tmp_path):
    trained, left_out = ("mlp", "cnn1d"), {"cnn3d": "too slow here", "transformer": "also too slow"}
    paths = [_write_cell(tmp_path, m, t, "random", s) for m in [*trained, "linear"] for t in TASKS for s in (42, 43)]
    nets = [p / "metrics.json" for p in paths if "linear" not in str(p)]
    write_table2(nets, tmp_path / "table2.csv", left_out)
    t2 = pd.read_csv(tmp_path / "table2.csv", keep_default_na=False).set_index("model")
    assert list(t2.index) == [*trained, *left_out]
    assert (t2.loc["cnn3d", ["loc_rmse", "shape_top1", "size_accuracy"]] == "n/a").all() and t2.loc["cnn3d", "n_seeds"] == 0
    assert t2.loc["transformer", "note"] == "not trained on this preset: also too slow" and t2.loc["cnn1d", "note"] == ""
    assert float(t2.loc["cnn1d", "loc_rmse"]) == pytest.approx(REG["rmse"])
    with pytest.raises(ValueError, match=r"\['mlp'\] are both trained and left out"):
        write_table2(nets, tmp_path / "bad.csv", {"mlp": "no"})

    write_table10(nets, tmp_path / "table10.csv", left_out)
    t10 = pd.read_csv(tmp_path / "table10.csv", keep_default_na=False).set_index(["model", "task"])
    assert len(t10) == 12 and list(dict.fromkeys(t10.index.get_level_values(0))) == [*trained, *left_out]
    row = t10.loc[("cnn3d", "shape")]
    assert row["params"] == "n/a" and row["train_hours"] == "n/a" and int(row["paper_params"]) == TABLE10[("cnn3d", "shape")]["params"]
    assert row["note"] == "not trained on this preset: too slow here" and t10.loc[("mlp", "size"), "note"] == ""
    assert float(t10.loc[("cnn1d", "size"), "train_hours"]) == pytest.approx(72 / 3600)

    write_speed_vs_accuracy([p / "metrics.json" for p in paths], tmp_path / "sva.png", left_out)
    assert set(pd.read_csv(tmp_path / "sva.csv")["model"]) == {*trained, "linear"}


def test_pareto_front():
    pts = pd.DataFrame({"train_seconds": [1, 10, 100, 5], "metric": [0.1, 0.3, 0.2, 0.05]})
    assert pareto(pts, higher_is_better=True).tolist() == [True, True, False, False]
    assert pareto(pts, higher_is_better=False).tolist() == [True, False, False, True]


def test_condition_tables_have_both_resolutions_na_for_untrained_and_the_paper_at_8x8(tmp_path):
    task, conditions = TABLES["table8"]
    untrained = "numbers"  # as if the preset had a single number object... of one size
    paths = [
        _write_cell(tmp_path, "cnn1d", task, "random", seed, resolution=res, condition=c, score=0.01 * i + (0.1 if res == "3x3" else 0.0)) / "metrics.json"
        for res in ("8x8", "3x3") for c in conditions if c != untrained for i, seed in enumerate((42, 43))
    ]  # fmt: skip
    write_condition_table(paths, "table8", list(CONDITION_GROUPS), tmp_path / "table8.csv")
    t = pd.read_csv(tmp_path / "table8.csv", keep_default_na=False)
    assert list(zip(t.resolution, t.condition)) == [(res, c) for res in ("3x3", "8x8") for c in conditions]
    t = t.set_index(["resolution", "condition"])
    assert t.loc[("8x8", "all"), "condition_group"] == "baseline" and t.loc[("3x3", "front_quadrant"), "condition_group"] == "location"
    assert float(t.loc[("3x3", "letters"), "size_accuracy"]) == pytest.approx(0.605)  # mean over seeds of 0.6 and 0.61
    assert float(t.loc[("3x3", "letters"), "size_accuracy_std"]) == pytest.approx(0.00707, abs=1e-4)
    assert float(t.loc[("8x8", "letters"), "paper_size_accuracy"]) == CONDITION_TABLES["table8"]["letters"]["size_accuracy"]
    assert t.loc[("3x3", "letters"), "paper_size_accuracy"] == ""  # published at 8x8 only
    assert float(t.loc[("8x8", "all"), "trivial_size_accuracy"]) == pytest.approx(0.2525)
    for res in ("3x3", "8x8"):
        assert t.loc[(res, untrained), "size_accuracy"] == "n/a" and t.loc[(res, untrained), "n_seeds"] == 0
    assert (t.drop(untrained, level="condition").n_seeds == 2).all() and (t.protocol == "clean").all()
    assert not {c for c in t.columns if c.startswith(("loc_", "shape_"))}


def test_condition_tables_refuse_other_cells(tmp_path):
    shape = _write_cell(tmp_path, "cnn1d", "shape", "random", 42) / "metrics.json"
    with pytest.raises(ValueError, match="table8 shows the size cells of one model"):
        condition_table(load_runs([shape]), "table8", list(CONDITION_GROUPS))
    size_cell = _write_cell(tmp_path, "cnn1d", "size", "random", 42, condition="8inch") / "metrics.json"
    with pytest.raises(ValueError, match="table8 has no row for conditions"):
        condition_table(load_runs([size_cell]), "table8", list(CONDITION_GROUPS))
    quadrant = _write_cell(tmp_path, "cnn1d", "size", "random", 42, condition="back_quadrant") / "metrics.json"
    with pytest.raises(ValueError, match=r"no row for conditions \['back_quadrant'\]"):
        condition_table(load_runs([quadrant]), "table8", ["lighting"])


def test_condition_tables_show_the_groups_trained(tmp_path):
    paths = [_write_cell(tmp_path, "cnn1d", "location", "random", 42, condition=c) / "metrics.json" for c in ("all", "light_on", "light_off")]
    t = condition_table(load_runs(paths), "table9", ["lighting"])
    assert list(t.condition) == ["all", "light_on", "light_off"] and (t.n_seeds == 1).all()
    assert (t.loc_outside_workspace == 0.1).all() and (t.loc_outside_workspace_std == 0.0).all()


def test_jitter_figure(tmp_path, time_axis):
    paths = [
        _write_cell(tmp_path, "cnn1d", task, "random", seed, condition=jitter_condition(fwhm), score=fwhm / 1e4 + 0.01 * i) / "metrics.json"
        for task in TASKS for fwhm in (0, 50, 100, 600) for i, seed in enumerate((42, 43))
    ]  # fmt: skip
    plot_jitter(jitter_curve(load_runs(paths), time_axis), "jitter", time_axis, tmp_path / "jitter.png")
    assert (tmp_path / "jitter.png").stat().st_size > 10_000
    curve = pd.read_csv(tmp_path / "jitter.csv")
    assert len(curve) == 8 * 4 and set(curve.task) == set(TASKS)
