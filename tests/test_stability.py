"""The stability report (report/stability.py) on small synthetic inputs:
cells' metrics.json, a transforms.json and a twin_calibration.json, each
planted with known failures."""

import json
import math

import numpy as np
import pandas as pd
import pytest

from denali_pipe.cli import main
from denali_pipe.core.geometry import PAPER_TIME_AXIS
from denali_pipe.report.stability import COLUMNS, cell_id, write_stability
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import Cell
from denali_pipe.transforms.sim_to_real import KERNEL_BINS, ZONES, Bootstrap, FitCheck, Transforms, ZoneTransforms, write_transforms
from denali_pipe.twin.calibrate import CALIBRATION_VERSION

N_TEST = 100
MODES = [
    "location worse than the mean",
    "classifier at chance",
    "diverged training",
    "training stopped by its budget",
    "location outside the workspace",
    "sim-to-real transforms unidentified",
    "twin coordinate at its bound",
    "twin calibration stopped by its budget",
]


def write_cell(root, model, task, split, test, baseline, stopped=False, seed=42):
    cell = Cell(model=model, task=task, split=split, resolution="3x3", protocol="clean", seed=seed)
    d = root / cell_id(cell)
    d.mkdir(parents=True)
    m = CellMetrics(
        cell=cell, hyper={"lr": 1e-3, "epochs": 10, "batch_size": 64, "norm": "raw"}, selected_on="validation", n_train=300, n_validation=60,
        n_test=N_TEST, n_classes=2 if task != "shape" else 5, input_shape=(3, 3, 57), params=1000, test=test, baseline=baseline,
        train_seconds=1.0, inference_seconds=0.1, train_samples_per_second=300.0, inference_samples_per_second=1000.0, device="cpu",
        best_epoch=3, epochs_run=3 if stopped else 10, stopped_by_budget=stopped,
    )  # fmt: skip
    (d / "metrics.json").write_text(m.to_json())
    return d / "metrics.json"


def loc(rmse, outside=0.0, furthest=0.0):
    return {"rmse": rmse, "mae": rmse, "outside_workspace": outside, "max_outside_workspace": furthest}


@pytest.fixture
def cells(tmp_path):
    """Two location cells (one worse than the mean, with predictions out of
    the workspace), four classifiers around chance (0.5 +- 0.05 on 100
    test samples), a diverged cell, a budget-stopped one."""
    r = tmp_path / "runs"
    chance = {"top1": 0.5}
    return [
        write_cell(r, "cnn1d", "location", "random", loc(0.05), loc(0.10)),
        write_cell(r, "cnn1d", "location", "size_held_out", loc(0.20, 0.25, 0.4), loc(0.10)),
        write_cell(r, "cnn1d", "size", "random", {"top1": 0.56}, chance),  # above chance + sd
        write_cell(r, "cnn1d", "size", "location_held_out", {"top1": 0.54}, chance),  # within one sd of chance
        write_cell(r, "cnn1d", "size", "repeats_grouped", {"top1": 0.30}, chance),  # below chance
        write_cell(r, "cnn1d", "shape", "random", {"top1": float("nan")}, {"top1": 0.2}),  # diverged
        write_cell(r, "cnn3d", "shape", "random", {"top1": 0.9}, {"top1": 0.2}, stopped=True),
        write_cell(r, "linear", "location", "random", {"rmse": 0.05, "mae": 0.04}, {"rmse": 0.1, "mae": 0.09}),  # predates the workspace metrics
    ]


