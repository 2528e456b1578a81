"""Centre-zone measurements, on histograms whose answers are known."""

import numpy as np
import pytest

from denali_pipe.rig.measure import fwhm, matched_filter_snr, measure, zone_shape


def gaussian(b, centre, sigma, height):
    return height * np.exp(-0.5 * ((b - centre) / sigma) ** 2)


def test_measure_reads_floors_peak_and_bump():
    b = np.arange(128.0)
    background = np.where(b < 50, 200.0, 100.0) + gaussian(b, 45, 1.5, 10000)
    capture = background + gaussian(b, 100, 2.0, 500)
    m = measure(capture, background)
    assert m.floor_before == pytest.approx(200, rel=1e-6)
    assert m.floor_after == pytest.approx(100, rel=1e-6)
    assert m.direct_bin == 45 and m.direct_peak == pytest.approx(10200, rel=1e-3)
    assert m.bump_bin == 100 and m.bump_excess == pytest.approx(500)
    assert m.bump_fwhm == pytest.approx(2 * np.sqrt(2 * np.log(2)) * 2.0, rel=0.05)
    assert m.bump_over_floor == pytest.approx(2.5)
    assert m.late_over_floor == pytest.approx(0.5)
    assert m.bump_fraction == pytest.approx(500 / 10200, rel=1e-3)


def test_fwhm_of_a_box():
    x = np.zeros(20)
    x[8:12] = 1.0
    assert fwhm(x, 9) == pytest.approx(4.0)


def test_matched_filter_snr_of_a_known_bump():
    b = np.arange(128.0)
    expected = np.full(128, 400.0)
    signal = gaussian(b, 60, 2.0, 100.0)
    # sum s^2 / 400 for a Gaussian of height h and sigma 2: h^2 sqrt(pi) 2 / 400
    assert matched_filter_snr(signal, expected, 0.0) == pytest.approx(np.sqrt(100.0**2 * np.sqrt(np.pi) * 2 / 400), rel=1e-3)
    assert matched_filter_snr(signal, expected, 20.0) == pytest.approx(matched_filter_snr(signal, expected, 0.0) / np.sqrt(2), rel=1e-3)


def test_zone_shape_reads_rise_width_tails_late_floor_and_near_field():
    b = np.arange(128.0)
    h = np.full(128, 100.0)
    h[50:54] += 1000.0  # the direct return: 4 bins at its peak
    h[54:] += 1000.0 * 0.2 * np.exp(-(b[54:] - 54) / 10)  # a slow tail
    h[15] += 30.0  # a near-field return
    h[-18:] -= 50.0  # the late floor at half
    s = zone_shape(h)
    assert s["half_rise"] == 50 and s["width"] == 4
    # the tail 5-14 bins after the first peak bin (50): bins 55-64
    assert s["tail_5_14"] == pytest.approx((0.2 * np.exp(-(b[55:65] - 54) / 10)).mean())
    assert s["near_field"] == pytest.approx(0.03)
    assert s["late_over_floor"] == pytest.approx((100 - 50 + 200 * np.exp(-(b[-18:] - 54) / 10)).mean() / 100)
