"""Sim-to-real transforms (paper supplement §11.5.1): scale, blur, noise.

A digital twin's centre-zone transient (`twin.render`, radiance per unit laser
intensity per bin) is made to look like a real background-subtracted
centre-zone histogram (counts) by three transforms, fitted once on paired
histograms of the training captures (`fit_transforms`) and applied in order:

1. scale: tau_scale[b] = a * tau_sim[b] ** gamma (a in counts per unit of the
   twin's radiance ** gamma);
2. blur: tau_blur = k * tau_scale, a convolution along time with an 11-bin
   kernel k (non-negative, summing to one), centred ('same' length, zero
   padding): k[HALF + d] weighs a delay of d bins, so it models both the
   pulse shape and the twin's offset of a few bins;
3. noise: tau_noise = mu + (Poisson(mu+) - mu+) + N(0, (a_noise - 1) mu+ + b_noise)
   with mu = tau_blur and mu+ = max(mu, 0): the total variance is
   a_noise mu+ + b_noise (counts^2) and its mean is mu. a_noise >= 1 keeps it
   at least the Poisson variance of the signal; b_noise >= 0 is the flat
   floor's shot noise (and read noise), which background subtraction removes
   from the mean but not from the variance.

The transforms act on the twin's full 128-bin axis; the fit compares their
output with the real histogram in its cropped bins (`crop_start` onwards), so
the blur near the crop edge sees the twin's bins before it, as the paper's
128-bin transforms do.
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from scipy.optimize import minimize_scalar

from denali_pipe import geometry as geo
from denali_pipe.atomic import atomic_file
from denali_pipe.io.features import read_features
from denali_pipe.splits import Split, held_out_groups
from denali_pipe.twin.render import read_twin

log = logging.getLogger(__name__)

CENTRE = (1, 1)  # the centre zone of the 3x3 grid: the zone the twin renders
KERNEL_BINS = 11  # the paper's blur kernel length L
HALF = KERNEL_BINS // 2
FIDELITIES = ("raw", "scaled", "blurred", "noisy")  # each adds one transform to the one before
# The scaling fit pools pairs into this many groups of similar simulated mass
# before taking logs (see `fit_scale`): enough points to pin gamma, each group
# holding enough pairs that its summed real mass stands well above the noise.
SCALE_GROUPS = 16
# gamma is searched in this range; the hardware's response is near linear.
GAMMA_BOUNDS = (0.1, 10.0)
# Blur fit: L-BFGS iterations on an 11-parameter quadratic in k (converges in tens).
BLUR_ITERATIONS = 200
# Scale and blur are fitted in turn: the scale first as if unblurred, then again
# through the fitted kernel (which moves mass across the edges of the fit's
# windows and of the crop), then the kernel again; a third pass changes nothing.
SCALE_BLUR_PASSES = 2
# Noise fit: reweighting passes after the equal-weight one (converged after two).
NOISE_PASSES = 2


@dataclass(frozen=True)
class Pairs:
    """Real captures and their twins, one row per capture (set, location).

    real: (N, R, T) float32 background-subtracted centre-zone counts of the R
    repeats, bins crop_start .. crop_start + T - 1.
    sim: (N, N_BINS) float32 the twin's transient of the same object, size and
    location on the full time axis (radiance per unit laser intensity).
    keys: N rows: set, object, size, location.
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


def split_pairs(keys: pd.DataFrame, seed: int, test_fraction: float) -> Split:
    """The real train/test split of the pairs (rows of `keys`): captures
    (set, location) held out whole, so that all repeats of one capture fall on
    one side; drawn like the benchmark's grouped splits (`splits.held_out_groups`)."""
    groups = list(zip(keys["set"], keys["location"]))
    train_keys = set(held_out_groups(groups, seed, test_fraction)[0])
    train = np.array([g in train_keys for g in groups], dtype=bool)
    return Split(np.flatnonzero(train), np.flatnonzero(~train))


