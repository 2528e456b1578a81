"""The sensor's response: first-photon pile-up, its inverse, the sampled pulse (sensor.response)."""

import numpy as np
import pytest

from denali_pipe.sensor.response import (
    PULSE_STEP,
    counts_from_rates,
    pulse_area,
    pulse_at,
    pulse_offsets,
    rates_from_counts,
    tail_summary,
)


def exponential_pulse(tau=3.0):
    """An exponential decay from 0 integrated over one bin: continuous, as a bin-integrated pulse is."""
    u = pulse_offsets()
    cdf = lambda t: np.where(t > 0, -np.expm1(-np.clip(t, 0, None) / tau), 0.0)  # noqa: E731
    p = cdf(u + 0.5) - cdf(u - 0.5)
    return p / pulse_area(p)


def test_pile_up_lowers_the_floor_after_a_return_by_exp_minus_its_rate():
    """Coates: every bin after a return keeps exp(-Lambda) of its counts, Lambda the return's detections per cycle."""
    floor, cycles, bins = 2e-5, 4e6, 128
    rates = np.full(bins, floor)
    rates[40] += 0.7  # a strong return, all in one bin
    h = counts_from_rates(rates, cycles)
    before, after = h[30], h[50]
    assert after / before == pytest.approx(np.exp(-0.7 - 20 * floor), rel=1e-6)
    assert h[40] == pytest.approx(cycles * np.exp(-40 * floor) * -np.expm1(-(0.7 + floor)), rel=1e-9)


def test_rates_from_counts_inverts_counts_from_rates():
    rng = np.random.default_rng(0)
    rates = rng.uniform(0, 0.01, (3, 9, 128))
    rates[..., 30] = 0.5
    back, sd = rates_from_counts(counts_from_rates(rates, 4e6), 4e6)
    np.testing.assert_allclose(back, rates, rtol=1e-9, atol=1e-15)
    assert sd.shape == rates.shape and np.all(sd > 0)


def test_more_counts_than_cycles_can_give_is_refused():
    with pytest.raises(ValueError, match="more counts"):
        rates_from_counts(np.full((1, 128), 1e5), 1e6)


def test_the_sampled_pulse_has_unit_area_at_any_sub_bin_position():
    p = exponential_pulse()
    for mu in (20.0, 20.3, 20.75):
        assert pulse_at(p, np.arange(128) - mu).sum() == pytest.approx(1.0, abs=2e-3)
    assert pulse_at(p, np.array([-100.0, 1000.0])).tolist() == [0.0, 0.0]
    assert pulse_at(p, np.array([2.0 + PULSE_STEP / 2]))[0] == pytest.approx(np.mean(pulse_at(p, np.array([2.0, 2.0 + PULSE_STEP]))))


def test_tail_summary_reads_an_exponential_tail():
    s = tail_summary(exponential_pulse(3.0))
    assert s["time_constant_bins"] == pytest.approx(3.0, rel=0.02)
    # the bin-integrated decay peaks half a bin after its onset; quarter-bin samples put the cut within an eighth of a bin
    assert s["peak_offset_bins"] == 0.5 and s["share_from_5_bins"] == pytest.approx(np.exp(-5.5 / 3), rel=0.06)
