"""Sim-to-real transforms (paper supplement §11.5.1): scale, blur, noise.

A digital twin's zone transient (`twin.render`, radiance per unit laser
intensity per bin) is made to look like the real background-subtracted
histogram of the same zone (counts) by three transforms, fitted on paired
histograms of the training captures (`fit_transforms`) and applied in order:

1. scale: tau_scale[b] = a * tau_sim[b] ** gamma (a in counts per unit of the
   twin's radiance ** gamma);
2. blur: tau_blur = k * tau_scale, a convolution along time with an 11-bin
   kernel k (non-negative, summing to one), centred ('same' length, zero
   padding): k[HALF + d] weighs a delay of d bins, so it models both the
   pulse shape and the twin's offset of a few bins;
3. noise: tau_noise = mu + (Poisson(mu+) - mu+) + N(0, (a_noise - 1) mu+ + b_noise) + o
   with mu = tau_blur and mu+ = max(mu, 0): the variance between repeats is
   a_noise mu+ + b_noise (counts^2). a_noise >= 1 keeps it at least the
   Poisson variance of the signal; b_noise >= 0 is the flat floor's shot
   noise (and read noise), which background subtraction removes from the
   mean but not from the variance. o ~ N(offset_mean, offset_sd^2) is one
   draw per histogram, the same in every bin (the paper's noise has no such
   term): a capture's floor against the background subtracted from it. The
   room light and the dark level drift between the two captures, and every
   repeat of a capture shares the drift, so the repeats' variance cannot see
   it; across captures it is the largest part of a dim zone's signal (the
   demo's edge zones: sd ~35 counts per bin against an object return of
   10-20, docs/twin.md).

The transforms act on the twin's full 128-bin axis; the fit compares their
output with the real histogram in its cropped bins (`crop_start` onwards), so
the blur near the crop edge sees the twin's bins before it, as the paper's
128-bin transforms do.

The pairs hold every zone of the 3x3 grid, one row per (capture, zone).
The transforms are fitted either once for all zones (`shared`) or per zone
(`per_zone`); `choose_mode` fits both on part of the training captures and
keeps the one with the lower residual on the rest (`ZoneTransforms`).

The fit (`fit_transforms`) is the likelihood of scale, blur and noise
together, and `check_fit` says how far it can be trusted: the peak
signal-to-noise of the captures, bootstrap standard errors and intervals
over captures, and the parameters the captures do not identify (a warning
is logged then).
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar, nnls

from denali_pipe.core import geometry as geo
from denali_pipe.core.atomic import atomic_file
from denali_pipe.core.floor import common_offset, kept_bins, offset_spread
from denali_pipe.core.splits import Split, held_out_groups
from denali_pipe.io.features import read_features
from denali_pipe.twin.render import read_twin

log = logging.getLogger(__name__)

GRID = 3  # the pairs' zone grid (the sim-to-real fit uses the 3x3 captures)
ZONES = GRID * GRID
CENTRE_ZONE = ZONES // 2  # the centre zone's index (row-major): the paper's twin
MODES = ("shared", "per_zone")
KERNEL_BINS = 11  # the paper's blur kernel length L
HALF = KERNEL_BINS // 2
FIDELITIES = ("raw", "scaled", "blurred", "noisy")  # each adds one transform to the one before
# gamma is searched in this range; the hardware's response is near linear.
GAMMA_BOUNDS = (0.1, 10.0)
# Reweighting passes of the fit after its equal-weight one (`fit_transforms`):
# on twin-like pairs at peak SNRs of 0.5-5 the second moves a by about 2e-4
# relative and a third by about 1e-6.
FIT_PASSES = 2
# Noise fit: reweighting passes after the equal-weight one (converged after two).
NOISE_PASSES = 2
# The modelled variance is floored here (counts^2) so that noiseless bins get a finite weight.
VARIANCE_FLOOR = 1e-12
# The parameters with one value each (as `Transforms` names them); the kernel is the other.
SCALARS = ("a", "gamma", "a_noise", "b_noise")
# The floor offset's: bootstrapped beside SCALARS, but not judged by their
# standard error against their value, as 0 (no offset) is a value they take.
OFFSET = ("offset_mean", "offset_sd")


@dataclass(frozen=True)
class Pairs:
    """Real captures and their twins, one row per capture (set, location)
    and zone, capture-major (the ZONES rows of a capture follow each other).

    real: (N, R, T) float32 background-subtracted counts of one zone's R
    repeats, bins crop_start .. crop_start + T - 1.
    sim: (N, N_BINS) float32 the twin's transient of the same zone, object,
    size and location on the full time axis (radiance per unit laser intensity).
    keys: N rows: set, object, size, location, zone (row-major index).
    """

    real: np.ndarray
    sim: np.ndarray
    keys: pd.DataFrame
    crop_start: int

    @property
    def bins(self) -> int:
        return self.real.shape[-1]

    def crop(self, h: np.ndarray) -> np.ndarray:
        """The real data's bins of full-axis histograms (..., N_BINS) -> (..., T)."""
        return h[..., self.crop_start : self.crop_start + self.bins]

    def subset(self, rows: np.ndarray) -> Pairs:
        return Pairs(self.real[rows], self.sim[rows], self.keys.iloc[rows].reset_index(drop=True), self.crop_start)

    def zone(self, z: int) -> Pairs:
        """The rows of zone z."""
        return self.subset(np.flatnonzero(self.keys["zone"].to_numpy() == z))

    def captures(self) -> tuple[np.ndarray, np.ndarray, pd.DataFrame]:
        """Per capture: real (C, R, ZONES, T), sim (C, ZONES, N_BINS) and the keys of its centre-zone row."""
        if len(self.keys) % ZONES or not (self.keys["zone"].to_numpy().reshape(-1, ZONES) == np.arange(ZONES)).all():
            raise ValueError("captures(): the pairs do not hold every zone of each capture in order")
        C = len(self.keys) // ZONES
        real = self.real.reshape(C, ZONES, *self.real.shape[1:]).transpose(0, 2, 1, 3)
        keys = self.keys.iloc[CENTRE_ZONE::ZONES].drop(columns="zone").reset_index(drop=True)
        return real, self.sim.reshape(C, ZONES, -1), keys


