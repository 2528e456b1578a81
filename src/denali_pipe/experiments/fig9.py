"""Fig 9 (paper supplement §11.5.2): sim-to-real transfer of a 1D CNN localiser.

Two panels (`PANELS`): `centre`, the paper's, where the localiser sees the
centre zone only, and `all_zones`, where it sees all 9 zones of the 3x3
grid. For each fidelity of the simulated histograms (`transforms.FIDELITIES`:
raw twins, scaled, scaled+blurred, scaled+blurred+noisy, each zone by its
own transforms, `transforms.ZoneTransforms`) and each number of real
samples n (e.g. 0, 10, 50, 100, 200), a fresh 1D CNN learns the object's
(x, y): the twins of the training captures at that fidelity plus n real
samples, for a fixed number of epochs (no model selection, as the paper).
Beside them, the control (`CONTROL`): the same localiser trained on the
same n real samples alone (n > 0), no twin, for as many optimiser steps as
a twin model (`control_hyper`). Every model is scored on the
same held-out real test split: all repeats of every capture at the held-out
gantry locations (`transforms.split_pairs`, the split the calibration and
the transforms were fitted on): no test location is seen by the twins'
calibration or transforms, the twins' training rows, the control or the
added real samples. A real-sample count above what the training captures
hold is fitted at all of them, and the table says so (`sample_counts`).

Per seed: the model's initialisation and batch order, the draw of real
samples (one permutation of the training captures' repeats, its first n, so
the sets are nested as n grows) and the noise draws. Every model of one seed
starts from the same weights, so the curves differ by their data alone.

Every model's predictions are bounded to the workspace, the box of its
training labels: the localiser's bounded head keeps them within half a
gantry step of it (`Localiser`), and `bound_to_workspace` clips that last
margin, so that raw twins scored on real counts miss by no more than the
box allows.

Beside the models, the table holds the predict-the-mean baseline as rows of
their own (fidelity `MEAN_BASELINE`, one per seed, n_real = n_sim = 0: it
sees no histogram, only the training captures' positions): the same metrics
of predicting the mean training position for every real test sample. The
split is `split_seed`'s, so its rows are equal across seeds; they are kept
per seed so that the baseline aggregates like every model.
"""

from __future__ import annotations

import functools
import logging
import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import torch
from torch import nn

from denali_pipe.core.floor import kept_bins
from denali_pipe.core.seeds import derive_seed, rng_for
from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train.metrics import predict_mean_baseline, regression_metrics
from denali_pipe.train.models import cnn1d
from denali_pipe.train.precision import check_bfloat16, training_precision
from denali_pipe.train.registry import N_LOCATION_OUTPUTS
from denali_pipe.train.training import Hyper, fit, infer, loss_for, position_head, standardise, target_statistics, to_metres
from denali_pipe.transforms.sim_to_real import CENTRE_ZONE, FIDELITIES, GRID, ZONES, Pairs, ZoneTransforms, split_pairs

log = logging.getLogger(__name__)

MEAN_BASELINE = "mean_baseline"  # the `fidelity` of the predict-the-mean baseline's rows
CONTROL = "real_only"  # the `fidelity` of the control's rows: n real samples, no twin
# The column of the real-sample counts asked for that a row's n_real stands
# in for, capped at the training captures' repeats ("" where none was).
CAPPED = "n_real_capped_from"
PANELS = {"centre": 1, "all_zones": GRID}  # panel -> zones per side the localiser sees


