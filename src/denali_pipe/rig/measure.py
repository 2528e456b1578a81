"""The numbers that describe a raw zone histogram, measured the way
docs/stages.md and docs/rig_zones.md read them off the release's figures of
real captures, so the rig can be held against them (`report/rig_vs_real.py`,
the physics tests): the centre zone's floors, direct peak and bump
(`measure`), any zone's direct-return shape (`zone_shape`), the far column's
early return (`early_share`).

All inputs are counts per bin, (N_BINS,) float; bins are indices 0..127.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

# The pre-peak floor: bins from FLOOR_START to FLOOR_GAP bins before the direct
# peak (the first bins and the peak's rising edge left out).
FLOOR_START = 2
FLOOR_GAP = 8
# The late floor: the last LATE_BINS bins (the figures read "by bin 128").
LATE_BINS = 8
# A far zone's early return: its counts within EARLY_WINDOW bins of the
# brightest zone's direct peak, against its own later peak (the real far
# column's first peak sits there: capture_setup.png's pixels 1, 4 and 7).
EARLY_WINDOW = 3
# The three-bounce bump is searched this many bins after the direct peak:
# the hidden object is at least ~0.25 m from the wall, ~20 bins of path.
BUMP_AFTER_PEAK = 15
# Any zone's shape (`zone_shape`): its floor over the first bins, before any
# return (the near-field one, ~38 bins before the direct return, starts at
# bin 12 in the release's figure); the near-field window; the two tail
# windows after the direct peak (bins from it).
SHAPE_FLOOR_BINS = 12
NEAR_FIELD = slice(12, 19)
TAILS = {"tail_5_14": (5, 15), "tail_15_29": (15, 30)}
SHAPE_LATE_BINS = 18


@dataclass(frozen=True)
class CentreZone:
    """floor_before, floor_after, direct_peak, bump_excess: counts per bin;
    bump_bin, direct_bin: bin indices; bump_fwhm: bins (NaN without a bump)."""

    floor_before: float
    floor_after: float
    direct_peak: float
    direct_bin: int
    bump_excess: float
    bump_bin: int
    bump_fwhm: float

    @property
    def floor_fraction(self) -> float:
        """Pre-peak floor over the direct peak."""
        return self.floor_before / self.direct_peak

    @property
    def bump_fraction(self) -> float:
        """Bump excess over the direct peak."""
        return self.bump_excess / self.direct_peak

    @property
    def bump_over_floor(self) -> float:
        return self.bump_excess / self.floor_before

    @property
    def late_over_floor(self) -> float:
        """Late floor over the pre-peak floor (below 1: the dead time after the direct return)."""
        return self.floor_after / self.floor_before

    def to_dict(self) -> dict:
        return {
            **dataclasses.asdict(self),
            "floor_fraction": self.floor_fraction,
            "bump_fraction": self.bump_fraction,
            "bump_over_floor": self.bump_over_floor,
            "late_over_floor": self.late_over_floor,
        }


def fwhm(excess: np.ndarray, at: int) -> float:
    """Full width at half maximum (bins) of the peak of `excess` at bin `at`,
    half-maximum crossings interpolated linearly between bins."""
    half = excess[at] / 2
    lo = at
    while lo > 0 and excess[lo - 1] > half:
        lo -= 1
    hi = at
    while hi < len(excess) - 1 and excess[hi + 1] > half:
        hi += 1
    left = lo - (excess[lo] - half) / (excess[lo] - excess[lo - 1]) if lo > 0 else float(lo)
    right = hi + (excess[hi] - half) / (excess[hi] - excess[hi + 1]) if hi < len(excess) - 1 else float(hi)
    return float(right - left)


def measure(capture: np.ndarray, background: np.ndarray) -> CentreZone:
    """Measure one raw capture against the background at the same location
    (the mean over its repeats, or its expectation): floors and direct peak
    from the capture, the bump from capture minus background."""
    capture = np.asarray(capture, float)
    direct_bin = int(np.argmax(capture))
    floor_before = float(capture[FLOOR_START : max(direct_bin - FLOOR_GAP, FLOOR_START + 1)].mean())
    excess = capture - np.asarray(background, float)
    start = direct_bin + BUMP_AFTER_PEAK
    bump_bin = start + int(np.argmax(excess[start:]))
    bump = float(excess[bump_bin])
    return CentreZone(
        floor_before=floor_before,
        floor_after=float(capture[-LATE_BINS:].mean()),
        direct_peak=float(capture[direct_bin]),
        direct_bin=direct_bin,
        bump_excess=bump,
        bump_bin=bump_bin,
        bump_fwhm=fwhm(excess, bump_bin) if bump > 0 else float("nan"),
    )


def matched_filter_snr(signal: np.ndarray, expected: np.ndarray, read_noise: float) -> np.ndarray:
    """SNR (...,) of a known signal (..., N_BINS) in one capture whose
    expected counts are `expected` (same shape): the matched filter's
    sqrt(sum_b s_b^2 / var_b), with var_b the Poisson variance plus read
    noise squared (counts^2)."""
    return np.sqrt((np.asarray(signal, float) ** 2 / (np.asarray(expected, float) + read_noise**2)).sum(-1))


def zone_shape(h: np.ndarray) -> dict[str, float]:
    """The shape of any zone's direct return in one histogram (N_BINS,),
    as `scripts/read_figure_zones.py` reads each panel of the release's
    plotted real capture: `half_rise`, the first bin at half the peak above
    the floor (the median of the first SHAPE_FLOOR_BINS bins); `width`, bins
    from it to the last bin above half; `tail_5_14` and `tail_15_29`, the
    mean height above the floor in those bins after the peak, over the
    peak's; `late_over_floor`, the last SHAPE_LATE_BINS bins' mean over the
    floor; `near_field`, the largest excess in NEAR_FIELD over the peak's."""
    h = np.asarray(h, float)
    floor = float(np.median(h[:SHAPE_FLOOR_BINS]))
    above = h - floor
    peak = int(np.argmax(above))
    half = np.nonzero(above >= 0.5 * above[peak])[0]
    tails = {name: float(above[peak + a : peak + b].mean() / above[peak]) for name, (a, b) in TAILS.items()}
    return {
        "half_rise": float(half[0]),
        "width": float(half[-1] - half[0] + 1),
        **tails,
        "late_over_floor": float(h[-SHAPE_LATE_BINS:].mean() / floor),
        "near_field": float((h[NEAR_FIELD].max() - floor) / above[peak]),
    }


def early_share(zones: np.ndarray, zone: int) -> float:
    """A zone's early return over its own direct peak, both above its floor.

    zones: one capture's counts (Z, N_BINS). The early return is the zone's
    largest count within EARLY_WINDOW bins of the brightest zone's direct
    peak, its own peak the largest after that window; the floor as
    `measure` takes it, before the brightest zone's peak. A zone that sees
    farther wall than the brightest zone holds an early return only by
    light meant for other zones (the receiver's glare)."""
    zones = np.asarray(zones, float)
    first = int(np.argmax(zones.max(axis=1)))
    at = int(np.argmax(zones[first]))
    h = zones[zone]
    floor = h[FLOOR_START : max(at - FLOOR_GAP, FLOOR_START + 1)].mean()
    early = h[max(at - EARLY_WINDOW, 0) : at + EARLY_WINDOW + 1].max() - floor
    own = h[at + EARLY_WINDOW + 1 :].max() - floor
    return float(early / own)
