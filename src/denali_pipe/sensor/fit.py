"""The sensor fitted to a real distance sweep: pulse, timing, pile-up, crosstalk.

The sweep (captures.SWEEP) is a flat plane at known distances. Every zone of
every capture is a return at position mu = zero_bin + offset_z +
bins_per_metre_z d + shift_c on a floor, through first-photon pile-up of
`cycles` cycles (sensor.response). What the fit shares across captures:

- the pulse q (bin-integrated, sampled every quarter bin, unit area,
  smooth): the instrument's measured response, no assumed form;
- timing: the centre zone's zero-distance bin, each other zone's offset from
  it, and each zone's bins per metre of plane distance (a zone looking off
  the plane's normal sees a longer path: its slope is the larger);
- cycles: the pile-up law's N;
- crosstalk: each zone's return from the cover glass at zero distance.

What it leaves free per capture and zone (the scene's, not the sensor's):
the return's amplitude and the floor (ambient light, which the plane shades
at close range); per capture, a time shift, held to no mean and no trend
with distance so that the linear timing law carries both. The shifts take
up a smooth curve of +-0.2 bin over the sweep that every zone shares (the
converter's non-linearity or the stage's distance labels; these data
cannot tell which), which a linear law does not extrapolate.

The fit alternates: given everything else, the per-capture amplitudes and
floors (weighted linear least squares on the rates), the pulse (sparse
linear least squares with a curvature penalty) and the shifts (a 1-D search
per capture) each have closed or cheap solutions; the timing law and N then
take a nonlinear least-squares step. Residuals are weighted by each rate's
shot noise; uncertainties are the last step's, scaled by its chi^2 per
degree of freedom (the model is not at the shot-noise floor: that
scaling is stated, not hidden).

Held-out captures (every `held_out_every`-th distance, spread over the
range) keep the shared terms and the fitted crosstalk fixed, and get their
own amplitude, floor and shift: `evaluate` scores them in counts, net of
their shot noise.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.optimize import least_squares, nnls

from denali_pipe.core.geometry import SPEED_OF_LIGHT
from denali_pipe.sensor.captures import BINS, ZONES, Captures
from denali_pipe.sensor.response import centred, counts_from_rates, pulse_area, pulse_at, pulse_design, pulse_offsets, rates_from_counts, tail_summary

CENTRE = ZONES // 2
BIN = np.arange(BINS)
# The pulse's curvature penalty (rates' chi^2 units per squared second difference): smooths the
# quarter-bin samples between the captures' sub-bin positions without flattening the peak.
SMOOTHING = 100.0
SHIFT_GRID = np.linspace(-1.0, 1.0, 41)  # bins: each capture's shift search, then a parabola through the best three
# Windows after a zone's peak (bins) that the held-out score reports apart, and what a fitted
# sensor must reach on held-out distances (issue 63): nl2 net of shot noise, |tail|, |late floor| errors.
TAIL, LATE = (5, 20), (30, 60)
CRITERIA = {"nl2_net": 0.05, "tail_error": 0.10, "late_error": 0.05}


@dataclass(frozen=True)
class Timing:
    """Where a return from a plane at d m falls, in bins: zero_bin +
    offsets[z] + bins_per_metre[z] d (offsets (ZONES,), the centre's 0).
    A return's position is where its pulse's peak falls (the centroid of the
    pulse above half its peak, `response.pulse_centre`)."""

    zero_bin: float
    offsets: np.ndarray
    bins_per_metre: np.ndarray

    def position(self, distance_m: np.ndarray, shift: np.ndarray | float = 0.0) -> np.ndarray:
        """(N, ZONES) return positions for planes at distance_m (N,) plus each capture's shift (N,) in bins."""
        d = np.asarray(distance_m, float)[:, None]
        return self.zero_bin + self.offsets[None, :] + self.bins_per_metre[None, :] * d + np.asarray(shift, float).reshape(-1, 1)

    def vector(self) -> np.ndarray:
        return np.concatenate([[self.zero_bin], np.delete(self.offsets, CENTRE), self.bins_per_metre])

    @classmethod
    def from_vector(cls, v: np.ndarray) -> Timing:
        return cls(float(v[0]), np.insert(v[1:ZONES], CENTRE, 0.0), np.asarray(v[ZONES : 2 * ZONES], float))


@dataclass(frozen=True)
class SensorFit:
    """The shared terms (module docstring), their standard errors, and the fit's record.

    pulse (K,) at response.pulse_offsets(); crosstalk (ZONES,) detections per
    cycle of the zero-distance return (median over the training captures);
    se: standard errors by name (zero_bin, offsets, bins_per_metre, cycles);
    chi2_dof: the last step's weighted residual per degree of freedom;
    shift_sd: the training captures' shifts' sd (bins); amplitude
    (len(train_distances), ZONES): each training capture's return, detections
    per cycle (the pulse's area), from which a scene's render reads each
    zone's gain (experiments.sensor_vs_real)."""

    timing: Timing
    cycles: float
    pulse: np.ndarray
    crosstalk: np.ndarray
    se: dict
    chi2_dof: float
    shift_sd: float
    train_distances: np.ndarray
    test_distances: np.ndarray
    amplitude: np.ndarray
    history: list = field(default_factory=list)


def held_out(distance_m: np.ndarray, every: int) -> np.ndarray:
    """(N,) bool: every `every`-th capture in order of distance, from the
    third, held out (spread over the whole range)."""
    order = np.argsort(distance_m, kind="stable")
    mask = np.zeros(len(distance_m), bool)
    mask[order[2::every]] = True
    return mask


def split_sweep(sweep: Captures, held_out_every: int, min_distance_m: float) -> tuple[Captures, Captures]:
    """(training, held-out) captures of a sweep from min_distance_m on (`held_out`)."""
    if sweep.distance_m is None:
        raise ValueError(f"{sweep.name}: not a distance sweep (no dist_to_plane_m)")
    use = np.flatnonzero(sweep.distance_m >= min_distance_m)
    test = held_out(sweep.distance_m[use], held_out_every)
    return sweep.select(use[~test]), sweep.select(use[test])


def _inner(pulse, mu, rates, sd, crosstalk_mu, crosstalk=None):
    """Per capture and zone, the weighted least-squares amplitude, floor and
    (where `crosstalk` is None) crosstalk of the rates (N, Z, B) given the
    return positions mu (N, Z). (weighted residuals, coefficients (N, Z, 3), fitted rates)."""
    k = pulse_at(pulse, BIN - mu[..., None])
    kx = pulse_at(pulse, BIN - crosstalk_mu[..., None])
    y = rates if crosstalk is None else rates - crosstalk[None, :, None] * kx
    cols = [k, np.ones_like(k)] + ([kx] if crosstalk is None else [])
    X = np.stack(cols, axis=-1) / sd[..., None]
    coef = np.linalg.solve(np.einsum("...bi,...bj->...ij", X, X) + 1e-12 * np.eye(len(cols)), np.einsum("...bi,...b->...i", X, y / sd)[..., None])[..., 0]
    fitted = np.einsum("...bi,...i->...b", X, coef) * sd + (0 if crosstalk is None else crosstalk[None, :, None] * kx)
    if crosstalk is not None:
        coef = np.concatenate([coef, np.broadcast_to(crosstalk[None, :, None], coef.shape[:-1] + (1,))], axis=-1)
    return (fitted - rates) / sd, coef, fitted


def _solve_pulse(coef, mu, crosstalk_mu, rates, sd):
    """The pulse that best fits the rates given every amplitude, floor and
    crosstalk (coef) and position: weighted least squares, curvature-penalised,
    non-negative, unit area."""
    w = 1 / sd
    y = ((rates - coef[..., 1:2]) * w).ravel()
    rows, cols, vals = [], [], []
    for m, a in ((mu, coef[..., 0]), (crosstalk_mu, coef[..., 2])):
        r, c, v = pulse_design(BIN - m[..., None], a[..., None] * w)
        rows.append(r), cols.append(c), vals.append(v)
    k = len(pulse_offsets())
    M = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(y.size, k))
    curvature = sp.diags([np.ones(k - 2), -2 * np.ones(k - 2), np.ones(k - 2)], [0, 1, 2], shape=(k - 2, k))
    # no negative light: bounded least squares on the normal equations' factor
    normal = (M.T @ M + SMOOTHING * (curvature.T @ curvature)).toarray()
    factor = np.linalg.cholesky(normal).T
    pulse = nnls(factor, np.linalg.solve(factor.T, M.T @ y), maxiter=10 * k)[0]
    return pulse / pulse_area(pulse)


