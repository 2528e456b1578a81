"""Fig 9 on tiny synthetic pairs: table shape (both panels, the control), a
real test split of whole locations disjoint from everything trained on,
real-sample counts capped at what the training captures hold, determinism
per seed, predictions bounded to the training labels' box, the
predict-the-mean baseline, and the real samples saved."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.experiments.fig9 import CAPPED, CONTROL, MEAN_BASELINE, PANELS, bound_to_workspace, control_hyper, real_samples, run_fig9, sample_counts
from denali_pipe.report.fig9 import NEVER, samples_for, write_fig9
from denali_pipe.train.training import Hyper
from denali_pipe.transforms.sim_to_real import FIDELITIES, KERNEL_BINS, ZONES, Pairs, Transforms, ZoneTransforms, split_pairs

CROP, T, R = 77, 51, 3
N_CAPTURES = 30
SETTINGS = {"test_fraction": 0.3, "fig9": {"real_samples": [0, 5, 20], "seeds": [1, 2], "sim_copies": 1}}
HP = Hyper(lr=1e-3, epochs=1, batch_size=16, norm="raw")
TRANSFORMS = ZoneTransforms("shared", (Transforms(1e3, 1.0, tuple(np.full(KERNEL_BINS, 1 / KERNEL_BINS)), 1.0, 4.0),) * ZONES)


@pytest.fixture(scope="module")
def data() -> tuple[Pairs, np.ndarray]:
    """Two sets x 15 locations x 9 zones; each zone's twin bump moves with x
    (and with the zone), the real one is the scaled, noisy twin."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.2, 0.2, (N_CAPTURES, 2)).astype(np.float32)
    b = np.arange(geo.N_BINS)
    centre = 90 + 20 * np.repeat(xy[:, 0], ZONES) + np.tile(np.arange(ZONES) - 4, N_CAPTURES)
    sim = (np.exp(-0.5 * ((b[None] - centre[:, None]) / 2.0) ** 2) * 1e-2).astype(np.float32)
    real = (1e3 * sim[:, None, CROP : CROP + T] + rng.normal(0, 2, (len(sim), R, T))).astype(np.float32)
    keys = pd.DataFrame({
        "set": np.repeat(["A_8inch_3x3_lighton", "1_4inch_3x3_lighton"], 15 * ZONES), "object": "A", "size": "8inch",
        "location": np.repeat(np.tile(np.arange(15), 2), ZONES), "zone": np.tile(np.arange(ZONES), N_CAPTURES),
    })  # fmt: skip
    return Pairs(real, sim, keys, CROP), xy


@pytest.fixture(scope="module")
def runs(data) -> pd.DataFrame:
    return run_fig9(*data, TRANSFORMS, SETTINGS, HP, split_seed=42)


def test_table_shape(runs, tmp_path):
    f9 = SETTINGS["fig9"]
    models = runs[runs["fidelity"].isin(FIDELITIES)]
    control = runs[runs["fidelity"] == CONTROL]
    assert len(models) == len(PANELS) * len(FIDELITIES) * len(f9["real_samples"]) * len(f9["seeds"])
    assert set(models["fidelity"]) == set(FIDELITIES) and set(models["n_real"]) == set(f9["real_samples"])
    assert set(control["n_real"]) == {5, 20} and (control["n_sim"] == 0).all() and set(runs["panel"]) == set(PANELS)
    # 15 locations of 2 sets: 5 held out, both sets' captures there
    assert np.isfinite(runs["rmse"]).all() and (runs["n_test"] == 10 * R).all() and (models["n_sim"] == 20).all()
    assert (runs[CAPPED] == "").all()
    table = write_fig9(runs, tmp_path / "fig9.png", tmp_path / "fig9.csv")
    assert len(table) == len(PANELS) * (len(FIDELITIES) * len(f9["real_samples"]) + 2 + 1)
    assert {"rmse", "rmse_std", "mse", "mse_std", "mae", "mae_std", "n_seeds", "control_n_same_rmse", "real_samples_saved"} <= set(table.columns)
    assert (table["n_seeds"] == 2).all()
    fid = table[table["fidelity"].isin(FIDELITIES)]
    assert (fid["real_samples_saved"] != "").all() and (table.loc[~table["fidelity"].isin(FIDELITIES), "real_samples_saved"] == "").all()
    assert pd.read_csv(tmp_path / "fig9.csv").shape == table.shape and (tmp_path / "fig9.png").stat().st_size > 0


def test_samples_for_interpolates_along_the_control():
    n, rmse = np.array([10.0, 50.0, 100.0]), np.array([0.10, 0.06, 0.05])
    assert samples_for(0.08, n, rmse) == pytest.approx(30.0)
    assert samples_for(0.12, n, rmse) == 10.0  # already there with its fewest
    assert samples_for(0.04, n, rmse) == np.inf
    # not monotone: the first crossing along the curve
    assert samples_for(0.07, np.array([10.0, 50.0, 100.0]), np.array([0.10, 0.06, 0.08])) == pytest.approx(40.0)


