"""The capture floor offset's statistics: what is taken for an offset and what for noise."""

import numpy as np
import pytest

from denali_pipe.core.floor import common_offset, kept_bins, offset_spread


def test_a_common_offset_within_the_noise_is_not_taken():
    rng = np.random.default_rng(0)
    assert common_offset(rng.normal(0.0, 5.0, 400)) == 0.0
    assert common_offset(np.array([3.0])) == 0.0
    o = rng.normal(-15.0, 30.0, 400)
    assert common_offset(o) == pytest.approx(o.mean())


def test_a_spread_within_the_noise_is_not_taken_for_offsets():
    """Readings of noise sd 6 alone leave no offset variance; offsets of sd
    35 under the same noise come back as their own variance."""
    rng = np.random.default_rng(1)
    noise = np.full(400, 36.0)
    assert offset_spread(rng.normal(0.0, 6.0, 400), noise) == 0.0
    spread = offset_spread(rng.normal(0.0, 35.0, 400) + rng.normal(0.0, 6.0, 400), noise)
    assert np.sqrt(spread) == pytest.approx(35.0, rel=0.1)
    assert offset_spread(np.array([1.0]), np.array([1.0])) == 0.0


def test_kept_bins_are_those_not_zeroed_in_any_capture():
    """The preprocessing zeroes a zone's bins before its start in every
    capture; a kept bin may be 0 in one capture by chance, not in all."""
    counts = np.array([[0.0, 0.0, 3.0, -1.0], [0.0, 0.0, 0.0, 2.0]])
    assert kept_bins(counts).tolist() == [[False, False, True, True], [False, False, False, True]]
    assert kept_bins(counts, axis=0).tolist() == [False, False, True, True]
