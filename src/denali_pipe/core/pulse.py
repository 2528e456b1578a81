"""A SPAD sensor's instrument response (the pulse), in histogram bins.

Gaussian timing jitter (laser pulse and SPAD jitter together) convolved with
a mixture of two exponential tails: a fast one (the SPAD's diffusion tail,
about a bin) and a slow one carrying a share of the energy (carrier
diffusion from deep in the silicon, laser afterglow: the real direct returns
decay over tens of bins). Each part is an exponentially modified Gaussian,
integrated over the bins in closed form from its CDF, so a sub-bin shift
costs nothing and leaves no interpolation pattern.

The rig draws its captures through a `Pulse` set in its config; the twin's
calibration fits one to the captures. Both use this one form.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, ndtr

from denali_pipe.core import geometry as geo


@dataclass(frozen=True)
class Pulse:
    """sigma_bins: the jitter's sd; fast_tail_bins, slow_tail_bins: the two
    tails' time constants; slow_share: the slow tail's share of the energy
    (0-1; 0, the default, is a pulse of the jitter and the fast tail alone).
    All times in bins."""

    sigma_bins: float
    fast_tail_bins: float
    slow_tail_bins: float = 0.0
    slow_share: float = 0.0


def _exgauss_cdf(t: np.ndarray, sigma: float, tau: float) -> np.ndarray:
    # Phi(t/s) - exp(s^2 / 2 tau^2 - t / tau) Phi(t/s - s/tau), in logs for stability
    return ndtr(t / sigma) - np.exp(sigma**2 / (2 * tau**2) - t / tau + log_ndtr(t / sigma - sigma / tau))


def kernel(p: Pulse, shift_bins: float = 0.0) -> np.ndarray:
    """(2 N_BINS - 1,) the unit-area pulse integrated over each bin, for
    delays -(N_BINS - 1) .. N_BINS - 1 bins; delay 0 holds the Gaussian's
    centre when `shift_bins` is 0. Normalised over this window (the slow
    tail beyond a histogram's length is cut)."""
    edges = np.arange(-geo.N_BINS + 0.5, geo.N_BINS, 1.0) - shift_bins
    c = _exgauss_cdf(edges, p.sigma_bins, p.fast_tail_bins)
    if p.slow_share > 0:
        c = (1 - p.slow_share) * c + p.slow_share * _exgauss_cdf(edges, p.sigma_bins, p.slow_tail_bins)
    k = np.diff(c)
    return k / k.sum()


def convolve(h: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(..., N_BINS) histograms h convolved along time with a `kernel` k:
    out[b] = sum_i h[i] k[b - i], the same bins (a return at bin i spreads
    to the bins after it, and before it by the jitter)."""
    i = np.arange(geo.N_BINS)
    return h @ k[(i[None, :] - i[:, None]) + geo.N_BINS - 1]
