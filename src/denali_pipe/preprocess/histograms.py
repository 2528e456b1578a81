"""Per-set preprocessing: temporal alignment, background subtraction, cropping.

Histograms are `(location, repeat, zone_row, zone_col, bin)` photon counts;
each repeat stays a sample (as in the paper). Steps, per capture set:

1. Temporal alignment: the direct wall return is the strongest, sharpest
   feature of every histogram and does not depend on the hidden object, so
   each histogram is shifted by whole bins until its direct return lines up
   with the background's at the same location. Sub-bin shifts are not
   applied: interpolation would blur the pulse more than the jitter it removes.
2. Background subtraction: minus the `NOOBJECT` set captured at the same
   location, resolution and lighting (`background_means`). What remains is
   the object's three-bounce return plus noise (negative values kept). One
   background capture is subtracted from every object set at its location,
   so its own shot noise would be a pattern shared by all of them, which a
   model can learn as a fingerprint of the location. The background is
   therefore the low-rank part of its captures across locations: what
   varies with location above the noise (the mount's return, drifts) is
   kept, the capture's own shot noise is not.
3. Cropping: after subtraction each zone's direct return leaves its shot
   noise, sqrt(2 * counts) thousands of counts tall at the peak. Every zone
   keeps its bins from its own direct-return end (`CropWindow.zone_starts`):
   the set drops the bins before the earliest end (`crop_start`) and sets a
   later-ending zone's bins before its own end to zero. Zones see their wall
   patches at different distances (peaks 16 bins apart on 3x3), and one
   window for all would either cut the object's return out of the early
   zones or keep the late zones' tails. A zone's end never passes the
   earliest bin at which the scene's geometry lets an object's return reach
   it (a slow tail can outlast it). The window is derived from the
   background sets of one resolution and the scene (`crop_window`), so every
   set of that resolution, both lightings, shares it.

Normalisation (raw counts, or log1p + z-score) needs statistics over a
training split, so it lives with training (`normalise`), not here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from denali_pipe.io.features import Features

# After subtraction the direct return cancels in expectation and leaves its
# shot noise, whose variance is its counts. A zone's return has ended where
# its excess over the floor is at most the floor itself, i.e. the noise there
# is within sqrt(2) of the floor's. The slow tail of the real pulse decays
# over tens of bins and the three-bounce bump sits on it (docs/stages.md),
# so a stricter end would crop the bump away (3x3 demo: 10 % of the floor is
# reached ~45 bins after the peak, in the middle of the bumps).
DIRECT_END_FRACTION = 1.0
# Bins before the direct return used to estimate the flat floor.
FLOOR_BINS = 16
# A zone's direct return counts only if its mean peak stands this many noise sigmas above the floor.
SIGNIFICANCE = 5.0
# Bins by which a zone's first kept bin precedes the earliest three-bounce
# arrival that the geometry allows (`crop_window`): the object's pulse
# starts its rise ~2 jitter sigmas (~1 bin) before its centre.
LEAD_MARGIN_BINS = 1
# Whole-bin alignment shifts searched; reaching this means the capture, not the clock, is wrong.
MAX_SHIFT_BINS = 8


def hard_threshold(beta: float) -> float:
    """Gavish & Donoho's optimal hard threshold lambda*(beta) for singular
    values of an m x n matrix (beta = m / n <= 1) with known unit noise: keep
    a singular value above lambda*(beta) sqrt(n) (IEEE Trans. Inf. Theory
    60(8), 2014, eq. 11; 4/sqrt(3) for a square matrix)."""
    return float(np.sqrt(2 * (beta + 1) + 8 * beta / (beta + 1 + np.sqrt(beta**2 + 14 * beta + 1))))


def background_means(background: np.ndarray) -> np.ndarray:
    """(L, n, n, B) float64: the background at each of its L locations, the
    mean over repeats with its shot noise removed.

    background: (L, R, n, n, B) counts of one NOOBJECT set. The repeat means
    are whitened by each bin's noise (the repeats' scatter pooled over
    locations, divided by R; at least one count's Poisson variance per
    repeat), and their matrix (L, n n B) keeps the singular values above the
    optimal hard threshold for unit noise (`hard_threshold`). The kept rank
    carries what changes with location above the noise; one location's shot
    noise spreads over every direction and only a share rank / (n n B) of it
    stays. With one location or one repeat there is nothing to tell signal
    from noise by, and the plain mean over repeats is returned."""
    mean = background.mean(axis=1, dtype=np.float64)
    n_loc, n_rep = background.shape[:2]
    if n_loc < 2 or n_rep < 2:
        return mean
    var = background.astype(np.float64).var(axis=1, ddof=1).mean(axis=0) / n_rep
    sd = np.sqrt(np.maximum(var, 1.0 / n_rep))
    y = (mean / sd).reshape(n_loc, -1)
    u, s, vt = np.linalg.svd(y, full_matrices=False)
    m, n = sorted(y.shape)
    rank = int((s > hard_threshold(m / n) * np.sqrt(n)).sum())
    return ((u[:, :rank] * s[:rank]) @ vt[:rank]).reshape(mean.shape) * sd


def shift_bins(hist: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Shift each histogram along its last axis by whole bins (positive = later),
    filling the vacated bins with the nearest edge value (the flat floor).

    hist: (L, R, n, n, B); shifts: (L, R) int. Returns a new array of hist's dtype.
    """
    out = np.array(hist, copy=True)
    for (l, r), d in np.ndenumerate(shifts):
        if d:
            out[l, r] = np.roll(hist[l, r], d, axis=-1)
            if d > 0:
                out[l, r, ..., :d] = hist[l, r, ..., :1]
            else:
                out[l, r, ..., d:] = hist[l, r, ..., -1:]
    return out


