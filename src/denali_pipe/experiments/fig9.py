"""Fig 9 (paper supplement §11.5.2): sim-to-real transfer of a 1D CNN localiser.

For each fidelity of the simulated histograms (`transforms.FIDELITIES`: raw
twins, scaled, scaled+blurred, scaled+blurred+noisy) and each number of real
samples n (e.g. 0, 10, 50, 100, 200), a fresh 1D CNN learns the object's
(x, y) from centre-pixel histograms: the twins of the training captures at
that fidelity plus n real samples, for a fixed number of epochs (no model
selection, as the paper). Every model is scored on the same held-out real
test split: all repeats of the test captures (`transforms.split_pairs`, the
split the transforms were fitted on, so they never saw a test capture).

Per seed: the model's initialisation and batch order, the draw of real
samples (one permutation of the training captures' repeats, its first n, so
the sets are nested as n grows) and the noise draws. Every model of one seed
starts from the same weights, so the curves differ by their data alone.

Every model's predictions are bounded to the workspace, the box of its
training labels (`bound_to_workspace`), so that the raw twins' wild
extrapolation on real counts stays on the scale of the other errors.

Beside the models, the table holds the predict-the-mean baseline as rows of
their own (fidelity `MEAN_BASELINE`, one per seed, n_real = n_sim = 0: it
sees no histogram, only the training captures' positions): the same metrics
of predicting the mean training position for every real test sample. The
split is `split_seed`'s, so its rows are equal across seeds; they are kept
per seed so that the baseline aggregates like every model.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import pandas as pd
import torch
from torch import nn

from denali_pipe.metrics import predict_mean_baseline, regression_metrics
from denali_pipe.models import cnn1d
from denali_pipe.preprocess import normalise
from denali_pipe.registry import N_LOCATION_OUTPUTS
from denali_pipe.seeds import derive_seed, rng_for
from denali_pipe.train import Hyper, fit, infer, loss_for
from denali_pipe.transforms import FIDELITIES, Pairs, Transforms, apply, split_pairs

log = logging.getLogger(__name__)

MEAN_BASELINE = "mean_baseline"  # the `fidelity` of the predict-the-mean baseline's rows


def sim_samples(pairs: Pairs, y: np.ndarray, t: Transforms, fidelity: str, copies: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Simulated training samples: each twin of `pairs` `copies` times at
    `fidelity`, in the real bins. Deterministic fidelities repeat the same
    histogram; the noisy one draws fresh noise per copy, so every fidelity
    trains on the same number of samples. Returns x (copies N, T) float32,
    y (copies N, 2) metres."""
    rng = rng_for(seed, "fig9", "noise")
    x = np.concatenate([pairs.crop(apply(pairs.sim, t, fidelity, rng)) for _ in range(copies)])
    return x, np.tile(y, (copies, 1))


