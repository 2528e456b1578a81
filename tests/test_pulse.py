"""The SPAD pulse (`denali_pipe.core.pulse`): unit area, exact sub-bin shifts,
the fast rise and slow decay its parameters set, and a convolution that
delays a return."""

from __future__ import annotations

import numpy as np
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.core import pulse

DELAYS = np.arange(-geo.N_BINS + 1, geo.N_BINS)
SPAD = pulse.Pulse(sigma_bins=0.6, fast_tail_bins=1.0, slow_tail_bins=15.0, slow_share=0.2)


def test_kernel_is_unit_area_and_shifts_by_sub_bins():
    k = pulse.kernel(SPAD)
    assert k.sum() == pytest.approx(1.0, abs=1e-12) and k.min() > -1e-12
    centroid = lambda kern: (kern * DELAYS).sum()  # noqa: E731
    assert centroid(pulse.kernel(SPAD, 0.3)) - centroid(k) == pytest.approx(0.3, abs=1e-3)


def test_kernel_mean_is_the_tails_mean_delay():
    # an exGaussian's mean is its Gaussian's centre plus its tail's time constant
    p = pulse.Pulse(1.0, 2.0, 10.0, 0.3)
    assert (pulse.kernel(p) * DELAYS).sum() == pytest.approx(0.7 * 2.0 + 0.3 * 10.0, abs=1e-3)


def test_kernel_rises_fast_and_decays_slowly():
    k = pulse.kernel(SPAD)
    peak = int(np.argmax(k)) - (geo.N_BINS - 1)
    assert peak in (0, 1)
    # the slow share: what lies past 5 fast time constants is ~the slow tail's energy there
    late = k[DELAYS > 5].sum()
    assert late == pytest.approx(0.2 * np.exp(-5 / 15.0), rel=0.1)
    # it stays above 1 % of its peak for ~1 bin before the peak and tens after it
    above = np.flatnonzero(k > 0.01 * k.max()) - (geo.N_BINS - 1)
    assert above[0] >= -2 and above[-1] >= 20


def test_convolve_delays_a_return_by_the_shift():
    h = np.zeros((2, geo.N_BINS))
    h[:, 40] = [1.0, 2.0]
    out = pulse.convolve(h, pulse.kernel(pulse.Pulse(0.5, 0.2, 10.0, 0.01), 3.0))
    assert np.argmax(out, axis=1).tolist() == [43, 43] and out[1].sum() == pytest.approx(2 * out[0].sum())
    assert out[:, :38].max() < 1e-6  # nothing arrives before the return, beyond the jitter