def panel_view(real: np.ndarray, sim: np.ndarray, panel: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a panel's localiser sees of the captures: real (C, R, n, n, T)
    counts, sim (C, n*n, N_BINS) twins and their zones' indices (n*n,), n
    the panel's (`PANELS`). real: (C, R, ZONES, T); sim: (C, ZONES, N_BINS)."""
    C, R, _, T = real.shape
    if panel == "centre":
        return real[:, :, [CENTRE_ZONE]].reshape(C, R, 1, 1, T), sim[:, [CENTRE_ZONE]], np.array([CENTRE_ZONE])
    return real.reshape(C, R, GRID, GRID, T), sim, np.arange(ZONES)


def sim_samples(
    sim: np.ndarray, zones: np.ndarray, y: np.ndarray, zt: ZoneTransforms, fidelity: str, copies: int, seed: int, crop: tuple[int, int], kept: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Simulated training samples: each twin sim (C, Z, N_BINS) of zones
    `zones` (Z,) `copies` times at `fidelity`, in the real bins crop
    (start, T), zero outside `kept` (n, n, T), the bins the real captures of
    those zones hold (the preprocessing zeroes a later-starting zone's bins
    before its start; a twin's noise and floor offset there would be a cue no
    capture has). Deterministic fidelities repeat the same histogram; the noisy
    one draws fresh noise per copy, so every fidelity trains on the same
    number of samples. Returns x (copies C, n, n, T) float32, y (copies C, 2) metres."""
    rng = rng_for(seed, "fig9", "noise")
    C, Z, _ = sim.shape
    n = int(round(np.sqrt(Z)))
    zone = np.tile(zones, C)
    flat = sim.reshape(C * Z, -1)
    x = [zt.apply(flat, zone, fidelity, rng)[:, crop[0] : crop[0] + crop[1]].reshape(C, n, n, crop[1]) * kept for _ in range(copies)]
    return np.concatenate(x), np.tile(y, (copies, 1))


def sample_counts(asked: list[int], available: int) -> list[tuple[int, tuple[int, ...]]]:
    """The real-sample counts a tree can fit: each of `asked` capped at the
    `available` real training samples (capture repeats), a count that several
    asked ones cap to fitted once. Returns (n fitted, the asked counts capped
    to it) in ascending n, the second empty where none was. ValueError when
    a count above 0 is asked and no real sample is available: then nothing
    is left to fit."""
    if available <= 0 and any(n > 0 for n in asked):
        raise ValueError(f"fig9: real-sample counts {sorted(asked)} asked for, but the training captures hold no real sample")
    capped: dict[int, list[int]] = {}
    for n in sorted(set(asked)):
        capped.setdefault(min(n, available), [])
        if n > available:
            capped[available].append(n)
    return [(n, tuple(c)) for n, c in sorted(capped.items())]


def real_samples(real: np.ndarray, y: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first `n` of one seeded permutation of every (capture, repeat) of
    real (C, R, ...): x (n, ...) counts, y (n, 2) metres, and their
    (capture row, repeat) indices (n, 2). ValueError if fewer than n exist."""
    N, R = real.shape[:2]
    if n > N * R:
        raise ValueError(f"fig9: {n} real samples asked for, but the training captures hold only {N * R} ({N} captures x {R} repeats)")
    flat = rng_for(seed, "fig9", "real").permutation(N * R)[:n]
    rows, reps = np.divmod(flat, R)
    return real[rows, reps], y[rows], np.stack([rows, reps], axis=1)


def _asked(asked: tuple[int, ...]) -> str:
    return " ".join(map(str, asked))


@dataclass(frozen=True)
class Localiser:
    """A trained Fig 9 localiser and what feeding it needs: its input
    normalisation (`preprocess.normalise`'s kind and (mu, sigma)) and the
    positions' statistics its outputs are standardised by
    (`train.target_statistics`, a clean location cell's)."""

    model: nn.Module
    norm: str
    stats: tuple | None
    target_stats: tuple

    def predict(self, x: np.ndarray) -> np.ndarray:
        """(N, 2) predicted positions (m) of x (N, n, n, T) counts."""
        out = infer(self.model, torch.from_numpy(np.ascontiguousarray(normalise(x, self.norm, self.stats)[0])))
        return to_metres(out, self.target_stats)


def train_localiser(x: np.ndarray, y: np.ndarray, hp: Hyper, seed: int, precision: torch.dtype) -> Localiser:
    """A fresh 1D CNN (location) trained on x (N, n, n, T), y (N, 2) m for
    hp.epochs through `train.fit` (the cells' loop and loss, no model
    selection) in `precision` (`localiser_precision`). It regresses
    standardised positions through the bounded head, as the clean protocol's
    location cells do: in metres its outputs would spend the few epochs
    learning the workspace's offset from 0 (the rows x 0.9-1.3 m)."""
    torch.manual_seed(seed)
    xn, stats = normalise(x, hp.norm)
    target_stats = target_statistics("location", "clean", y)
    xt = torch.from_numpy(np.ascontiguousarray(xn))
    yt = torch.from_numpy(np.ascontiguousarray(standardise(y, target_stats), np.float32))
    model = cnn1d("location", N_LOCATION_OUTPUTS, tuple(x.shape[1:]))
    fit(model, xt, yt, hp, seed, loss_for("location"), name="fig9 localiser", precision=precision, head=position_head(target_stats))
    return Localiser(model, hp.norm, stats, target_stats)


def bound_to_workspace(pred: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(N, 2) predicted positions (m) clipped to the box lo..hi, (2,) corners in m.

    The gantry only places objects inside its workspace, so an answer outside
    it is wrong by construction. The localiser's bounded head already keeps
    its answers within half a gantry step of its training box; this takes
    that margin too. Pass the box of the model's training labels
    (`workspace`): data rather than our design drawing, so it also holds on
    the real release."""
    return np.clip(pred, lo, hi)


def workspace(y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The axis-aligned box of positions y (N, 2) m: its (2,) lower and upper corners."""
    return y.min(axis=0), y.max(axis=0)


@functools.cache
def localiser_precision(setting: str, native_bf16: bool, input_shape: tuple[int, ...]) -> torch.dtype:
    """The dtype the localisers of `input_shape` (n, n, T) train in under
    config `train.precision` (`precision.training_precision`, its check on a
    fresh localiser of that shape, once a process)."""
    with torch.random.fork_rng(devices=[]):
        model = cnn1d("location", N_LOCATION_OUTPUTS, input_shape)
    dtype, check = training_precision(
        setting, "cpu", native_bf16, lambda: check_bfloat16(model, input_shape, "location", N_LOCATION_OUTPUTS, loss_for("location"))
    )
    log.info("fig9 localisers of input %s train in %s (check: %s)", input_shape, str(dtype).removeprefix("torch."), None if check is None else check.record())
    return dtype


def score(x_fit: np.ndarray, y_fit: np.ndarray, x_test: np.ndarray, y_test: np.ndarray, hp: Hyper, seed: int, precision: str, native_bf16: bool) -> dict:
    """Train a localiser on x_fit, y_fit and its test metrics (predictions
    bounded to y_fit's box); precision: config `train.precision`
    (`localiser_precision`)."""
    t0 = time.perf_counter()
    localiser = train_localiser(x_fit, y_fit, hp, seed, localiser_precision(precision, native_bf16, tuple(x_fit.shape[1:])))
    m = regression_metrics(bound_to_workspace(localiser.predict(x_test), *workspace(y_fit)), y_test)
    log.info("fig9 localiser on %d samples: test RMSE %.4f m (%.1f s)", len(x_fit), m["rmse"], time.perf_counter() - t0)
    return m


def control_hyper(hp: Hyper, n_sim: int, n_real: int) -> Hyper:
    """The control's settings: the twin models' (hp) with its epochs scaled
    so that it takes as many optimiser steps on its n_real samples as a twin
    model takes on n_sim + n_real. At the twins' epochs a control of 10
    samples would take 5 steps and stay worse than predicting the mean (the
    demo: 0.18-0.20 m against 0.107), which measures its training budget, not
    what real data alone can teach."""
    steps = hp.epochs * -(-(n_sim + n_real) // hp.batch_size)
    return replace(hp, epochs=-(-steps // -(-n_real // hp.batch_size)))


def run_fig9(
    pairs: Pairs,
    labels: np.ndarray,
    zt: ZoneTransforms,
    settings: dict,
    hp: Hyper,
    split_seed: int,
    precision: str = "float32",
    native_bf16: bool = False,
) -> pd.DataFrame:
    """Every (panel, fidelity or control, n real, seed) model of Fig 9 and its test metrics.

    pairs: every zone of every real capture with its twin (`transforms.build_pairs`);
    labels: (C, 2) the true (x, y) of each capture (`Pairs.captures` order),
    metres; zt: the fitted transforms; settings: the `fit` config section
    (test_fraction, fig9: real_samples, seeds, sim_copies); hp:
    Adam/batch/normalisation settings and epochs; split_seed: the seed of
    the real train/test split (the calibration's and the transforms');
    precision: config `train.precision`, native_bf16: whether this CPU
    multiplies bfloat16 natively (`localiser_precision`).

    Returns one row per model, predictions bounded to its training labels'
    box, and one `MEAN_BASELINE` row per panel and seed: panel, fidelity,
    n_real, `CAPPED`, seed, n_sim, n_test, then `metrics.regression_metrics`
    on the real test samples (m, m^2). A count of real samples above the
    training captures' repeats is fitted at all of them (`sample_counts`)."""
    real, sim, keys = pairs.captures()
    if len(labels) != len(keys):
        raise ValueError(f"fig9: {len(labels)} labels for {len(keys)} captures")
    f9 = settings["fig9"]
    split = split_pairs(keys, split_seed, settings["test_fraction"])
    crop = (pairs.crop_start, pairs.bins)
    y_train, y_test = labels[split.train], np.repeat(labels[split.test], real.shape[1], axis=0)
    baseline = regression_metrics(predict_mean_baseline(y_train, len(y_test)), y_test)
    counts = sample_counts(f9["real_samples"], len(split.train) * real.shape[1])
    for n, asked in counts:
        if asked:
            log.warning("fig9: real-sample counts %s asked for, but the training captures hold only %d: fitted at %d", list(asked), n, n)
    log.info("fig9 predict-the-mean baseline: test RMSE %.4f m", baseline["rmse"])
    rows = []
    for panel in PANELS:
        r_view, s_view, zones = panel_view(real, sim, panel)
        r_train, s_train = r_view[split.train], s_view[split.train]
        x_test = r_view[split.test].reshape(-1, *r_view.shape[2:])
        kept = kept_bins(r_train, axis=(0, 1))
        for seed in f9["seeds"]:
            model_seed = derive_seed(seed, "fig9", "model") % 2**31
            common = {"panel": panel, "seed": seed, "n_test": len(x_test)}
            n_sim = f9["sim_copies"] * len(s_train)
            for n_real, asked in counts:
                if n_real > 0:
                    x_real, y_real, _ = real_samples(r_train, y_train, n_real, seed)
                    m = score(x_real, y_real, x_test, y_test, control_hyper(hp, n_sim, n_real), model_seed, precision, native_bf16)
                    rows.append({**common, "fidelity": CONTROL, "n_real": n_real, CAPPED: _asked(asked), "n_sim": 0, **m})
            for fidelity in FIDELITIES:
                x_sim, y_sim = sim_samples(s_train, zones, y_train, zt, fidelity, f9["sim_copies"], seed, crop, kept)
                for n_real, asked in counts:
                    x_real, y_real, _ = real_samples(r_train, y_train, n_real, seed)
                    m = score(np.concatenate([x_sim, x_real]), np.concatenate([y_sim, y_real]), x_test, y_test, hp, model_seed, precision, native_bf16)
                    rows.append({**common, "fidelity": fidelity, "n_real": n_real, CAPPED: _asked(asked), "n_sim": len(x_sim), **m})
            rows.append({**common, "fidelity": MEAN_BASELINE, "n_real": 0, CAPPED: "", "n_sim": 0, **baseline})
    return pd.DataFrame(rows)