def _shifts(pulse, timing, distance, rates, sd, crosstalk=None):
    """Each capture's time shift (N,) bins minimising its weighted residual over all zones."""
    zero = timing.position(np.zeros(len(distance)))
    costs = np.stack([(_inner(pulse, timing.position(distance, s), rates, sd, zero, crosstalk)[0] ** 2).sum(axis=(1, 2)) for s in SHIFT_GRID], axis=1)
    return grid_minimum(SHIFT_GRID, costs)


def grid_minimum(grid: np.ndarray, costs: np.ndarray) -> np.ndarray:
    """(N,) where each row of costs (N, len(grid)), sampled on the even
    grid, is least: the best grid point moved to the vertex of the parabola
    through it and its two neighbours."""
    best = np.clip(costs.argmin(axis=1), 1, len(grid) - 2)
    c0, c1, c2 = (costs[np.arange(len(best)), best + j] for j in (-1, 0, 1))
    step = grid[1] - grid[0]
    denom = c0 - 2 * c1 + c2
    return grid[best] + np.where(denom > 0, 0.5 * step * (c0 - c2) / np.where(denom > 0, denom, 1), 0.0)


def _detrended(shift, distance):
    """The shifts less their mean and linear trend with distance (the timing law's share)."""
    return shift - np.polyval(np.polyfit(distance, shift, 1), distance)