def build_pairs(feature_paths: list[Path], twin_paths: list[Path]) -> Pairs:
    """Pair every capture of the 3x3 light-on feature stores with the twin of
    its object and size at the same location. Sets in name order, locations
    ascending. ValueError naming the file when a set is not 3x3 light-on,
    the crop windows differ, or a twin is missing a set or a location."""
    twins = {}
    for path in twin_paths:
        t = read_twin(Path(path))
        twins[(t.attrs["object"]["name"], t.attrs["size"])] = (Path(path), t)
    real, sim, keys, crop = [], [], [], None
    for path in sorted(map(Path, feature_paths), key=lambda p: p.name):
        cs, f = read_features(path)
        if cs.resolution != "3x3" or cs.light != "lighton":
            raise ValueError(f"{path}: set {cs.name} is not a 3x3 light-on capture set; the sim-to-real pairs use those only")
        if crop is None:
            crop = (f.crop_start, f.values.shape[-1])
        elif (f.crop_start, f.values.shape[-1]) != crop:
            raise ValueError(f"{path}: {f.values.shape[-1]} bins from bin {f.crop_start}, the other sets have {crop[1]} from bin {crop[0]}")
        if (cs.object, cs.size) not in twins:
            raise ValueError(f"{path}: no twin store of {cs.object} {cs.size} among {[str(p) for p, _ in twins.values()]}")
        twin_path, twin = twins[(cs.object, cs.size)]
        missing = sorted(set(f.locations.tolist()) - set(twin.locations.tolist()))
        if missing:
            raise ValueError(f"{twin_path}: the twin of {cs.name} lacks locations {missing}")
        real.append(f.values[:, :, CENTRE[0], CENTRE[1], :])
        sim.append(np.stack([twin.histogram(loc) for loc in f.locations]))
        keys.append(pd.DataFrame({"set": cs.name, "object": cs.object, "size": cs.size, "location": f.locations.astype(np.int64)}))
    if not real:
        raise ValueError("build_pairs: no feature stores given")
    return Pairs(np.concatenate(real).astype(np.float32), np.concatenate(sim).astype(np.float32), pd.concat(keys, ignore_index=True), crop[0])


# --- the transforms ---------------------------------------------------------------------


@dataclass(frozen=True)
class Transforms:
    """Fitted parameters: a (counts / radiance**gamma), gamma, kernel
    (KERNEL_BINS,) summing to one, a_noise (>= 1), b_noise (counts^2, >= 0)."""

    a: float
    gamma: float
    kernel: tuple[float, ...]
    a_noise: float
    b_noise: float

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


def add_noise(mu: np.ndarray, a_noise: float, b_noise: float, rng: np.random.Generator) -> np.ndarray:
    """One Poisson-Gaussian draw around mean `mu` (counts): mean mu,
    variance a_noise * max(mu, 0) + b_noise."""
    mu = np.asarray(mu, np.float64)
    pos = np.maximum(mu, 0.0)
    poisson = rng.poisson(pos) - pos
    gauss = rng.normal(0.0, 1.0, mu.shape) * np.sqrt((a_noise - 1.0) * pos + b_noise)
    return (mu + poisson + gauss).astype(np.float32)


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
    return add_noise(h, t.a_noise, t.b_noise, rng)


# --- the fits ---------------------------------------------------------------------------


def signal_windows(sim: np.ndarray, crop_start: int, bins: int, min_fraction: float) -> np.ndarray:
    """(N, bins) bool: the real bins where the scale fit sums mass. A bin
    enters where its twin is at least `min_fraction` of the twin's peak in
    the cropped window, widened by the kernel's half-length on both sides so
    that the mass the blur moves out of those bins is still counted. Below
    that fraction the twin is its numerically empty tail, and the real bins
    there hold only noise. A twin without any positive bin has no window."""
    s = sim[:, crop_start : crop_start + bins]
    peak = s.max(axis=1, keepdims=True, initial=0.0)
    core = (s >= min_fraction * peak) & (peak > 0)
    wide = np.zeros_like(core)
    for d in range(-HALF, HALF + 1):  # dilation by HALF bins
        shifted = np.roll(core, d, axis=1)
        if d > 0:
            shifted[:, :d] = False
        elif d < 0:
            shifted[:, d:] = False
        wide |= shifted
    return wide