def test_real_samples_saved_in_the_table(tmp_path):
    rows = [
        {
            "panel": "centre",
            "fidelity": CONTROL,
            "n_real": n,
            CAPPED: "",
            "seed": 1,
            "n_sim": 0,
            "n_test": 9,
            "rmse": r,
            "mse": r * r,
            "mae": r,
            "rmse_euclidean": r,
        }
        for n, r in ((10, 0.10), (50, 0.06))
    ]
    rows += [
        {
            "panel": "centre",
            "fidelity": "noisy",
            "n_real": n,
            CAPPED: "",
            "seed": 1,
            "n_sim": 5,
            "n_test": 9,
            "rmse": r,
            "mse": r * r,
            "mae": r,
            "rmse_euclidean": r,
        }
        for n, r in ((0, 0.08), (10, 0.05), (50, 0.12))
    ]
    rows += [
        {
            "panel": "centre",
            "fidelity": MEAN_BASELINE,
            "n_real": 0,
            CAPPED: "",
            "seed": 1,
            "n_sim": 0,
            "n_test": 9,
            "rmse": 0.11,
            "mse": 0.0121,
            "mae": 0.1,
            "rmse_euclidean": 0.11,
        }
    ]
    table = write_fig9(pd.DataFrame(rows), tmp_path / "f.png", tmp_path / "f.csv")
    noisy = table[table["fidelity"] == "noisy"].set_index("n_real")
    assert noisy.at[0, "control_n_same_rmse"] == "30" and noisy.at[0, "real_samples_saved"] == "30"
    assert noisy.at[10, "real_samples_saved"] == NEVER
    # the control does better with its fewest: it needs at most those, and the twins cost real samples
    assert noisy.at[50, "control_n_same_rmse"] == "<=10" and noisy.at[50, "real_samples_saved"] == "<=-40"


def test_real_samples_saved_spread_over_seeds(tmp_path):
    """Each seed's twins against its own control: seed 1 saves 30 at n 0
    (0.08 against its control's 0.10 -> 0.06 over 10 -> 50), seed 2 saves
    40 (0.06 against 0.12 -> 0.04): std 7; at n 10 seed 2's control is
    never as good, a bound, so no spread is given."""
    curves = {
        CONTROL: {1: ((10, 0.10), (50, 0.06)), 2: ((10, 0.12), (50, 0.04))},
        "noisy": {1: ((0, 0.08), (10, 0.07)), 2: ((0, 0.06), (10, 0.03))},
        MEAN_BASELINE: {1: ((0, 0.11),), 2: ((0, 0.11),)},
    }
    rows = [
        {"panel": "centre", "fidelity": f, "n_real": n, CAPPED: "", "seed": seed, "n_sim": 5 if f == "noisy" else 0, "n_test": 9,
         "rmse": r, "mse": r * r, "mae": r, "rmse_euclidean": r}
        for f, by_seed in curves.items() for seed, curve in by_seed.items() for n, r in curve
    ]  # fmt: skip
    table = write_fig9(pd.DataFrame(rows), tmp_path / "f.png", tmp_path / "f.csv")
    noisy = table[table["fidelity"] == "noisy"].set_index("n_real")
    assert noisy.at[0, "real_samples_saved_std"] == "7" and noisy.at[10, "real_samples_saved_std"] == ""
    assert (table.loc[table["fidelity"] == CONTROL, "real_samples_saved_std"] == "").all()


