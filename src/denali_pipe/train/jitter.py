"""The timing-jitter condition (paper Sec 5.2, supplement 11.6): the
background-subtracted 3x3 centre-zone histograms with lights on, blurred
along time by a normalised discrete Gaussian of full width at half maximum
F ps, as training cells of condition `jitter<F>ps` (conditions.py selects
the samples and calls `jitter` here; `jitter0ps` is the unjittered
original). experiments/jitter.py gathers the cells into the sweep's table.

The kernel is bin-integrated: tap j is the probability that a Gaussian
timing error moves a count from the centre of its bin into the bin j bins
away, Phi((j + 1/2) / sigma) - Phi((j - 1/2) / sigma), sigma = FWHM /
(2 sqrt(2 ln 2)) in bins of the captures' time axis (config
`sensor.time_axis`). Sampling the Gaussian at bin centres instead
collapses to a delta below a bin: at 50 ps FWHM in 78.2-ps bins (sigma
0.27 bins) its neighbour taps are 0.1 %, here 3.3 %, so sub-bin widths
still blur.
"""

from __future__ import annotations

import math
import re

import numpy as np

from denali_pipe.core.geometry import RESOLUTIONS, TimeAxis

RESOLUTION = "3x3"  # the captures whose centre zone the sweep blurs
FWHM_PER_SIGMA = 2.0 * math.sqrt(2.0 * math.log(2.0))
# Taps reach this many sigma each side: the Gaussian mass beyond is < 1e-4.
KERNEL_HALF_WIDTH_SIGMAS = 4.0
_CONDITION = re.compile(r"jitter(\d+)ps")
CONDITION_PATTERN = _CONDITION.pattern


def jitter_condition(fwhm_ps: int) -> str:
    """The cell condition of one FWHM (ps): `jitter<F>ps`."""
    return f"jitter{int(fwhm_ps)}ps"


def jitter_fwhm(condition: str) -> int | None:
    """The FWHM (ps) a `jitter<F>ps` condition names; None for any other."""
    m = _CONDITION.fullmatch(condition)
    return None if m is None else int(m[1])


def jitter_kernel(fwhm_ps: float, axis: TimeAxis) -> np.ndarray:
    """(2K + 1,) float64 taps summing to one, centred on tap K: the
    bin-integrated Gaussian of FWHM `fwhm_ps` in bins of `axis` (module
    docstring), truncated at KERNEL_HALF_WIDTH_SIGMAS; [1.0] for FWHM 0."""
    if fwhm_ps < 0:
        raise ValueError(f"jitter FWHM must be >= 0 ps, got {fwhm_ps}")
    if fwhm_ps == 0:
        return np.ones(1)
    sigma = fwhm_ps / axis.bin_width_ps / FWHM_PER_SIGMA
    half = max(1, math.ceil(KERNEL_HALF_WIDTH_SIGMAS * sigma))
    edges = np.array([_normal_cdf((j + 0.5) / sigma) for j in range(-half - 1, half + 1)])
    taps = np.diff(edges)
    return taps / taps.sum()


def _normal_cdf(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def jitter(x: np.ndarray, fwhm_ps: float, axis: TimeAxis) -> np.ndarray:
    """x (..., T) counts in bins of `axis` blurred along the last (time) axis
    by `jitter_kernel`: a linear convolution, zero beyond the ends, the same
    T bins kept; float32."""
    taps = jitter_kernel(fwhm_ps, axis)
    half, bins = len(taps) // 2, x.shape[-1]
    padded = np.pad(np.asarray(x, np.float64), [(0, 0)] * (x.ndim - 1) + [(half, half)])
    # the taps are symmetric, so this sliding sum is the convolution
    return sum(t * padded[..., i : i + bins] for i, t in enumerate(taps)).astype(np.float32)


def centre_zone(x: np.ndarray) -> np.ndarray:
    """(N, 3, 3, T) -> (N, 1, 1, T): the centre zone of RESOLUTION histograms."""
    n = RESOLUTIONS[RESOLUTION]
    if x.ndim != 4 or x.shape[1:3] != (n, n):
        raise ValueError(f"the jitter sweep takes {RESOLUTION} histograms (N, {n}, {n}, T); got {x.shape}")
    return x[:, n // 2 : n // 2 + 1, n // 2 : n // 2 + 1, :]