def split_pairs(keys: pd.DataFrame, seed: int, test_fraction: float) -> Split:
    """The real train/test split of the pairs (rows of `keys`): gantry
    locations held out whole, every set's captures there with them (drawn
    like the benchmark's `location_held_out`, `splits.held_out_groups`).
    The calibration, the transforms, the twins' training rows and Fig 9's
    control and real samples all take the training side, so none of them
    meets a test location's background or geometry in another set's capture,
    as a split by capture (set, location) let them."""
    locations = keys["location"].to_numpy()
    train = np.isin(locations, held_out_groups(locations.tolist(), seed, test_fraction)[0])
    return Split(np.flatnonzero(train), np.flatnonzero(~train))


def read_real(feature_paths: list[Path]) -> tuple[np.ndarray, pd.DataFrame, int]:
    """Every capture of the 3x3 light-on feature stores: real (N, R, 3, 3, T)
    float32 background-subtracted counts, keys (N rows: set, object, size,
    location) and the first bin kept. Sets in name order, locations
    ascending. ValueError naming the file when a set is not 3x3 light-on or
    the crop windows differ."""
    real, keys, crop = [], [], None
    for path in sorted(map(Path, feature_paths), key=lambda p: p.name):
        cs, f = read_features(path)
        if cs.resolution != "3x3" or cs.light != "lighton":
            raise ValueError(f"{path}: set {cs.name} is not a 3x3 light-on capture set; the sim-to-real pairs use those only")
        if crop is None:
            crop = (f.crop_start, f.values.shape[-1])
        elif (f.crop_start, f.values.shape[-1]) != crop:
            raise ValueError(f"{path}: {f.values.shape[-1]} bins from bin {f.crop_start}, the other sets have {crop[1]} from bin {crop[0]}")
        real.append(f.values)
        keys.append(pd.DataFrame({"set": cs.name, "object": cs.object, "size": cs.size, "location": f.locations.astype(np.int64)}))
    if not real:
        raise ValueError("no feature stores given")
    return np.concatenate(real).astype(np.float32), pd.concat(keys, ignore_index=True), crop[0]


def build_pairs(feature_paths: list[Path], twin_paths: list[Path]) -> Pairs:
    """Pair every zone of every capture of the 3x3 light-on feature stores
    (`read_real`) with the twin of its object and size at the same location
    and zone. ValueError naming the file when a twin is missing a set or a location."""
    twins = {}
    for path in twin_paths:
        t = read_twin(Path(path))
        twins[(t.attrs["object"]["name"], t.attrs["size"])] = t
    real, keys, crop = read_real(feature_paths)
    sim = []
    for (name, size), rows in keys.groupby(["object", "size"], sort=False):
        if (name, size) not in twins:
            raise ValueError(f"no twin store of {name} {size} among {[str(t.path) for t in twins.values()]}")
        twin = twins[(name, size)]
        missing = sorted(set(rows["location"].tolist()) - set(twin.locations.tolist()))
        if missing:
            raise ValueError(f"{twin.path}: the twin of {name} {size} lacks locations {missing}")
    for name, size, location in zip(keys["object"], keys["size"], keys["location"]):
        sim.append(twins[(name, size)].histogram(location, "3x3").reshape(ZONES, geo.N_BINS))
    N, R = real.shape[:2]
    long_keys = keys.loc[keys.index.repeat(ZONES)].reset_index(drop=True)
    long_keys["zone"] = np.tile(np.arange(ZONES), N)
    real = real.reshape(N, R, ZONES, -1).transpose(0, 2, 1, 3).reshape(N * ZONES, R, -1)
    return Pairs(real, np.concatenate(sim).astype(np.float32), long_keys, crop)