def test_real_samples_never_come_from_the_test_split(data):
    pairs, xy = data
    real, _, keys = pairs.captures()
    split = split_pairs(keys, 42, SETTINGS["test_fraction"])
    assert np.array_equal(split.test, np.unique(split_pairs(pairs.keys, 42, SETTINGS["test_fraction"]).test // ZONES))  # the transforms' split
    # whole locations: every set's capture at a test location is a test capture
    assert not set(keys["location"].iloc[split.test]) & set(keys["location"].iloc[split.train])
    test_captures = set(map(tuple, keys.iloc[split.test][["set", "location"]].values))
    train_keys = keys.iloc[split.train].reset_index(drop=True)
    for seed in (1, 2):
        x, y, idx = real_samples(real[split.train], xy[split.train], 20, seed)
        drawn = set(map(tuple, train_keys.iloc[idx[:, 0]][["set", "location"]].values))
        assert drawn and not drawn & test_captures
        assert np.array_equal(x, real[split.train][idx[:, 0], idx[:, 1]]) and np.array_equal(y, xy[split.train][idx[:, 0]])
        assert np.array_equal(real_samples(real[split.train], xy[split.train], 5, seed)[2], idx[:5])  # nested as n grows
    with pytest.raises(ValueError, match="only 60"):
        real_samples(real[split.train], xy[split.train], 61, 1)


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
    real repeats alike) bound every model, the control's too."""
    pairs, xy = data
    # no training (the bound is the point, not the model): 28 fits were ~20 s
    far = SimpleNamespace(predict=lambda x: np.full((len(x), 2), 1e6))
    monkeypatch.setattr("denali_pipe.experiments.fig9.train_localiser", lambda x, y, hp, seed, precision: far)
    one_seed = {**SETTINGS, "fig9": {**SETTINGS["fig9"], "seeds": [1]}}
    runs = run_fig9(pairs, xy, TRANSFORMS, one_seed, HP, split_seed=42)
    split = split_pairs(pairs.captures()[2], 42, SETTINGS["test_fraction"])
    miss = np.repeat(xy[split.test], R, axis=0).astype(np.float64) - xy[split.train].max(axis=0)
    models = runs[runs["fidelity"].isin(FIDELITIES)]
    assert np.allclose(models["rmse"], np.sqrt(np.mean(miss**2)))
    # the control's box is its own real samples'
    real = pairs.captures()[0][split.train]
    for n in (5, 20):
        _, y, _ = real_samples(real, xy[split.train], n, 1)
        miss_n = np.repeat(xy[split.test], R, axis=0).astype(np.float64) - y.max(axis=0)
        assert np.allclose(runs.query("fidelity == @CONTROL and n_real == @n")["rmse"], np.sqrt(np.mean(miss_n**2)))


def test_mean_baseline_is_predicting_the_training_mean(data, runs, tmp_path):
    pairs, xy = data
    split = split_pairs(pairs.captures()[2], 42, SETTINGS["test_fraction"])
    y_test = np.repeat(xy[split.test], R, axis=0).astype(np.float64)
    miss = y_test - xy[split.train].astype(np.float64).mean(axis=0)
    baseline = runs[runs["fidelity"] == MEAN_BASELINE]
    assert sorted(baseline["seed"]) == sorted(SETTINGS["fig9"]["seeds"] * len(PANELS))
    assert np.allclose(baseline["rmse"], np.sqrt(np.mean(miss**2))) and np.allclose(baseline["mae"], np.mean(np.abs(miss)))
    assert np.allclose(baseline["rmse_euclidean"], np.sqrt(np.mean(np.sum(miss**2, axis=1))))
    write_fig9(runs, tmp_path / "fig9.png", tmp_path / "fig9.csv")
    row = pd.read_csv(tmp_path / "fig9.csv").query("fidelity == @MEAN_BASELINE")
    assert len(row) == len(PANELS) and np.allclose(row["rmse"], np.sqrt(np.mean(miss**2))) and (row["rmse_std"] == 0).all()


def test_the_control_takes_as_many_steps_as_a_twin_model():
    # a twin model: 5 epochs of ceil(2110 / 64) = 33 batches = 165 steps, so
    # the control on 10 samples (1 batch an epoch) gets 165 epochs; at 2200
    # samples 5 x 35 = 175 steps, on 200 (4 batches) ceil(175 / 4) = 44
    hp = Hyper(lr=1e-3, epochs=5, batch_size=64, norm="raw")
    assert control_hyper(hp, 2100, 10).epochs == 165
    assert control_hyper(hp, 2000, 200).epochs == 44
    assert control_hyper(hp, 2000, 200).lr == hp.lr


def test_sample_counts_cap_at_what_the_captures_hold():
    assert sample_counts([0, 10, 50], 150) == [(0, ()), (10, ()), (50, ())]
    # a 12-location release tree: 150 training repeats for the config's 200
    assert sample_counts([0, 10, 50, 100, 200], 150) == [(0, ()), (10, ()), (50, ()), (100, ()), (150, (200,))]
    assert sample_counts([200, 100, 10], 60) == [(10, ()), (60, (100, 200))]
    assert sample_counts([0], 0) == [(0, ())]  # the twins alone still fit
    with pytest.raises(ValueError, match="hold no real sample"):
        sample_counts([0, 10], 0)


def test_fig9_fits_the_real_samples_there_are_and_says_so(data, tmp_path):
    """Counts above the 60 training repeats are fitted at 60, once, and the
    CSV and the figure's ticks say which counts they stand for."""
    capped = {**SETTINGS, "fig9": {**SETTINGS["fig9"], "real_samples": [0, 20, 100, 200], "seeds": [1]}}
    runs = run_fig9(*data, TRANSFORMS, capped, HP, split_seed=42)
    assert set(runs["n_real"]) == {0, 20, 60}
    assert (runs.loc[runs["n_real"] == 60, CAPPED] == "100 200").all() and (runs.loc[runs["n_real"] < 60, CAPPED] == "").all()
    table = write_fig9(runs, tmp_path / "fig9.png", tmp_path / "fig9.csv")
    csv = pd.read_csv(tmp_path / "fig9.csv", keep_default_na=False, dtype={CAPPED: str})
    assert (csv.loc[csv["n_real"] == 60, CAPPED] == "100 200").all() and len(csv) == len(table)
