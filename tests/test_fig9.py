"""Fig 9 on tiny synthetic pairs: table shape, a real test split disjoint from
the real training samples, determinism per seed, predictions bounded to the
training labels' box, the predict-the-mean baseline."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from denali_pipe import geometry as geo
from denali_pipe.experiments.fig9 import MEAN_BASELINE, bound_to_workspace, real_samples, run_fig9
from denali_pipe.report.fig9 import write_fig9
from denali_pipe.train import Hyper
from denali_pipe.transforms import FIDELITIES, KERNEL_BINS, Pairs, Transforms, split_pairs

CROP, T, R = 77, 51, 3
SETTINGS = {"test_fraction": 0.3, "fig9": {"real_samples": [0, 5, 20], "seeds": [1, 2], "sim_copies": 1}}
HP = Hyper(lr=1e-3, epochs=1, batch_size=16, norm="raw")
TRANSFORMS = Transforms(1e3, 1.0, tuple(np.full(KERNEL_BINS, 1 / KERNEL_BINS)), 1.0, 4.0)


@pytest.fixture(scope="module")
def data() -> tuple[Pairs, np.ndarray]:
    """Two sets x 15 locations; the twin's bump moves with x, the real one is the scaled, noisy twin."""
    rng = np.random.default_rng(0)
    n = 30
    xy = rng.uniform(-0.2, 0.2, (n, 2)).astype(np.float32)
    b = np.arange(geo.N_BINS)
    sim = np.exp(-0.5 * ((b - 90 - 20 * xy[:, :1]) / 2.0) ** 2).astype(np.float32) * 1e-2
    real = (1e3 * sim[:, None, CROP : CROP + T] + rng.normal(0, 2, (n, R, T))).astype(np.float32)
    keys = pd.DataFrame(
        {"set": np.repeat(["A_8inch_3x3_lighton", "1_4inch_3x3_lighton"], 15), "object": "A", "size": "8inch", "location": np.tile(np.arange(15), 2)}
    )
    return Pairs(real, sim, keys, CROP), xy


@pytest.fixture(scope="module")
def runs(data) -> pd.DataFrame:
    return run_fig9(*data, TRANSFORMS, SETTINGS, HP, split_seed=42)


def test_table_shape(runs, tmp_path):
    f9 = SETTINGS["fig9"]
    models = runs[runs["fidelity"] != MEAN_BASELINE]
    assert len(models) == len(FIDELITIES) * len(f9["real_samples"]) * len(f9["seeds"])
    assert set(models["fidelity"]) == set(FIDELITIES) and set(models["n_real"]) == set(f9["real_samples"])
    assert np.isfinite(runs["rmse"]).all() and (runs["n_test"] == 9 * R).all() and (models["n_sim"] == 21).all()
    table = write_fig9(runs, tmp_path / "fig9.png", tmp_path / "fig9.csv")
    assert len(table) == len(FIDELITIES) * len(f9["real_samples"]) + 1
    assert {"rmse", "rmse_std", "mse", "mse_std", "mae", "mae_std", "n_seeds"} <= set(table.columns)
    assert (table["n_seeds"] == 2).all()
    assert pd.read_csv(tmp_path / "fig9.csv").shape == table.shape and (tmp_path / "fig9.png").stat().st_size > 0


def test_real_samples_never_come_from_the_test_split(data):
    pairs, xy = data
    split = split_pairs(pairs.keys, 42, SETTINGS["test_fraction"])
    train = pairs.subset(split.train)
    test_captures = set(map(tuple, pairs.keys.iloc[split.test][["set", "location"]].values))
    for seed in (1, 2):
        x, y, idx = real_samples(train, xy[split.train], 20, seed)
        drawn = set(map(tuple, train.keys.iloc[idx[:, 0]][["set", "location"]].values))
        assert drawn and not drawn & test_captures
        assert np.array_equal(x, train.real[idx[:, 0], idx[:, 1]]) and np.array_equal(y, xy[split.train][idx[:, 0]])
        assert np.array_equal(real_samples(train, xy[split.train], 5, seed)[2], idx[:5])  # nested as n grows
    with pytest.raises(ValueError, match="only 63"):
        real_samples(train, xy[split.train], 64, 1)