def fit_scale(real: np.ndarray, sim: np.ndarray, crop_start: int, min_fraction: float, kernel: np.ndarray) -> tuple[float, float]:
    """(a, gamma) of tau = a * tau_sim ** gamma by weighted least squares on logs.

    real: (N, R, T) real counts of R >= 2 repeats; sim: (N, N_BINS);
    kernel: the blur the real data has undergone (a unit impulse before one
    is fitted; see `fit_transforms`).

    Per-bin logs cannot be used as they stand on this data: the blur moves
    counts between bins (a per-bin fit reads the pulse's widening as gamma < 1)
    and background-subtracted bins are noise-dominated (about 48 counts of
    noise against 20-30 of signal per demo bin), so keeping only positive bins
    biases the fit upwards and zeros and negatives have no log at all. The
    fit therefore compares masses: per pair, the real counts (mean over
    repeats) summed over its `signal_windows` W, against the mass that
    kernel * (a tau_sim ** gamma) puts into W, which is a times
    sum_b tau_sim[b] ** gamma * v[b] over the full time axis, v the share of
    bin b that the kernel moves into W (1 inside W and 0 far outside for a
    unit impulse; the kernel sums to one, so mass is only moved). Pairs are
    sorted by simulated mass and pooled into SCALE_GROUPS equal groups; per
    group, the log of the summed real mass is fitted by log a + the log of
    the summed sum_b tau_sim ** gamma v, weighted by the inverse variance of
    the log, (mass / sigma)^2, sigma^2 the group's summed variance of the
    repeat means (measured across repeats). For each gamma, log a is the
    weighted linear least-squares intercept; gamma minimises the weighted
    residual sum of squares (bounded scalar search). Groups whose real mass
    is not positive have no log and are left out. When the groups' twins do
    not differ in level gamma is not identified and is 1."""
    _check_repeats(real, "fit_scale")
    T = real.shape[-1]
    win = signal_windows(sim, crop_start, T, min_fraction)
    keep = win.any(axis=1)
    if not keep.any():
        raise ValueError("fit_scale: no pair has a positive simulated bin in the real bins; nothing to scale")
    full = np.zeros((int(keep.sum()), sim.shape[1]), np.float32)
    full[:, crop_start : crop_start + T] = win[keep]
    v = blur(full, np.asarray(kernel)[::-1]).astype(np.float64)  # the share of each bin that lands in W
    s = np.maximum(sim[keep].astype(np.float64), 0.0)
    s_ref = s.max()  # fit on s / s_ref <= 1 so that no power of it under- or overflows; a is rescaled at the end
    s = s / s_ref
    r64 = real[keep].astype(np.float64)
    r, noise_var, win = r64.mean(axis=1), r64.var(axis=1, ddof=1) / r64.shape[1], win[keep]
    order = np.argsort((s * v).sum(axis=1), kind="stable")
    groups = [g for g in np.array_split(order, min(SCALE_GROUPS, len(order))) if len(g)]
    real_mass = np.array([(r[g] * win[g]).sum() for g in groups])
    mass_var = np.array([(noise_var[g] * win[g]).sum() for g in groups])
    ok = real_mass > 0
    if not ok.any():
        raise ValueError(f"fit_scale: the real mass of every group of pairs is <= 0 ({real_mass.tolist()}); the real captures hold no object signal")
    if not ok.all():
        log.warning("fit_scale: %d of %d groups have no positive real mass and are left out", (~ok).sum(), len(ok))
    groups = [g for g, k in zip(groups, ok) if k]
    log_real = np.log(real_mass[ok])
    # noise-free groups (zero variance) would take all the weight: floor sigma at 1e-9 of the mass
    w = 1.0 / np.maximum(mass_var[ok] / real_mass[ok] ** 2, 1e-18)
    w = w / w.sum()

    def log_sim(gamma: float) -> np.ndarray:
        p = s**gamma * v  # every group holds a positive simulated bin in its window, so no log of 0
        return np.log([p[g].sum() for g in groups])

    def log_a(gamma: float) -> float:
        return float((w * (log_real - log_sim(gamma))).sum())

    def rss(gamma: float) -> float:
        return float((w * (log_real - log_sim(gamma) - log_a(gamma)) ** 2).sum())

    # gamma moves a group's log mass by its mass-weighted mean log tau_sim: without spread in that, gamma is not identified
    slopes = np.array([(s[g] * v[g] * np.log(np.where(s[g] > 0, s[g], 1.0))).sum() / (s[g] * v[g]).sum() for g in groups])
    spread = np.ptp(slopes) if len(groups) > 1 else 0.0
    gamma = 1.0 if spread < 1e-6 else float(minimize_scalar(rss, bounds=GAMMA_BOUNDS, method="bounded", options={"xatol": 1e-6}).x)
    return float(np.exp(log_a(gamma) - gamma * np.log(s_ref))), gamma


def shifted_copies(scaled: np.ndarray, crop_start: int, bins: int) -> np.ndarray:
    """(N, bins, KERNEL_BINS): column j is the real bins of `scaled`
    (N, N_BINS) blurred by the unit kernel e_j, so `blur(scaled, k)` in the
    real bins is this times k."""
    eye = np.eye(KERNEL_BINS)
    return np.stack([blur(scaled, eye[j])[:, crop_start : crop_start + bins] for j in range(KERNEL_BINS)], axis=-1)


