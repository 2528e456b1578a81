"""How a TMF882x zone turns photon arrivals into a histogram of counts.

Each laser cycle, a zone's time-to-digital converter records at most its
first detection (first-photon pile-up; the zone's SPADs share one TDC, and
the real floor after a strong return stays low for the rest of the
histogram, so no detector recovers within a cycle). With lambda_b the mean
number of detections a cycle would give in bin b without pile-up, a
histogram of N cycles holds on average (Coates 1968)

    h_b = N exp(-sum_{j<b} lambda_j) (1 - exp(-lambda_b)),

and every count is Poisson (shot noise). The inverse, `rates_from_counts`,
recovers lambda from a histogram exactly given N: the fit works on rates,
where the model is linear in the return's amplitude and the floor.

A return at sub-bin position mu adds A q(b - mu) to lambda_b: q is the
pulse integrated over one bin (`pulse_at`), the instrument's response
measured on the real sweep (sensor.fit) and kept as samples at quarter-bin
offsets, unit area. Times are in bins throughout.
"""

from __future__ import annotations

import numpy as np

# The pulse's samples: offsets (bins from the return's position) from
# PULSE_START to PULSE_END in steps of PULSE_STEP; zero outside.
PULSE_START, PULSE_END, PULSE_STEP = -5.0, 110.0, 0.125


def pulse_offsets() -> np.ndarray:
    """(K,) the offsets in bins at which a pulse is sampled."""
    return np.arange(PULSE_START, PULSE_END + PULSE_STEP / 2, PULSE_STEP)


def _knots(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(index, fraction, inside) of offsets u on the pulse's samples."""
    x = (np.asarray(u, float) - PULSE_START) / PULSE_STEP
    i = np.floor(x).astype(int)
    k = len(pulse_offsets())
    return np.clip(i, 0, k - 2), x - i, (i >= 0) & (i < k - 1)


def pulse_at(pulse: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The bin-integrated pulse (K,) at offsets u (any shape, bins), linear
    between its samples and zero outside them."""
    i, f, inside = _knots(u)
    return np.where(inside, pulse[i] * (1 - f) + pulse[i + 1] * f, 0.0)


def pulse_design(u: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sparse design of `pulse_at` over offsets u (...) scaled by
    weights (...): (rows, columns, values) of the matrix M with
    M @ pulse = weights * pulse_at(pulse, u), rows in u's flat order."""
    i, f, inside = _knots(u)
    w = np.where(inside, weights, 0.0).ravel()
    rows = np.arange(w.size)
    return np.concatenate([rows, rows]), np.concatenate([i.ravel(), i.ravel() + 1]), np.concatenate([w * (1 - f.ravel()), w * f.ravel()])


def pulse_area(pulse: np.ndarray) -> float:
    """The pulse's area in bins: the counts of a unit return summed over the histogram."""
    return float(pulse.sum() * PULSE_STEP)


def counts_from_rates(rates: np.ndarray, cycles: float) -> np.ndarray:
    """Expected counts (..., B) of `cycles` laser cycles under first-photon
    pile-up, from detections per cycle per bin (..., B) (module docstring)."""
    lam = np.clip(rates, 0.0, None)
    before = np.concatenate([np.zeros(lam.shape[:-1] + (1,)), np.cumsum(lam, axis=-1)[..., :-1]], axis=-1)
    return cycles * np.exp(-before) * -np.expm1(-lam)


def rates_from_counts(counts: np.ndarray, cycles: float) -> tuple[np.ndarray, np.ndarray]:
    """(rates, sd) (..., B): the detections per cycle per bin that give
    histogram `counts` (..., B) of `cycles` cycles on average
    (`counts_from_rates` inverted), and each rate's shot-noise sd, from the
    counts' Poisson sd (count + 1, so that an empty bin still weighs)."""
    h = np.asarray(counts, float)
    before = np.concatenate([np.zeros(h.shape[:-1] + (1,)), np.cumsum(h, axis=-1)[..., :-1]], axis=-1)
    left = cycles - before
    if np.any(left <= h):
        raise ValueError(f"a histogram holds more counts ({int(h.sum(-1).max())}) than its {cycles:.4g} cycles can give")
    return -np.log1p(-h / left), np.sqrt(h + 1) / (left - h)


def pulse_centre(pulse: np.ndarray) -> float:
    """The centroid (bins) of the pulse's samples above half its peak: where
    a return's position puts its peak (the timing's convention, sensor.fit)."""
    u, top = pulse_offsets(), pulse >= pulse.max() / 2
    return float((u[top] * pulse[top]).sum() / pulse[top].sum())


def centred(pulse: np.ndarray) -> tuple[np.ndarray, float]:
    """(the pulse moved so that `pulse_centre` is 0, unit area; how far it moved, bins)."""
    c = pulse_centre(pulse)
    moved = pulse_at(pulse, pulse_offsets() + c)
    return moved / pulse_area(moved), c


def tail_summary(pulse: np.ndarray, start: float = 5.0) -> dict:
    """The pulse's late part, from `start` bins after its peak on: its share
    of the area and the time constant (bins) of an exponential fitted to
    its log from there to where it falls below 1e-4 of the peak."""
    u = pulse_offsets()
    peak = u[np.argmax(pulse)]
    late = u >= peak + start
    share = float(pulse[late].sum() / pulse.sum())
    keep = late & (pulse > 1e-4 * pulse.max())
    slope = np.polyfit(u[keep], np.log(pulse[keep]), 1)[0]
    return {"share_from_5_bins": share, "time_constant_bins": float(-1 / slope), "peak_offset_bins": float(peak)}