def _initial(hists: np.ndarray, distance: np.ndarray) -> tuple[Timing, float, np.ndarray]:
    """Timing from each zone's peak centroid against distance; N from the
    strongest capture's floor after its return against before it (Coates:
    after = before exp(-Lambda), return = N (1 - exp(-Lambda))); a pulse of a
    bin-wide peak and a 3-bin exponential tail."""
    peak = hists.argmax(axis=-1)
    idx = np.clip(peak[..., None] + np.arange(-2, 3), 0, BINS - 1)
    w = np.take_along_axis(hists, idx, -1)
    centroid = (w * idx).sum(-1) / w.sum(-1)
    fits = [np.polyfit(distance, centroid[:, z], 1) for z in range(ZONES)]
    slopes, intercepts = np.array([f[0] for f in fits]), np.array([f[1] for f in fits])
    timing = Timing(intercepts[CENTRE], intercepts - intercepts[CENTRE], slopes)
    c = int(np.argmax(hists[:, CENTRE].sum(-1)))
    h, p = hists[c, CENTRE], int(peak[c, CENTRE])
    before, after = np.median(h[: max(p - 4, 2)]), np.median(h[min(p + 40, BINS - 10) :])
    total = h[max(p - 3, 0) : p + 30].sum()
    loss = -np.log(np.clip(after / before, 0.05, 0.99))
    cycles = max(total / -np.expm1(-loss), 1.1 * hists.sum(-1).max())
    u = pulse_offsets()
    pulse = np.where(u < -1, 0.0, np.where(u < 0.5, 1.0, 0.93 * np.exp(-(u - 0.5)) + 0.07 * np.exp(-(u - 0.5) / 3.0)))
    return timing, float(cycles), pulse / pulse_area(pulse)