def fit_kernel(real_mean: np.ndarray, scaled: np.ndarray, crop_start: int) -> np.ndarray:
    """(KERNEL_BINS,) kernel k minimising the MSE between the real bins of
    k * scaled and real_mean. real_mean: (N, T) counts; scaled: (N, N_BINS)
    the scaled twins. k = softmax(theta), so it is non-negative and sums to
    one; theta starts at 0 (a flat kernel) and L-BFGS fits it,
    deterministically. The blur is linear in k, so the MSE is the quadratic
    k'Gk - 2c'k + const with G and c summed once over every pair and bin: the
    fit's cost does not grow with the data. The loss is divided by the real
    data's mean square so that its size does not depend on the counts' scale."""
    X = shifted_copies(scaled, crop_start, real_mean.shape[1]).reshape(-1, KERNEL_BINS).astype(np.float64)
    y = real_mean.astype(np.float64).ravel()
    norm = max(float((y**2).sum()), 1e-12)
    G = torch.from_numpy(X.T @ X / norm)
    c = torch.from_numpy(X.T @ y / norm)
    theta = torch.zeros(KERNEL_BINS, dtype=torch.float64, requires_grad=True)
    opt = torch.optim.LBFGS([theta], lr=1.0, max_iter=BLUR_ITERATIONS, tolerance_grad=1e-14, tolerance_change=1e-16, line_search_fn="strong_wolfe")

    def closure():
        opt.zero_grad()
        k = torch.softmax(theta, 0)
        loss = k @ G @ k - 2 * c @ k
        loss.backward()
        return loss

    opt.step(closure)
    return torch.softmax(theta.detach(), 0).numpy()


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
    equal weights). Each pass is constrained: if the free solution breaks a
    bound, the best solution on that bound."""
    _check_repeats(real, "fit_noise")
    v = real.astype(np.float64).var(axis=1, ddof=1).ravel()
    m = np.maximum(mu.astype(np.float64), 0.0).ravel()
    ab = _bounded_lstsq(m, v, np.ones_like(v))
    for _ in range(NOISE_PASSES):
        ab = _bounded_lstsq(m, v, 1.0 / np.maximum(ab[0] * m + ab[1], 1e-12) ** 2)
    return ab


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


def fit_transforms(pairs: Pairs, min_fraction: float) -> Transforms:
    """Fit scale and blur in turn (SCALE_BLUR_PASSES), then the noise
    around the blurred scaled twins, all on `pairs` (the training captures)."""
    if len(pairs.real) == 0:
        raise ValueError("fit_transforms: no pairs to fit on")
    real_mean = pairs.real.mean(axis=1, dtype=np.float64)
    kernel = np.eye(KERNEL_BINS)[HALF]
    for _ in range(SCALE_BLUR_PASSES):
        a, gamma = fit_scale(pairs.real, pairs.sim, pairs.crop_start, min_fraction, kernel)
        scaled = scale(pairs.sim, a, gamma)
        kernel = fit_kernel(real_mean, scaled, pairs.crop_start)
    mu = pairs.crop(blur(scaled, kernel))
    a_noise, b_noise = fit_noise(pairs.real, mu)
    return Transforms(a, gamma, tuple(float(k) for k in kernel), a_noise, b_noise)


def write_transforms(path: Path, t: Transforms, record: dict) -> None:
    """transforms.json: the parameters plus `record` (what they were fitted on)."""
    with atomic_file(Path(path)) as tmp:
        tmp.write_text(json.dumps({**t.to_dict(), "kernel_bins": KERNEL_BINS, "bin_width_opl": geo.BIN_WIDTH_OPL, **record}, indent=1) + "\n")


def read_transforms(path: Path) -> Transforms:
    """Read transforms.json; ValueError naming the file when a parameter is missing or out of range."""
    try:
        d = json.loads(Path(path).read_text())
        t = Transforms(float(d["a"]), float(d["gamma"]), tuple(float(k) for k in d["kernel"]), float(d["a_noise"]), float(d["b_noise"]))
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a transforms file ({type(e).__name__}: {e})") from None
    if len(t.kernel) != KERNEL_BINS or not (t.a > 0 and t.gamma > 0 and t.a_noise >= 1 and t.b_noise >= 0):
        raise ValueError(f"{path}: parameters out of range: {t.to_dict()}")
    return t