# --- the transforms ---------------------------------------------------------------------


@dataclass(frozen=True)
class Transforms:
    """Fitted parameters: a (counts / radiance**gamma), gamma, kernel
    (KERNEL_BINS,) summing to one, a_noise (>= 1), b_noise (counts^2, >= 0),
    and the capture-level floor offset's mean and sd (counts; 0 and 0 in a
    file written before the offset was fitted, which then adds none)."""

    a: float
    gamma: float
    kernel: tuple[float, ...]
    a_noise: float
    b_noise: float
    offset_mean: float = 0.0
    offset_sd: float = 0.0

    def to_dict(self) -> dict:
        return {**asdict(self), "kernel": list(self.kernel)}


def scale(sim: np.ndarray, a: float, gamma: float) -> np.ndarray:
    """a * sim ** gamma, elementwise. Negative inputs count as 0: a
    fractional power of a negative number is undefined, and a render's
    radiance is never negative."""
    return (a * np.maximum(sim, 0.0) ** gamma).astype(np.float32)


def blur(h: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Convolve (..., B) with a (KERNEL_BINS,) kernel along the last axis,
    centred, zero padded, same length B."""
    k = np.asarray(kernel, np.float64)
    flat = h.reshape(-1, h.shape[-1]).astype(np.float64)
    out = np.stack([np.convolve(row, k, mode="same") for row in flat]) if len(flat) else flat
    return out.reshape(h.shape).astype(np.float32)


def add_noise(mu: np.ndarray, t: Transforms, rng: np.random.Generator) -> np.ndarray:
    """One draw of the noise around mean `mu` (..., B) counts: per bin
    Poisson-Gaussian of variance a_noise * max(mu, 0) + b_noise, plus one
    floor offset per histogram (N(offset_mean, offset_sd^2), every bin)."""
    mu = np.asarray(mu, np.float64)
    pos = np.maximum(mu, 0.0)
    poisson = rng.poisson(pos) - pos
    gauss = rng.normal(0.0, 1.0, mu.shape) * np.sqrt((t.a_noise - 1.0) * pos + t.b_noise)
    offset = rng.normal(t.offset_mean, t.offset_sd, (*mu.shape[:-1], 1))
    return (mu + poisson + gauss + offset).astype(np.float32)


def apply(sim: np.ndarray, t: Transforms, fidelity: str, rng: np.random.Generator | None = None) -> np.ndarray:
    """Simulated histograms (..., N_BINS) at one fidelity of FIDELITIES:
    raw (as rendered), scaled, scaled+blurred, or scaled+blurred+noisy
    (a draw from `rng`, which that fidelity requires)."""
    if fidelity not in FIDELITIES:
        raise ValueError(f"unknown fidelity {fidelity!r}; expected one of {FIDELITIES}")
    if fidelity == "raw":
        return np.asarray(sim, np.float32)
    h = scale(sim, t.a, t.gamma)
    if fidelity == "scaled":
        return h
    h = blur(h, np.array(t.kernel))
    if fidelity == "blurred":
        return h
    if rng is None:
        raise ValueError("the noisy fidelity needs a random generator")
    return add_noise(h, t, rng)


# --- the fit ----------------------------------------------------------------------------


def reach(h: np.ndarray, crop_start: int, bins: int) -> np.ndarray:
    """(N, N_BINS) full-axis histograms -> (N, bins + KERNEL_BINS - 1): the
    bins that the blur draws the real bins crop_start .. crop_start + bins - 1
    from, HALF more on either side (zero beyond the time axis)."""
    return np.pad(h, ((0, 0), (HALF, HALF)))[:, crop_start : crop_start + bins + 2 * HALF]


def shifted_copies(window: np.ndarray, bins: int) -> np.ndarray:
    """(N, bins + KERNEL_BINS - 1) `reach` windows -> (N, bins, KERNEL_BINS):
    column j is the real bins blurred by the unit kernel e_j (a delay of
    j - HALF bins), so the real bins of `blur(h, k)` are this times k."""
    return np.stack([window[:, 2 * HALF - j : 2 * HALF - j + bins] for j in range(KERNEL_BINS)], axis=-1)


def twin_window(sim: np.ndarray, crop_start: int, bins: int) -> np.ndarray:
    """The twins' `reach` windows (N, bins + KERNEL_BINS - 1) in float64,
    negative radiance counted as 0 (as `scale` does). ValueError when no bin
    is positive: there is nothing to scale."""
    window = np.maximum(reach(sim.astype(np.float64), crop_start, bins), 0.0)
    if not (window > 0).any():
        raise ValueError("fit_transforms: no pair has a positive simulated bin in reach of the real bins; nothing to scale")
    return window


def one_level(window: np.ndarray) -> bool:
    """Whether every positive bin of the twins' windows holds the same
    radiance (to 1e-6): then tau_sim ** gamma only rescales the twins, which
    a absorbs, and gamma is not identified."""
    levels = window[window > 0]
    return bool(levels.min() >= levels.max() * (1 - 1e-6))


def _nonneg_lstsq(gram: np.ndarray, moment: np.ndarray, const: float) -> tuple[np.ndarray, float]:
    """argmin over c >= 0 of the quadratic c'Gc - 2 m'c + const (a residual
    sum of squares given by its normal equations: gram G (K, K), moment m
    (K,)), and its minimum. Solved as the NNLS |M c - z|^2 with M'M = G and
    M'z = m from G's eigendecomposition; directions without curvature are
    dropped (m, a combination of the design's columns, has no part along them)."""
    lam, vec = np.linalg.eigh(gram)
    keep = lam > lam.max() * 1e-12
    root = np.sqrt(lam[keep])
    c, _ = nnls(root[:, None] * vec[:, keep].T, vec[:, keep].T @ moment / root)
    return c, float(const - 2 * moment @ c + c @ gram @ c)


def fit_mean(real_mean: np.ndarray, weights: np.ndarray, sim: np.ndarray, crop_start: int) -> tuple[float, float, np.ndarray]:
    """(a, gamma, kernel) minimising sum w (real_mean - k * (a tau_sim ** gamma))^2
    over the real bins: weighted least squares of the scale and the blur together.

    real_mean: (N, T) repeat means (counts); weights: (N, T), the inverse
    variance of each (1 / counts^2); sim: (N, N_BINS) the twins.

    The model is linear in c = a k, which is >= 0 because a > 0 and k >= 0,
    so for a given gamma the best c is a non-negative least squares on the
    KERNEL_BINS `shifted_copies` of tau_sim ** gamma; then a = sum c (k sums
    to one) and k = c / a. gamma minimises the residual of that best c
    (a profile in one variable, searched in GAMMA_BOUNDS; it has one
    minimum on twin-like data, checked on a grid down to a peak SNR of 0.25).
    No log and no sum over chosen bins is taken: every bin enters as it is,
    zero and negative ones too, so noise does not bias the fit at low signal
    (a fit of log masses over the bins near the twin's peak lost tens of % of
    a below a peak SNR of about 1). gamma is 1 when the twins hold one level
    (`one_level`). ValueError when the best c is 0: no scaled twin correlates
    with the real counts. The captures' floor offsets are taken out before
    (`floor_offsets`)."""
    T = real_mean.shape[1]
    window = twin_window(sim, crop_start, T)
    s_ref = window.max()
    s = window / s_ref  # <= 1, so no power of it under- or overflows; a is rescaled at the end
    y, w = real_mean.astype(np.float64).ravel(), weights.astype(np.float64).ravel()
    wy = w * y

    def best_c(gamma: float) -> tuple[np.ndarray, float]:
        x = shifted_copies(s**gamma, T).reshape(-1, KERNEL_BINS)
        return _nonneg_lstsq(x.T @ (w[:, None] * x), x.T @ wy, float(y @ wy))

    if one_level(window):
        gamma = 1.0
    else:
        gamma = float(minimize_scalar(lambda g: best_c(g)[1], bounds=GAMMA_BOUNDS, method="bounded", options={"xatol": 1e-6}).x)
    c, _ = best_c(gamma)
    if not c.sum() > 0:
        raise ValueError(
            "fit_transforms: the best scale is 0 (no scaled twin correlates positively with the real counts); the real captures hold no object signal"
        )
    return float(c.sum() / s_ref**gamma), gamma, c / c.sum()


def _check_repeats(real: np.ndarray, who: str) -> None:
    if real.ndim != 3 or real.shape[1] < 2:
        raise ValueError(f"{who}: needs (N, R >= 2, T) repeats to measure the noise, got {real.shape}")


def fit_noise(real: np.ndarray, mu: np.ndarray) -> tuple[float, float]:
    """(a_noise, b_noise) of Var = a_noise * max(mu, 0) + b_noise, a_noise >= 1, b_noise >= 0.

    real: (N, R, T) counts of R >= 2 repeats; mu: (N, T) the modelled mean
    (the blurred twin in the real bins). The variance is measured across the
    repeats of each capture, per bin (unbiased sample variance, ddof 1): the
    repeats are independent draws of the same scene, so this is the noise
    alone, free of any mismatch between twin and real. It leaves out the
    noise of the subtracted background mean, which all repeats of a capture
    share. Every bin of every capture enters; the bins without signal pin
    b_noise. Weighted least squares of the variances on max(mu, 0): a sample
    variance's spread is proportional to the variance itself, so each bin is
    weighted by 1 / Var^2 of the previous solution (NOISE_PASSES passes from
    equal weights; that is the likelihood of the sample variances, scaled
    chi-square). Each pass is constrained: if the free solution breaks a
    bound, the best solution on that bound."""
    _check_repeats(real, "fit_noise")
    v = real.astype(np.float64).var(axis=1, ddof=1).ravel()
    m = np.maximum(mu.astype(np.float64), 0.0).ravel()
    ab = _bounded_lstsq(m, v, np.ones_like(v))
    for _ in range(NOISE_PASSES):
        ab = _bounded_lstsq(m, v, 1.0 / noise_variance(m, *ab) ** 2)
    return ab


def noise_variance(mu: np.ndarray, a_noise: float, b_noise: float) -> np.ndarray:
    """The modelled variance of one repeat, a_noise * max(mu, 0) + b_noise
    (counts^2), floored at VARIANCE_FLOOR so that its inverse is finite."""
    return np.maximum(a_noise * np.maximum(mu, 0.0) + b_noise, VARIANCE_FLOOR)


def _bounded_lstsq(m: np.ndarray, v: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """argmin over a >= 1, b >= 0 of sum w (a m + b - v)^2: the free solution
    if feasible, else the better of the solutions on a = 1 and on b = 0."""
    w = w / w.sum()
    candidates = []
    mw, vw = (w * m).sum(), (w * v).sum()
    var_m = (w * (m - mw) ** 2).sum()
    if var_m > 0:
        a = (w * (m - mw) * (v - vw)).sum() / var_m
        candidates.append((a, vw - a * mw))
    candidates.append((1.0, max(float((w * (v - m)).sum()), 0.0)))  # on a = 1
    mm = float((w * m * m).sum())
    candidates.append((max(float((w * m * v).sum()) / mm, 1.0) if mm > 0 else 1.0, 0.0))  # on b = 0
    feasible = [(float(a), float(b)) for a, b in candidates if a >= 1.0 and b >= 0.0]
    return min(feasible, key=lambda ab: float((w * (ab[0] * m + ab[1] - v) ** 2).sum()))


def model_mean(pairs: Pairs, a: float, gamma: float, kernel: np.ndarray) -> np.ndarray:
    """(N, T) the scaled, blurred twins in the real bins (counts)."""
    return pairs.crop(blur(scale(pairs.sim, a, gamma), kernel))


def fit_transforms(pairs: Pairs) -> Transforms:
    """Fit the three transforms together on `pairs` (the training captures):
    the Gaussian likelihood of the repeat means (`fit_mean`, with the noise
    model's variance) alternating with that of the repeats' sample variances
    (`fit_noise`, around the current mean). The first mean fit weighs every
    bin equally; each of FIT_PASSES passes then refits the noise and the
    mean with weights R / Var, Var the modelled variance of one repeat; the
    noise is refitted around the final mean."""
    if len(pairs.real) == 0:
        raise ValueError("fit_transforms: no pairs to fit on")
    _check_repeats(pairs.real, "fit_transforms")
    repeats = pairs.real.shape[1]
    real_mean = pairs.real.mean(axis=1, dtype=np.float64)
    offsets, n_free = floor_offsets(real_mean, pairs.sim, pairs.crop_start)
    pairs = replace(pairs, real=pairs.real - (np.float32(common_offset(offsets[n_free > 0])) * kept_bins(real_mean))[:, None, :])
    real_mean = pairs.real.mean(axis=1, dtype=np.float64)
    a, gamma, kernel = fit_mean(real_mean, np.ones_like(real_mean), pairs.sim, pairs.crop_start)
    for _ in range(FIT_PASSES):
        mu = model_mean(pairs, a, gamma, kernel)
        weights = repeats / noise_variance(mu, *fit_noise(pairs.real, mu))
        a, gamma, kernel = fit_mean(real_mean, weights, pairs.sim, pairs.crop_start)
    a_noise, b_noise = fit_noise(pairs.real, model_mean(pairs, a, gamma, kernel))
    free = n_free > 0
    if free.sum() < 2:
        return Transforms(a, gamma, tuple(float(k) for k in kernel), a_noise, b_noise)
    # a capture's offset is its mean over its twin-free bins, whose noise (b_noise per repeat) is taken out of their spread
    o, noise = offsets[free], b_noise / repeats / n_free[free]
    return Transforms(a, gamma, tuple(float(k) for k in kernel), a_noise, b_noise, float(o.mean()), float(np.sqrt(offset_spread(o, noise))))


def floor_offsets(real_mean: np.ndarray, sim: np.ndarray, crop_start: int) -> tuple[np.ndarray, np.ndarray]:
    """Each capture's floor offset (N,) counts and the bins it was read
    from (N,): its repeat mean (N, T) averaged over its twin-free bins, the
    kept bins (`kept_bins`) that no part of its twin sim (N, N_BINS) reaches
    through the blur (the first bins after the direct return's end and the
    last, on the demo). There the twin predicts nothing, so whatever the
    capture holds is its floor against the background's. Rows without such
    a bin get the mean of the others' (0 when no row has one)."""
    kept = kept_bins(real_mean)
    window = reach(np.maximum(sim.astype(np.float64), 0.0), crop_start, real_mean.shape[1])
    near = shifted_copies(window, real_mean.shape[1]).max(axis=-1) > 0
    free = kept & ~near
    n = free.sum(axis=1)
    offsets = np.where(free, real_mean, 0.0).sum(axis=1) / np.maximum(n, 1)
    fill = offsets[n > 0].mean() if (n > 0).any() else 0.0
    return np.where(n > 0, offsets, fill), n


# --- how far a fit can be trusted -------------------------------------------------------


@dataclass(frozen=True)
class Bootstrap:
    """The fit's spread over `resamples` refits, each on as many captures
    drawn with replacement (a capture's repeats stay together), drawn from
    `seed`. se: the standard error (sd over the refits, ddof 1) of each of
    SCALARS and OFFSET (a float) and of each kernel tap ("kernel": a list);
    interval: the percentile interval of coverage `level`, [low, high] per
    parameter (per tap for the kernel); kernel_l1: the mean L1 distance of
    the refits' kernels from the fitted kernel; failed: the refits that found
    no positive scale (left out of se and interval)."""

    resamples: int
    seed: int
    level: float
    se: dict
    interval: dict
    kernel_l1: float
    failed: int


@dataclass(frozen=True)
class FitCheck:
    """peak_snr: the training captures' median `peak_snr`; bootstrap: the
    fit's spread; noise_se: `noise_information_se` (None where the means do
    not vary); unidentified: each parameter that the captures do not pin
    down, with why (empty when the fit is identifiable)."""

    peak_snr: float
    bootstrap: Bootstrap
    noise_se: dict | None
    unidentified: dict

    @property
    def identifiable(self) -> bool:
        return not self.unidentified

    def to_dict(self) -> dict:
        return {
            "peak_snr": self.peak_snr,
            "identifiable": self.identifiable,
            "unidentified": self.unidentified,
            "noise_se": self.noise_se,
            "bootstrap": asdict(self.bootstrap),
        }


def peak_snr(pairs: Pairs, t: Transforms) -> float:
    """Median over the pairs of the modelled mean's peak in the real bins
    over the modelled noise sd at that peak, for one repeat:
    max mu / sqrt(a_noise max mu + b_noise), dimensionless (0 without signal)."""
    peak = np.maximum(model_mean(pairs, t.a, t.gamma, np.array(t.kernel)).max(axis=1), 0.0)
    return float(np.median(peak / np.sqrt(noise_variance(peak, t.a_noise, t.b_noise))))


def bootstrap(pairs: Pairs, t: Transforms, resamples: int, seed: int, level: float) -> Bootstrap:
    """Refit `resamples` times on captures drawn with replacement from
    `pairs` (t: the fit on all of them); see `Bootstrap`."""
    if resamples < 2 or not 0 < level < 1:
        raise ValueError(f"bootstrap: needs >= 2 resamples and a level in (0, 1), got {resamples} and {level}")
    rng = np.random.default_rng(seed)
    n = len(pairs.real)
    fits = []
    for _ in range(resamples):
        # a resample of weak captures may hold no object signal at all: that
        # refit has no scale, which says the captures barely pin the fit down
        try:
            fits.append(fit_transforms(pairs.subset(rng.integers(0, n, n))))
        except ValueError:
            continue
    if len(fits) < 2:
        raise ValueError(f"bootstrap: {resamples - len(fits)} of {resamples} refits found no positive scale; the captures do not identify the transforms")
    values = {p: np.array([getattr(f, p) for f in fits]) for p in (*SCALARS, *OFFSET, "kernel")}
    tails = (50 * (1 - level), 50 * (1 + level))  # percentiles
    return Bootstrap(
        resamples,
        seed,
        level,
        {p: v.std(axis=0, ddof=1).tolist() for p, v in values.items()},
        {p: np.percentile(v, tails, axis=0).T.tolist() for p, v in values.items()},
        float(np.abs(values["kernel"] - np.array(t.kernel)).sum(axis=1).mean()),
        resamples - len(fits),
    )


def noise_information_se(real: np.ndarray, mu: np.ndarray, a_noise: float, b_noise: float) -> dict | None:
    """{"a_noise", "b_noise"}: their standard errors from the information of
    the repeats' sample variances, the bounds a_noise >= 1, b_noise >= 0
    ignored. real: (N, R, T) counts; mu: (N, T) the modelled mean. A bin's
    sample variance over R repeats varies by 2 Var^2 / (R - 1) about its
    Var (Gaussian noise), so `fit_noise`'s weighted least squares of it on
    max(mu, 0) has the textbook line-fit variances, with weights
    w = (R - 1) / (2 Var^2): 1 / S for the slope and sum(w m^2) / (sum(w) S)
    for the intercept, S = sum w (m - weighted mean m)^2. None when the
    modelled means do not vary (S = 0): then no slope can be told from the floor."""
    m = np.maximum(mu.astype(np.float64), 0.0).ravel()
    w = (real.shape[1] - 1) / (2 * noise_variance(m, a_noise, b_noise) ** 2)
    spread = float((w * (m - (w * m).sum() / w.sum()) ** 2).sum())
    if spread <= 0:
        return None
    return {"a_noise": float(np.sqrt(1 / spread)), "b_noise": float(np.sqrt((w * m * m).sum() / w.sum() / spread))}


def check_fit(pairs: Pairs, t: Transforms, resamples: int, seed: int, level: float, max_rel_se: float) -> FitCheck:
    """Bootstrap the fit `t` of `pairs` and judge which parameters the
    captures identify: a scalar whose standard error exceeds `max_rel_se`
    of its value, or a kernel whose refits lie further than `max_rel_se`
    from it (mean L1; the kernel's own L1 norm is 1), is not identified;
    nor is gamma when the twins hold one level (`one_level`). A noise term's
    standard error is the larger of the bootstrap's and the information's
    (`noise_information_se`): a fit on a bound (a_noise = 1, b_noise = 0, as
    real noise may well be) has refits piled on that bound, whose spread
    understates what the captures leave open, while the bootstrap holds even
    where the noise is not Gaussian. Logs a warning naming the parameters
    not identified and the peak SNR."""
    boot = bootstrap(pairs, t, resamples, seed, level)
    noise_se = noise_information_se(pairs.real, model_mean(pairs, t.a, t.gamma, np.array(t.kernel)), t.a_noise, t.b_noise)
    unidentified = {}
    if one_level(twin_window(pairs.sim, pairs.crop_start, pairs.bins)):
        unidentified["gamma"] = "the twins hold one radiance level, which a absorbs: gamma is set to 1"
    if noise_se is None:
        unidentified |= dict.fromkeys(("a_noise", "b_noise"), "the modelled means do not vary, so the variance's slope cannot be told from its floor")
    for p in SCALARS:
        value, se = abs(getattr(t, p)), max(boot.se[p], (noise_se or {}).get(p, 0.0))
        rel = se / value if value > 0 else (0.0 if se == 0 else np.inf)
        if rel > max_rel_se and p not in unidentified:
            unidentified[p] = f"standard error {rel:.1%} of its value (more than {max_rel_se:.1%})"
    if boot.failed:
        unidentified["a"] = f"{boot.failed} of {boot.resamples} refits found no positive scale"
    if boot.kernel_l1 > max_rel_se:
        unidentified["kernel"] = f"the bootstrap's kernels lie {boot.kernel_l1:.3f} from it (mean L1, more than {max_rel_se})"
    check = FitCheck(peak_snr(pairs, t), boot, noise_se, unidentified)
    if unidentified:
        why = "; ".join(f"{p}: {reason}" for p, reason in unidentified.items())
        log.warning("the transforms fitted on %d captures (peak SNR %.2f) are not identifiable: %s", len(pairs.real), check.peak_snr, why)
    return check


# --- per zone or shared -----------------------------------------------------------------


@dataclass(frozen=True)
class ZoneTransforms:
    """The transforms of every zone: mode (`shared` or `per_zone`) and one
    Transforms per zone (row-major; the same one ZONES times when shared)."""

    mode: str
    zones: tuple[Transforms, ...]

    def apply(self, sim: np.ndarray, zone: np.ndarray, fidelity: str, rng: np.random.Generator | None = None) -> np.ndarray:
        """`apply` row by row: sim (N, N_BINS), zone (N,) each row's zone index."""
        out = np.empty(sim.shape, np.float32)
        for z in np.unique(zone):
            rows = np.flatnonzero(zone == z)
            out[rows] = apply(sim[rows], self.zones[int(z)], fidelity, rng)
        return out


def fit_zone_transforms(pairs: Pairs, mode: str) -> ZoneTransforms:
    """Fit the transforms on `pairs` once for all zones or once per zone."""
    if mode not in MODES:
        raise ValueError(f"unknown transforms mode {mode!r}; expected one of {MODES}")
    if mode == "shared":
        return ZoneTransforms(mode, (fit_transforms(pairs),) * ZONES)
    zones = []
    for z in range(ZONES):
        try:
            zones.append(fit_transforms(pairs.zone(z)))
        except ValueError as e:
            raise ValueError(f"zone {z}: {e}") from None
    return ZoneTransforms(mode, tuple(zones))


def mean_residual(pairs: Pairs, zt: ZoneTransforms) -> float:
    """||repeat mean - modelled mean||^2 / ||repeat mean||^2 over every row of
    `pairs` (the modelled mean: the scaled, blurred twin of the row's zone)."""
    mu = pairs.crop(zt.apply(pairs.sim, pairs.keys["zone"].to_numpy(), "blurred"))
    y = pairs.real.mean(axis=1, dtype=np.float64)
    return float(((y - mu) ** 2).sum() / (y**2).sum())


def choose_mode(train: Pairs, seed: int, fraction: float) -> tuple[str, dict, dict]:
    """The mode of the lower residual (`mean_residual`) on a share `fraction`
    of the training captures held out of the fits of both modes (by capture,
    drawn with `seed`). A mode that cannot be fitted is rejected: per zone,
    a zone whose captures hold no object signal (a dim corner of the
    sensor's centre-weighted field) has no scale of its own, and the shared
    transforms, fitted on every zone at once, still have one. Returns the
    mode, {mode: residual} of the modes fitted and {mode: why} of those
    rejected; ValueError when neither mode can be fitted."""
    inner = split_pairs(train.keys, seed, fraction)
    fit_on, held = train.subset(inner.train), train.subset(inner.test)
    residual, rejected = {}, {}
    for m in MODES:
        try:
            residual[m] = mean_residual(held, fit_zone_transforms(fit_on, m))
        except ValueError as e:
            rejected[m] = str(e)
    if not residual:
        raise ValueError(f"choose_mode: no transforms mode can be fitted: {rejected}")
    return min(residual, key=residual.get), residual, rejected


# --- the file ---------------------------------------------------------------------------


def write_transforms(path: Path, zt: ZoneTransforms, checks: list[FitCheck], axis: geo.TimeAxis, record: dict) -> None:
    """transforms.json: the mode, one entry per zone (row-major) with its
    parameters and check (under "check"), the kernel's bins (their number and
    width on `axis`, the captures' time axis) and `record` (what they were
    fitted on)."""
    zones = [{**t.to_dict(), "check": c.to_dict()} for t, c in zip(zt.zones, checks)]
    with atomic_file(Path(path)) as tmp:
        body = {"mode": zt.mode, "zones": zones, "kernel_bins": KERNEL_BINS, "bin_width_opl": axis.bin_width_opl, **record}
        tmp.write_text(json.dumps(body, indent=1) + "\n")


def _transforms(d: dict, path: Path) -> Transforms:
    try:
        t = Transforms(
            float(d["a"]), float(d["gamma"]), tuple(float(k) for k in d["kernel"]), float(d["a_noise"]), float(d["b_noise"]),
            float(d.get("offset_mean", 0.0)), float(d.get("offset_sd", 0.0)),
        )  # fmt: skip
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a transforms file ({type(e).__name__}: {e})") from None
    if len(t.kernel) != KERNEL_BINS or not (t.a > 0 and t.gamma > 0 and t.a_noise >= 1 and t.b_noise >= 0 and t.offset_sd >= 0):
        raise ValueError(f"{path}: parameters out of range: {t.to_dict()}")
    return t


def _zones(path: Path) -> tuple[dict, list[dict]]:
    try:
        d = json.loads(Path(path).read_text())
    except ValueError as e:
        raise ValueError(f"{path}: not a transforms file ({type(e).__name__}: {e})") from None
    if "zones" not in d or "mode" not in d:
        raise ValueError(f"{path}: no per-zone transforms ('mode', 'zones'): the file predates every-zone twins; refit it with `denali transforms`")
    if d["mode"] not in MODES or len(d["zones"]) != ZONES:
        raise ValueError(f"{path}: mode {d['mode']!r} with {len(d['zones'])} zones, expected one of {MODES} with {ZONES}")
    return d, d["zones"]


def read_transforms(path: Path) -> ZoneTransforms:
    """Read transforms.json's parameters; ValueError naming the file when a
    parameter is missing or out of range, or the file predates per-zone fits."""
    d, zones = _zones(path)
    return ZoneTransforms(d["mode"], tuple(_transforms(z, path) for z in zones))


def read_fit_check(path: Path) -> list[FitCheck]:
    """Read transforms.json's check of each zone; ValueError naming the file
    when one is missing or malformed."""
    _, zones = _zones(path)
    out = []
    for z in zones:
        try:
            c, b = z["check"], z["check"]["bootstrap"]
            boot = Bootstrap(
                int(b["resamples"]), int(b["seed"]), float(b["level"]), dict(b["se"]), dict(b["interval"]), float(b["kernel_l1"]), int(b["failed"])
            )
            noise_se = None if c["noise_se"] is None else {p: float(c["noise_se"][p]) for p in ("a_noise", "b_noise")}
            out.append(FitCheck(float(c["peak_snr"]), boot, noise_se, dict(c["unidentified"])))
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{path}: malformed 'check' entry ({type(e).__name__}: {e})") from None
    return out