def fit_sweep(sweep: Captures, held_out_every: int = 4, min_distance_m: float = 0.05, rounds: int = 6) -> SensorFit:
    """The sensor fitted to the sweep's captures from min_distance_m on, less
    the held-out ones (`held_out`); `rounds` alternations (module docstring)."""
    train, test = split_sweep(sweep, held_out_every, min_distance_m)
    d, hists = train.distance_m, train.hists
    timing, cycles, pulse = _initial(hists, d)
    shift = np.zeros(len(d))
    history = []
    for _ in range(rounds):
        rates, sd = rates_from_counts(hists, cycles)
        mu, zero = timing.position(d, shift), timing.position(np.zeros(len(d)))
        _, coef, _ = _inner(pulse, mu, rates, sd, zero)
        pulse = _solve_pulse(coef, mu, zero, rates, sd)
        shift = _detrended(_shifts(pulse, timing, d, rates, sd), d)

        def residual(v, pulse=pulse, shift=shift):
            t, n = Timing.from_vector(v[:-1]), float(np.exp(v[-1]))
            r, s = rates_from_counts(hists, n)
            return _inner(pulse, t.position(d, shift), r, s, t.position(np.zeros(len(d))))[0].ravel()

        # N can be no fewer than the counts of the fullest histogram (one detection a cycle at most)
        lower = np.append(np.full(2 * ZONES, -np.inf), np.log(1.001 * hists.sum(-1).max()))
        step = least_squares(residual, np.append(timing.vector(), np.log(cycles)), bounds=(lower, np.inf), x_scale="jac", max_nfev=30)
        timing, cycles = Timing.from_vector(step.x[:-1]), float(np.exp(step.x[-1]))
        n_free = step.x.size + len(pulse) + 3 * hists.shape[0] * ZONES + len(d)
        chi2_dof = float(2 * step.cost / (step.fun.size - n_free))
        history.append({"chi2_dof": chi2_dof, "cycles": cycles, "zero_bin": timing.zero_bin})
    # a return's position is its peak's: the pulse and the zero bin trade a shift, so the convention is set once, at the end
    pulse, moved = centred(pulse)
    timing = dataclasses.replace(timing, zero_bin=timing.zero_bin + moved)
    cov = np.linalg.pinv(step.jac.T @ step.jac) * chi2_dof
    se = np.sqrt(np.diag(cov))
    rates, sd = rates_from_counts(hists, cycles)
    _, coef, _ = _inner(pulse, timing.position(d, shift), rates, sd, timing.position(np.zeros(len(d))))
    return SensorFit(
        timing=timing,
        cycles=cycles,
        pulse=pulse,
        crosstalk=np.median(coef[..., 2], axis=0),
        se={
            "zero_bin": float(se[0]),
            "offsets": np.insert(se[1:ZONES], CENTRE, 0.0).tolist(),
            "bins_per_metre": se[ZONES : 2 * ZONES].tolist(),
            "cycles": float(cycles * se[-1]),
        },
        chi2_dof=chi2_dof,
        shift_sd=float(shift.std()),
        train_distances=d,
        test_distances=test.distance_m,
        amplitude=coef[..., 0],
        history=history,
    )


def predict(fit: SensorFit, captures: Captures) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(expected counts (N, Z, B), shifts (N,) bins, coefficients (N, Z, 3)) of
    a sweep's captures under the fit: the shared terms and crosstalk fixed,
    each capture's amplitudes, floors and shift its own."""
    rates, sd = rates_from_counts(captures.hists, fit.cycles)
    d = captures.distance_m
    shift = _shifts(fit.pulse, fit.timing, d, rates, sd, fit.crosstalk)
    _, coef, fitted = _inner(fit.pulse, fit.timing.position(d, shift), rates, sd, fit.timing.position(np.zeros(len(d))), fit.crosstalk)
    return counts_from_rates(fitted, fit.cycles), shift, coef


def window_sums(h: np.ndarray, peak: np.ndarray, window: tuple[int, int]) -> np.ndarray:
    """(N, Z) counts of h (N, Z, B) in bins peak + window[0] .. peak + window[1] (within the histogram)."""
    idx = peak[..., None] + np.arange(window[0], window[1] + 1)
    return np.where(idx < BINS, np.take_along_axis(h, np.minimum(idx, BINS - 1), -1), 0.0).sum(-1)