def alignment_shifts(hist: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Whole-bin shifts (L, R) that best align each histogram with the
    background (L, n, n, B) at the same location.

    A matched filter: the shift maximises the correlation of the shifted
    histogram, all zones together, with the background's floor-free profile,
    which is the direct return. Zones peak at different bins (their wall
    patches lie at different distances), so one shift per histogram fitted
    on every zone at once is far steadier than any per-zone peak, and still
    works on 8x8 zones that catch a few direct photons each.

    Raises ValueError when the best shift reaches MAX_SHIFT_BINS."""
    template = background - background[..., :FLOOR_BINS].mean(axis=-1, keepdims=True)
    h = hist.astype(np.float64)
    candidates = np.arange(-MAX_SHIFT_BINS, MAX_SHIFT_BINS + 1)
    scores = np.stack([np.einsum("lrijb,lijb->lr", np.roll(h, d, axis=-1), template) for d in candidates])
    shifts = candidates[scores.argmax(axis=0)]
    if np.abs(shifts).max(initial=0) >= MAX_SHIFT_BINS:
        l, r = np.unravel_index(np.abs(shifts).argmax(), shifts.shape)
        raise ValueError(f"direct return of location index {l} repeat {r} is at least {MAX_SHIFT_BINS} bins off the background's")
    return shifts


def subtract_background(hist: np.ndarray, background: np.ndarray) -> np.ndarray:
    """hist (L, R, n, n, B) minus background (L, n, n, B) at the same
    locations; float32, negatives kept."""
    if hist.shape[0] != background.shape[0] or hist.shape[2:] != background.shape[1:]:
        raise ValueError(f"histograms {hist.shape} and background {background.shape} do not match in locations, zones or bins")
    return (hist.astype(np.float32) - background[:, None].astype(np.float32)).astype(np.float32)


def _excess(profile: np.ndarray, n_averaged: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(floor (Z,), excess over it (Z, B), the Poisson noise sd of the mean
    profile's floor (Z,)) of a (Z, B) mean over `n_averaged` histograms."""
    floor = profile[:, :FLOOR_BINS].mean(axis=1)
    return floor, profile - floor[:, None], np.sqrt(np.maximum(floor, 1.0) / n_averaged)


def direct_end(profile: np.ndarray, n_averaged: int, fraction: float = DIRECT_END_FRACTION) -> np.ndarray:
    """First bin after the direct-return peak where the excess over the floor
    falls below `fraction` of the floor (at least `fraction` of one count),
    per zone; -1 for zones whose peak does not stand SIGNIFICANCE noise
    sigmas above the floor (8x8 zones catch ~1 direct photon per bin: their
    'end' would be noise).

    profile: (Z, B) mean counts over `n_averaged` histograms. Returns (Z,) int bins."""
    floor, excess, sigma = _excess(profile, n_averaged)
    peak = excess.argmax(axis=1)
    ends = []
    for z, p in enumerate(peak):
        if excess[z, p] < SIGNIFICANCE * sigma[z]:
            ends.append(-1)
            continue
        below = np.flatnonzero(excess[z, p:] < fraction * max(floor[z], 1.0))
        if not len(below):
            raise ValueError(f"zone {z}: the direct return never falls within {fraction:g} x the floor in the histogram")
        ends.append(p + below[0])
    return np.array(ends)


@dataclass(frozen=True)
class CropWindow:
    """crop_start: the first bin kept; zone_starts (n, n) int: each zone's
    first bin with data (>= crop_start; crop_start for zones without a
    significant direct return)."""

    crop_start: int
    zone_starts: np.ndarray

    def to_dict(self) -> dict:
        return {"crop_start": self.crop_start, "zone_starts": self.zone_starts.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "CropWindow":
        return cls(int(d["crop_start"]), np.asarray(d["zone_starts"], dtype=int))


def read_crop_window(path: Path) -> CropWindow:
    """The crop window `denali crop-window` wrote (results/features/crop_<res>.json);
    ValueError naming the file when it is not one."""
    try:
        return CropWindow.from_dict(json.loads(Path(path).read_text()))
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{path}: not a crop window ({type(e).__name__}: {e})") from None


def direct_onset(profile: np.ndarray, n_averaged: int) -> np.ndarray:
    """First bin of the direct return, per zone: the first whose excess over
    the floor stands SIGNIFICANCE noise sigmas above it (the pulse's rising
    edge at the zone's nearest wall point, less the jitter's early tail);
    -1 where the peak does not (as `direct_end`).

    profile: (Z, B) mean counts over `n_averaged` histograms. Returns (Z,) int bins."""
    _, excess, sigma = _excess(profile, n_averaged)
    out = []
    for z in range(len(profile)):
        above = np.flatnonzero(excess[z, FLOOR_BINS:] >= SIGNIFICANCE * sigma[z])
        out.append(FLOOR_BINS + above[0] if len(above) else -1)
    return np.array(out)


def crop_window(backgrounds: list[np.ndarray], lead_bins: np.ndarray, fraction: float = DIRECT_END_FRACTION) -> CropWindow:
    """Each zone's first kept bin from the given background sets (each
    (L, R, n, n, B), one resolution): its direct-return end (the latest over
    the sets), but never after its object signal can begin, its direct
    onset (the earliest over the sets) plus `lead_bins` (n, n: the least
    extra path of a three-bounce return in the scene, bins;
    `twin.layout.three_bounce_lead`) less LEAD_MARGIN_BINS; and the earliest
    of those. A direct return's slow tail can outlast the start of the
    nearest objects' returns: the end alone cut the demo's centre zone at
    bin 83, through the bump of an 8 in plate at 15 of 100 locations."""
    if not backgrounds:
        raise ValueError("crop_window needs at least one background set")
    n = backgrounds[0].shape[2]
    if np.shape(lead_bins) != (n, n):
        raise ValueError(f"three-bounce lead of shape {np.shape(lead_bins)} for {n}x{n} zones")
    profiles = [(b.mean(axis=(0, 1), dtype=np.float64).reshape(-1, b.shape[-1]), b.shape[0] * b.shape[1]) for b in backgrounds]
    ends = np.stack([direct_end(p, k, fraction) for p, k in profiles]).max(axis=0)
    if (ends < 0).all():
        raise ValueError("no zone of the background sets shows a significant direct return")
    onsets = np.stack([direct_onset(p, k) for p, k in profiles])
    onset = np.where((onsets >= 0).any(axis=0), np.where(onsets >= 0, onsets, np.iinfo(int).max).min(axis=0), -1)
    bins = backgrounds[0].shape[-1]
    signal = onset + np.floor(np.minimum(np.ravel(lead_bins), bins)).astype(int) - LEAD_MARGIN_BINS
    ends = np.where((ends >= 0) & (onset >= 0), np.minimum(ends, signal), ends)
    start = int(ends[ends >= 0].min())
    return CropWindow(start, np.maximum(ends, start).reshape(n, n))


def preprocess(hist: np.ndarray, locations: np.ndarray, background: np.ndarray, background_locations: np.ndarray, window: CropWindow) -> Features:
    """Align, subtract the background at matching locations, crop to `window`
    (zeroing each zone's bins before its own start).

    hist (L, R, n, n, B) counts; background (Lb, n, n, B) the background set
    at its locations (`background_means`), which must cover every location
    of `locations`."""
    pos = {int(k): i for i, k in enumerate(background_locations)}
    missing = [int(k) for k in locations if int(k) not in pos]
    if missing:
        raise ValueError(f"the background set has no capture at locations {missing}")
    bg = background[[pos[int(k)] for k in locations]]
    crop_start = window.crop_start
    if not 0 <= crop_start < hist.shape[-1]:
        raise ValueError(f"crop_start {crop_start} is outside 0..{hist.shape[-1] - 1}")
    if window.zone_starts.shape != hist.shape[2:4]:
        raise ValueError(f"crop window of {window.zone_starts.shape} zones for histograms of {hist.shape[2:4]} zones")
    shifts = alignment_shifts(hist, bg)
    values = subtract_background(shift_bins(hist, shifts), bg)[..., crop_start:]
    kept = np.arange(crop_start, hist.shape[-1]) >= window.zone_starts[..., None]  # (n, n, T)
    values = np.where(kept, values, np.float32(0.0))
    return Features(np.ascontiguousarray(values, dtype=np.float32), np.asarray(locations), shifts, crop_start)


def normalise(x: np.ndarray, kind: str, stats: tuple[float, float] | None = None) -> tuple[np.ndarray, tuple[float, float] | None]:
    """Model input from background-subtracted counts.

    kind "raw": the counts as float32 (stats unused, None returned).
    kind "log_z": a signed log1p, sign(x) log1p(|x|), then a global scalar
    z-score (x - mu) / sigma. On raw counts (all >= 0) the signed log equals
    the reference's log1p(clip(x, 0)); after background subtraction it keeps
    the negative half of the noise instead of piling it up at zero. mu and
    sigma come from x when `stats` is None; pass the training part's
    statistics to normalise anything else. Returns (array, (mu, sigma))."""
    if kind == "raw":
        return x.astype(np.float32, copy=False), None
    if kind != "log_z":
        raise ValueError(f"unknown normalisation {kind!r}; expected 'raw' or 'log_z'")
    y = np.sign(x) * np.log1p(np.abs(x))
    if stats is None:
        stats = (float(y.mean()), float(y.std()) + 1e-6)
    mu, sigma = stats
    return ((y - mu) / max(sigma, 1e-6)).astype(np.float32), stats