def transforms_file(path, mode, unidentified):
    """transforms.json with `unidentified` ({zone: {parameter: why}}) planted."""
    t = Transforms(2.0, 1.0, tuple(np.eye(KERNEL_BINS)[KERNEL_BINS // 2]), 1.0, 0.0)
    boot = Bootstrap(30, 0, 0.9, {}, {}, 0.01, 0)
    checks = [FitCheck(3.0, boot, None, unidentified.get(z, {})) for z in range(ZONES)]
    write_transforms(path, ZoneTransforms(mode, (t,) * ZONES), checks, PAPER_TIME_AXIS, {})
    return path


def calibration_file(path, at_bound, converged):
    body = {
        "denali_twin_calibration": CALIBRATION_VERSION,
        "parameters": {"offset_u": np.zeros((3, 3)).tolist(), "offset_v": np.zeros((3, 3)).tolist(), "scale": np.ones((3, 3)).tolist(), "time_offset": 0.0},
        "at_bound": at_bound,
        "fit": {"evaluations": 20, "converged": converged},
    }
    path.write_text(json.dumps(body))
    return path


def test_every_failure_mode_has_its_row_with_the_cases_that_fail(tmp_path, cells):
    transforms = transforms_file(tmp_path / "transforms.json", "per_zone", {4: {"gamma": "not identified"}, 7: {"a": "se 30%", "kernel": "spread"}})
    calibration = calibration_file(tmp_path / "twin_calibration.json", ["scale[0, 2]", "time_offset"], converged=False)
    table = write_stability(cells, transforms, calibration, tmp_path / "stability.png")
    on_disk = pd.read_csv(tmp_path / "stability.csv", keep_default_na=False)
    assert list(on_disk.columns) == COLUMNS and list(on_disk["failure"]) == MODES
    assert (tmp_path / "stability.png").stat().st_size > 10_000
    rows = table.set_index("failure")
    counts = {m: (int(rows.loc[m, "count"]), int(rows.loc[m, "of"])) for m in MODES}
    assert counts == {
        "location worse than the mean": (1, 3),
        "classifier at chance": (2, 4),  # the diverged cell counts as diverged only
        "diverged training": (1, 8),
        "training stopped by its budget": (1, 7),  # networks only
        "location outside the workspace": (1, 2),  # the linear cell predates the metric: not checked
        "sim-to-real transforms unidentified": (2, 9),
        "twin coordinate at its bound": (2, 28),  # 3 x 9 zone coordinates and the time offset
        "twin calibration stopped by its budget": (1, 1),
    }
    sd = math.sqrt(0.25 / N_TEST)
    assert rows.loc["classifier at chance", "which"] == (
        f"clean/3x3/all/location_held_out/cnn1d_size/seed42 (top-1 0.540, chance 0.500 +- {sd:.3f}); "
        f"clean/3x3/all/repeats_grouped/cnn1d_size/seed42 (top-1 0.300, chance 0.500 +- {sd:.3f})"
    )
    assert rows.loc["location worse than the mean", "which"] == "clean/3x3/all/size_held_out/cnn1d_location/seed42 (RMSE 0.200 m, mean 0.100 m)"
    assert rows.loc["location outside the workspace", "which"] == "clean/3x3/all/size_held_out/cnn1d_location/seed42 (25.0%, up to 0.40 m out)"
    assert rows.loc["diverged training", "which"] == "clean/3x3/all/random/cnn1d_shape/seed42"
    assert rows.loc["training stopped by its budget", "which"] == "clean/3x3/all/random/cnn3d_shape/seed42 (3 of 10 epochs)"
    assert rows.loc["sim-to-real transforms unidentified", "which"] == "zone 4: gamma: not identified; zone 7: a: se 30%; kernel: spread"
    assert rows.loc["twin coordinate at its bound", "which"] == "scale[0, 2]; time_offset"
    assert rows.loc["twin calibration stopped by its budget", "which"] == "twin calibration (20 evaluations)"
    governed = dict(zip(rows.index, rows["governed_by"]))
    assert governed["training stopped by its budget"] == "train.budget_seconds"
    assert governed["sim-to-real transforms unidentified"] == "fit.bootstrap.max_rel_se"
    assert governed["twin calibration stopped by its budget"] == "twin.calibration.max_evaluations"


def test_a_clean_run_has_every_row_at_zero_and_a_shared_fit_is_one_case(tmp_path):
    r = tmp_path / "runs"
    paths = [write_cell(r, "cnn1d", "location", "random", loc(0.05), loc(0.10)), write_cell(r, "cnn1d", "size", "random", {"top1": 0.9}, {"top1": 0.5})]
    transforms = transforms_file(tmp_path / "transforms.json", "shared", {})
    calibration = calibration_file(tmp_path / "twin_calibration.json", [], converged=True)
    table = write_stability(paths, transforms, calibration, tmp_path / "stability.png")
    assert (table["count"] == 0).all() and (table["which"] == "").all()
    assert table.set_index("failure").loc["sim-to-real transforms unidentified", "of"] == 1
    shared = transforms_file(tmp_path / "shared.json", "shared", dict.fromkeys(range(ZONES), {"gamma": "one radiance level"}))
    row = write_stability(paths, shared, calibration, tmp_path / "s2.png").set_index("failure").loc["sim-to-real transforms unidentified"]
    assert (row["count"], row["of"], row["which"]) == (1, 1, "shared: gamma: one radiance level")


def test_denali_stability_refuses_a_file_that_is_not_what_it_names(tmp_path, cells, caplog):
    transforms = transforms_file(tmp_path / "transforms.json", "shared", {})
    calibration = calibration_file(tmp_path / "twin_calibration.json", [], converged=True)
    out = tmp_path / "stability.png"
    assert main(["stability", *map(str, cells), "--transforms", str(transforms), "--calibration", str(calibration), "--out", str(out)]) == 0
    assert out.exists() and (tmp_path / "stability.csv").exists()
    bad = tmp_path / "bad"
    bad.mkdir()
    args = ["stability", *map(str, cells), "--transforms", str(calibration), "--calibration", str(calibration), "--out", str(bad / "s.png")]
    assert main(args) == 1
    assert f"{calibration}: no per-zone transforms" in caplog.text and not list(bad.iterdir())