def scores(measured: np.ndarray, expected: np.ndarray) -> dict:
    """Per zone (ZONES,) over captures (N, Z, B): the normalised L2 net of the
    shot noise, sqrt(max(sum (h - e)^2 - sum e, 0) / sum h^2), and the
    relative errors of the counts TAIL and LATE bins after each zone's peak."""
    peak = measured.argmax(-1)
    excess = ((measured - expected) ** 2).sum(axis=(0, 2)) - expected.sum(axis=(0, 2))
    out = {"nl2_net": np.sqrt(np.maximum(excess, 0) / (measured**2).sum(axis=(0, 2)))}
    for name, w in (("tail", TAIL), ("late", LATE)):
        out[f"{name}_error"] = window_sums(expected, peak, w).sum(0) / window_sums(measured, peak, w).sum(0) - 1
    return out


def held_out_scores(fit: SensorFit, test: Captures) -> pd.DataFrame:
    """One row per zone: `scores` of the held-out captures (`split_sweep`)
    under the fit, and the sd of their shifts from the timing law (bins)."""
    expected, shift, _ = predict(fit, test)
    s = scores(test.hists, expected)
    return pd.DataFrame({"zone": np.arange(ZONES), **s, "n_captures": len(test.hists), "shift_sd_bins": float(shift.std())})


def bin_width_ps(bins_per_metre: np.ndarray) -> np.ndarray:
    """A bin in ps from bins per metre of plane distance (the light goes there and back): 2 / (c slope)."""
    return 2 / (SPEED_OF_LIGHT * np.asarray(bins_per_metre)) * 1e12


def record(fit: SensorFit, held: pd.DataFrame, source: str) -> dict:
    """results/sensor_fit.json: every shared term with its standard error,
    the pulse's samples and tail, the bin width it implies (ps, from bins per
    metre of plane distance: 2 / (c slope)), and the held-out scores per zone."""
    slopes = fit.timing.bins_per_metre
    ps = bin_width_ps(slopes)
    return {
        "source": source,
        "status": "fitted",
        "cycles": fit.cycles,
        "timing": {
            "zero_bin": fit.timing.zero_bin,
            "offsets_bins": fit.timing.offsets.tolist(),
            "bins_per_metre": slopes.tolist(),
            "bin_width_ps": {"centre_zone": float(ps[CENTRE]), "zones": ps.tolist()},
        },
        "se": fit.se,
        "pulse": {
            "offsets_start_bins": float(pulse_offsets()[0]),
            "step_bins": float(pulse_offsets()[1] - pulse_offsets()[0]),
            "samples": fit.pulse.tolist(),
            **tail_summary(fit.pulse),
        },  # fmt: skip
        "crosstalk_per_cycle": fit.crosstalk.tolist(),
        "chi2_dof": fit.chi2_dof,
        "shift_sd_bins": fit.shift_sd,
        "train_distances_m": fit.train_distances.tolist(),
        "test_distances_m": fit.test_distances.tolist(),
        "amplitude_per_cycle": fit.amplitude.tolist(),
        "history": fit.history,
        "held_out": held.to_dict(orient="records"),
    }


def from_record(body: dict) -> SensorFit:
    """The fit back from its `record` (results/sensor_fit.json); ValueError
    when the record holds no fit (its status says why)."""
    if body.get("status") != "fitted":
        raise ValueError(f"the sensor was not fitted: {body.get('status')}")
    t = body["timing"]
    return SensorFit(
        timing=Timing(float(t["zero_bin"]), np.asarray(t["offsets_bins"], float), np.asarray(t["bins_per_metre"], float)),
        cycles=float(body["cycles"]),
        pulse=np.asarray(body["pulse"]["samples"], float),
        crosstalk=np.asarray(body["crosstalk_per_cycle"], float),
        se=body["se"],
        chi2_dof=float(body["chi2_dof"]),
        shift_sd=float(body["shift_sd_bins"]),
        train_distances=np.asarray(body["train_distances_m"], float),
        test_distances=np.asarray(body["test_distances_m"], float),
        amplitude=np.asarray(body["amplitude_per_cycle"], float),
        history=body["history"],
    )
