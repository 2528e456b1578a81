"""The timing-jitter sweep: the bin-integrated kernel, the blur, the centre
zone, the condition names and the sweep's table."""

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import norm

from denali_pipe.core.geometry import PAPER_TIME_AXIS, TimeAxis
from denali_pipe.experiments.jitter import jitter_curve
from denali_pipe.train.jitter import FWHM_PER_SIGMA, centre_zone, jitter, jitter_condition, jitter_fwhm, jitter_kernel

# The figures below are in the paper's 78.2-ps bins.
AXIS = PAPER_TIME_AXIS


@pytest.mark.parametrize("fwhm_ps", [50, 100, 600])
def test_kernel_is_the_gaussian_integrated_over_each_bin(fwhm_ps):
    taps = jitter_kernel(fwhm_ps, AXIS)
    half = len(taps) // 2
    sigma = fwhm_ps / AXIS.bin_width_ps / FWHM_PER_SIGMA
    j = np.arange(-half, half + 1)
    expected = norm.cdf((j + 0.5) / sigma) - norm.cdf((j - 0.5) / sigma)
    assert taps.sum() == pytest.approx(1.0) and np.allclose(taps, taps[::-1])
    assert np.allclose(taps, expected / expected.sum(), atol=1e-12)


@pytest.mark.parametrize("axis", [AXIS, TimeAxis(bin_width_ps=93.0, zero_bin=16.0)], ids=["78ps", "93ps"])
def test_a_wide_kernel_has_the_gaussians_variance_plus_a_bins(axis):
    taps = jitter_kernel(600, axis)  # sigma 3.3 bins of 78 ps, 2.7 of 93
    sigma = 600 / axis.bin_width_ps / FWHM_PER_SIGMA
    j = np.arange(len(taps)) - len(taps) // 2
    # rounding a Gaussian offset to whole bins adds a one-bin box's variance, 1/12 bin^2 (Sheppard)
    assert (taps * j**2).sum() == pytest.approx(sigma**2 + 1 / 12, rel=1e-3)


def test_sub_bin_jitter_still_blurs():
    taps = jitter_kernel(50, AXIS)  # 0.64 bins FWHM
    sigma = 50 / AXIS.bin_width_ps / FWHM_PER_SIGMA
    assert 0.03 < taps[len(taps) // 2 + 1] < 0.04
    assert math.exp(-0.5 / sigma**2) < 0.002  # what sampling the Gaussian at the neighbour's centre would give it
    assert np.array_equal(jitter_kernel(0, AXIS), [1.0])
    with pytest.raises(ValueError, match=">= 0 ps"):
        jitter_kernel(-1, AXIS)


def test_jitter_is_a_linear_convolution_along_time():
    x = np.random.default_rng(0).poisson(20.0, size=(4, 1, 1, 40)).astype(np.float32)
    out = jitter(x, 600, AXIS)
    assert out.shape == x.shape and out.dtype == np.float32
    taps = jitter_kernel(600, AXIS)
    assert np.allclose(out[2, 0, 0], np.convolve(x[2, 0, 0], taps, mode="same"), rtol=1e-5)
    assert np.array_equal(jitter(x, 0, AXIS), x)
    bump = np.zeros((1, 40), np.float32)
    bump[0, 20] = 100.0
    assert jitter(bump, 600, AXIS).sum() == pytest.approx(100.0)  # away from the ends no count is lost
    # the blurred bump is as wide as the kernel asks: FWHM 600 ps = 7.7 bins
    blurred = jitter(bump, 600, AXIS)[0]
    assert (blurred >= blurred.max() / 2).sum() in (7, 8, 9)


def test_centre_zone():
    x = np.arange(2 * 9 * 5, dtype=np.float32).reshape(2, 3, 3, 5)
    assert np.array_equal(centre_zone(x), x[:, 1:2, 1:2])
    with pytest.raises(ValueError, match="3x3 histograms"):
        centre_zone(np.zeros((2, 8, 8, 5)))


def test_condition_names():
    assert jitter_condition(50) == "jitter50ps" and jitter_fwhm("jitter50ps") == 50 and jitter_fwhm("jitter0ps") == 0
    assert jitter_fwhm("light_on") is None and jitter_fwhm("jitter50") is None


def test_jitter_curve_has_every_task_metric_and_fwhm():
    rows = []
    for fwhm in (600, 0, 100):
        for seed, delta in ((42, 0.0), (43, 0.02)):
            rows.append(
                {
                    "task": "location",
                    "condition": jitter_condition(fwhm),
                    "seed": seed,
                    "test_rmse": 0.05 + fwhm / 1e4 + delta,
                    "test_mae": 0.04,
                    "baseline_rmse": 0.1,
                    "baseline_mae": 0.09,
                }
            )
            rows.append(
                {
                    "task": "size",
                    "condition": jitter_condition(fwhm),
                    "seed": seed,
                    "test_precision": 0.9,
                    "test_recall": 0.9,
                    "test_top1": 0.9 - delta,
                    "baseline_precision": 0.25,
                    "baseline_recall": 0.5,
                    "baseline_top1": 0.5,
                }
            )
    curve = jitter_curve(pd.DataFrame(rows), AXIS)
    assert list(curve.metric.unique()) == ["loc_rmse", "loc_mae", "size_precision", "size_recall", "size_accuracy"]
    rmse = curve[curve.metric == "loc_rmse"]
    assert list(rmse.fwhm_ps) == [0, 100, 600] and rmse.fwhm_bins.iloc[2] == pytest.approx(600 / AXIS.bin_width_ps)
    assert rmse["mean"].tolist() == pytest.approx([0.06, 0.07, 0.12]) and rmse["std"].iloc[0] == pytest.approx(0.02 / math.sqrt(2))
    assert (rmse.trivial == 0.1).all() and (curve.n_seeds == 2).all()
    with pytest.raises(ValueError, match="not jitter cells"):
        jitter_curve(pd.DataFrame(rows).assign(condition="all"), AXIS)