def test_deterministic_per_seed(data, runs):
    one_seed = {**SETTINGS, "fig9": {**SETTINGS["fig9"], "seeds": [2], "real_samples": [5]}}
    again = run_fig9(*data, TRANSFORMS, one_seed, HP, split_seed=42)
    expected = runs[(runs["seed"] == 2) & ((runs["n_real"] == 5) | (runs["fidelity"] == MEAN_BASELINE))].reset_index(drop=True)
    pd.testing.assert_frame_equal(again, expected)
    other = runs[(runs["seed"] == 1) & (runs["n_real"] == 5)].reset_index(drop=True)
    assert not np.allclose(other["rmse"], expected[expected["fidelity"] != MEAN_BASELINE]["rmse"])


def test_bound_to_workspace_clips_onto_the_box_edge():
    lo, hi = np.array([-0.2, 0.1]), np.array([0.3, 0.5])
    pred = np.array([[0.0, 0.3], [1e6, 0.3], [-1e6, -1e6], [0.3, 0.1]])
    bounded = bound_to_workspace(pred, lo, hi)
    assert np.array_equal(bounded[0], pred[0]) and np.array_equal(bounded[3], pred[3])  # inside or on the edge: untouched
    assert np.array_equal(bounded[1], [0.3, 0.3]) and np.array_equal(bounded[2], [-0.2, 0.1])


def test_run_fig9_bounds_every_model_to_its_training_labels_box(data, monkeypatch):
    """A model that answers far outside the workspace scores as if it had
    answered the box's corner: the training captures' positions (twins and
    real repeats alike) bound every model."""
    pairs, xy = data
    monkeypatch.setattr("denali_pipe.experiments.fig9.predict", lambda model, stats, x, norm: np.full((len(x), 2), 1e6))
    one_seed = {**SETTINGS, "fig9": {**SETTINGS["fig9"], "seeds": [1]}}
    runs = run_fig9(pairs, xy, TRANSFORMS, one_seed, HP, split_seed=42)
    split = split_pairs(pairs.keys, 42, SETTINGS["test_fraction"])
    miss = np.repeat(xy[split.test], R, axis=0).astype(np.float64) - xy[split.train].max(axis=0)
    assert np.allclose(runs[runs["fidelity"] != MEAN_BASELINE]["rmse"], np.sqrt(np.mean(miss**2)))


def test_mean_baseline_is_predicting_the_training_mean(data, runs, tmp_path):
    pairs, xy = data
    split = split_pairs(pairs.keys, 42, SETTINGS["test_fraction"])
    y_test = np.repeat(xy[split.test], R, axis=0).astype(np.float64)
    miss = y_test - xy[split.train].astype(np.float64).mean(axis=0)
    baseline = runs[runs["fidelity"] == MEAN_BASELINE]
    assert sorted(baseline["seed"]) == SETTINGS["fig9"]["seeds"]
    assert np.allclose(baseline["rmse"], np.sqrt(np.mean(miss**2))) and np.allclose(baseline["mae"], np.mean(np.abs(miss)))
    assert np.allclose(baseline["rmse_euclidean"], np.sqrt(np.mean(np.sum(miss**2, axis=1))))
    write_fig9(runs, tmp_path / "fig9.png", tmp_path / "fig9.csv")
    row = pd.read_csv(tmp_path / "fig9.csv").query("fidelity == @MEAN_BASELINE")
    assert len(row) == 1 and np.isclose(row["rmse"].item(), np.sqrt(np.mean(miss**2))) and row["rmse_std"].item() == 0