def real_samples(pairs: Pairs, y: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first `n` of one seeded permutation of every (capture, repeat) of
    `pairs`: x (n, T) counts, y (n, 2) metres, and their (pair row, repeat)
    indices (n, 2). ValueError if fewer than n exist."""
    N, R, _ = pairs.real.shape
    if n > N * R:
        raise ValueError(f"fig9: {n} real samples asked for, but the training captures hold only {N * R} ({N} captures x {R} repeats)")
    flat = rng_for(seed, "fig9", "real").permutation(N * R)[:n]
    rows, reps = np.divmod(flat, R)
    return pairs.real[rows, reps], y[rows], np.stack([rows, reps], axis=1)


def train_localiser(x: np.ndarray, y: np.ndarray, hp: Hyper, seed: int) -> tuple[nn.Module, tuple | None]:
    """A fresh 1D CNN (location, one zone) trained on x (N, T), y (N, 2) for
    hp.epochs through `train.fit` (the cells' loop and loss, no model
    selection). Returns the model and its normalisation statistics
    (`preprocess.normalise`, from x)."""
    torch.manual_seed(seed)
    xn, stats = normalise(x, hp.norm)
    xt = torch.from_numpy(np.ascontiguousarray(xn[:, None, None, :]))
    yt = torch.from_numpy(np.ascontiguousarray(y, np.float32))
    model = cnn1d("location", N_LOCATION_OUTPUTS, (1, 1, x.shape[-1]))
    fit(model, xt, yt, hp, seed, loss_for("location"), name="fig9 localiser")
    return model, stats


def predict(model: nn.Module, stats: tuple | None, x: np.ndarray, norm: str) -> np.ndarray:
    """(N, 2) predicted positions (m) of x (N, T) counts."""
    return infer(model, torch.from_numpy(np.ascontiguousarray(normalise(x, norm, stats)[0][:, None, None, :])))


def bound_to_workspace(pred: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, 2) predicted positions (m) clipped to the box lo..hi, (2,) corners in m.

    The gantry only places objects inside its workspace, so an answer outside
    it is wrong by construction; a model that extrapolates on unfamiliar
    inputs (raw twins in radiance units, tested on real counts) would
    otherwise miss by ~1e6 m and dwarf every other error. Pass the box of the
    model's training labels (`workspace`): data rather than our design
    drawing, so it also holds on the real release."""
    return np.clip(pred, lo, hi)


def workspace(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned box of positions y (N, 2) m: its (2,) lower and upper corners."""
    return y.min(axis=0), y.max(axis=0)


def run_fig9(pairs: Pairs, labels: np.ndarray, t: Transforms, settings: dict, hp: Hyper, split_seed: int) -> pd.DataFrame:
    """Every (fidelity, n real, seed) model of Fig 9 and its test metrics.

    pairs: every real capture with its twin; labels: (N, 2) the true (x, y)
    of each pair, metres; t: the fitted transforms; settings: the `fit`
    config section (test_fraction, fig9: real_samples, seeds, sim_copies);
    hp: Adam/batch/normalisation settings and epochs; split_seed: the seed of
    the real train/test split (the transforms' split).

    Returns one row per model, predictions bounded to its training labels'
    box, and one `MEAN_BASELINE` row per seed: fidelity, n_real, seed, n_sim,
    n_test, then `metrics.regression_metrics` on the real test samples (m, m^2)."""
    if len(labels) != len(pairs.real):
        raise ValueError(f"fig9: {len(labels)} labels for {len(pairs.real)} pairs")
    f9 = settings["fig9"]
    split = split_pairs(pairs.keys, split_seed, settings["test_fraction"])
    train, test = pairs.subset(split.train), pairs.subset(split.test)
    y_train, y_test = labels[split.train], labels[split.test]
    x_test = test.real.reshape(-1, test.bins)
    y_test = np.repeat(y_test, test.real.shape[1], axis=0)
    baseline = regression_metrics(predict_mean_baseline(y_train, len(y_test)), y_test)
    log.info("fig9 predict-the-mean baseline: test RMSE %.4f m", baseline["rmse"])
    rows = []
    for seed in f9["seeds"]:
        for fidelity in FIDELITIES:
            x_sim, y_sim = sim_samples(train, y_train, t, fidelity, f9["sim_copies"], seed)
            for n_real in f9["real_samples"]:
                x_real, y_real, _ = real_samples(train, y_train, n_real, seed)
                y_fit = np.concatenate([y_sim, y_real])
                t0 = time.perf_counter()
                model, stats = train_localiser(np.concatenate([x_sim, x_real]), y_fit, hp, derive_seed(seed, "fig9", "model") % 2**31)
                m = regression_metrics(bound_to_workspace(predict(model, stats, x_test, hp.norm), *workspace(y_fit)), y_test)
                log.info("fig9 seed %d %s + %d real: test RMSE %.4f m (%.1f s)", seed, fidelity, n_real, m["rmse"], time.perf_counter() - t0)
                rows.append({"fidelity": fidelity, "n_real": n_real, "seed": seed, "n_sim": len(x_sim), "n_test": len(x_test), **m})
        rows.append({"fidelity": MEAN_BASELINE, "n_real": 0, "seed": seed, "n_sim": 0, "n_test": len(x_test), **baseline})
    return pd.DataFrame(rows)
