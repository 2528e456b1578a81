"""Alignment, background subtraction, crop window, normalisation."""

import numpy as np
import pytest

from denali_pipe.preprocess import histograms as pp


def _pulse(bins=128, at=47.0, height=6000.0, floor=1300.0, tail=2.5):
    b = np.arange(bins)
    t = b - at
    return floor + height * np.where(t < 0, np.exp(-0.5 * (t / 1.2) ** 2), np.exp(-t / tail))


def _set(L=4, R=3, n=3, shift=None, bump=0.0, seed=0):
    rng = np.random.default_rng(seed)
    base = np.stack([_pulse(at=45 + 2 * z) for z in range(n * n)]).reshape(n, n, -1)
    h = np.broadcast_to(base, (L, R, n, n, 128)).copy()
    h[..., 1, 1, 90:95] += bump
    if shift is not None:
        for (l, r), d in np.ndenumerate(shift):
            h[l, r] = np.roll(h[l, r], d, axis=-1)
    return rng.poisson(h).astype(np.int32)


def test_alignment_undoes_whole_bin_shifts():
    shifts = np.array([[0, 2, -1], [3, 0, 0], [0, 0, -2], [1, 1, -5]])
    bg = _set(seed=1)
    h = _set(shift=shifts, seed=2)
    found = pp.alignment_shifts(h, bg.mean(axis=1))
    assert np.array_equal(found, -shifts)
    aligned = pp.shift_bins(h, found)
    assert np.array_equal(pp.alignment_shifts(aligned, bg.mean(axis=1)), np.zeros_like(shifts))


def test_shift_fills_with_the_edge_floor_not_wrapped_counts():
    h = np.zeros((1, 1, 1, 1, 8))
    h[..., :] = [5, 5, 100, 5, 5, 5, 5, 9]
    out = pp.shift_bins(h, np.array([[2]]))
    assert out.ravel().tolist() == [5, 5, 5, 5, 100, 5, 5, 5]
    out = pp.shift_bins(h, np.array([[-1]]))
    assert out.ravel().tolist() == [5, 100, 5, 5, 5, 5, 9, 9]


def test_alignment_refuses_absurd_shifts():
    bg = _set(seed=1)
    h = _set(shift=np.full((4, 3), pp.MAX_SHIFT_BINS + 3), seed=2)
    with pytest.raises(ValueError, match="bins off the background"):
        pp.alignment_shifts(h, bg.mean(axis=1))


def test_subtraction_leaves_the_bump_and_zero_mean_noise():
    bg = _set(seed=1)
    h = _set(bump=200.0, seed=2)
    d = pp.subtract_background(h, bg.mean(axis=1))
    assert d.dtype == np.float32
    assert d[..., 1, 1, 90:95].mean() == pytest.approx(200, abs=25)
    assert abs(d[..., 0, 0, 100:].mean()) < 10


def test_subtraction_shape_mismatch_is_an_error():
    with pytest.raises(ValueError, match="do not match"):
        pp.subtract_background(_set(L=4), _set(L=3).mean(axis=1))


def test_hard_threshold_is_four_over_root_three_for_a_square_matrix():
    assert pp.hard_threshold(1.0) == pytest.approx(4 / np.sqrt(3))
    assert pp.hard_threshold(1e-9) == pytest.approx(np.sqrt(2), rel=1e-6)


def _mount_return(L):
    """(L,) counts of a mount's return that changes smoothly with location."""
    return 300.0 + 250.0 * np.sin(np.linspace(0, 3, L))


def _background_truth(L=60, n=3):
    base = np.stack([_pulse(at=45 + 2 * z) for z in range(n * n)]).reshape(n, n, -1)
    truth = np.broadcast_to(base, (L, n, n, 128)).copy()
    truth[..., 1, 1, 90:95] += _mount_return(L)[:, None]
    return truth


def test_background_means_remove_shot_noise_and_keep_what_varies_with_location():
    truth = _background_truth()
    bg = np.random.default_rng(4).poisson(np.broadcast_to(truth[:, None], (60, 3, 3, 3, 128)))
    plain = bg.mean(axis=1)
    clean = pp.background_means(bg)
    assert clean.shape == plain.shape
    # the plain mean keeps all of one capture's shot noise, the low-rank one a few per cent
    assert np.sqrt(((clean - truth) ** 2).mean()) < 0.3 * np.sqrt(((plain - truth) ** 2).mean())
    mount = clean[..., 1, 1, 90:95].mean(axis=-1) - clean[..., 1, 1, 100:120].mean(axis=-1)
    assert np.abs(mount - _mount_return(60)).max() < 0.1 * _mount_return(60).mean()


def test_background_means_are_the_plain_mean_without_locations_or_repeats_to_compare():
    bg = _set(L=1, seed=1)
    assert np.array_equal(pp.background_means(bg), bg.mean(axis=1))
    bg = _set(L=4, R=1, seed=1)
    assert np.array_equal(pp.background_means(bg), bg.mean(axis=1))


def test_sets_at_one_location_share_no_background_noise():
    """Two object sets at the same locations, minus one background: their
    residuals in bins with no return must not correlate (a location
    fingerprint a model would learn), as they do with the plain mean."""
    L, n = 60, 3
    truth = _background_truth(L, n)
    rng = np.random.default_rng(6)
    draw = lambda: rng.poisson(np.broadcast_to(truth[:, None], (L, 3, n, n, 128)))  # noqa: E731
    bg, a, b = draw(), draw(), draw()

    def shared(background):
        ra, rb = (pp.subtract_background(h, background).mean(axis=1)[..., 100:] for h in (a, b))
        ra, rb = (r - r.mean(axis=0) for r in (ra, rb))
        return np.mean([np.corrcoef(ra[i].ravel(), rb[i].ravel())[0, 1] for i in range(L)])

    assert shared(bg.mean(axis=1)) > 0.4
    assert abs(shared(pp.background_means(bg))) < 0.1


NO_LEAD = np.full((3, 3), np.inf)  # no object can reach a zone before its direct return ends


def test_crop_window_starts_each_zone_after_its_direct_return():
    bgs = [_set(L=10, seed=s) for s in (1, 2)]
    w = pp.crop_window(bgs, NO_LEAD)
    # zone z peaks at 45 + 2 z; its tail (2.5 bins) falls to the floor (6000 -> 1300
    # counts of excess) ln(6000 / 1300) * 2.5 ~ 3.8 bins after the peak
    peaks = 45 + 2 * np.arange(9)
    assert np.all((w.zone_starts.ravel() >= peaks + 3) & (w.zone_starts.ravel() <= peaks + 6))
    assert w.crop_start == w.zone_starts.min()
    profile = np.mean([b.mean(axis=(0, 1)) for b in bgs], axis=0).reshape(9, -1)
    floor = profile[:, :16].mean(axis=1)
    for z, start in enumerate(w.zone_starts.ravel()):
        assert profile[z, start:].max() - floor[z] <= 1.1 * floor[z]


def test_crop_window_never_starts_a_zone_after_its_object_signal_can():
    # a tail that outlasts the nearest objects' returns: the zone keeps its
    # bins from its direct onset plus the geometry's lead, less the margin
    bgs = [_set(L=10, seed=s) for s in (1, 2)]
    ends = pp.crop_window(bgs, NO_LEAD).zone_starts
    onsets = np.min([pp.direct_onset(b.mean(axis=(0, 1)).reshape(9, -1), 30) for b in bgs], axis=0).reshape(3, 3)  # the earliest set's
    assert (onsets > 16).all() and (onsets < 45 + 2 * np.arange(9).reshape(3, 3)).all()
    lead = np.full((3, 3), 100.0)
    lead[1, 1] = 2.5  # an object can reach the centre zone 2.5 bins after its direct onset
    w = pp.crop_window(bgs, lead)
    assert w.zone_starts[1, 1] == onsets[1, 1] + 2 - pp.LEAD_MARGIN_BINS < ends[1, 1]
    others = np.ones((3, 3), bool)
    others[1, 1] = False
    assert np.array_equal(w.zone_starts[others], ends[others])
    with pytest.raises(ValueError, match="lead"):
        pp.crop_window(bgs, np.full((8, 8), 100.0))


def test_crop_window_ignores_zones_without_a_significant_return():
    bg = _set(L=10, seed=1).astype(np.int64)
    bg[:, :, 2, 2] = np.random.default_rng(3).poisson(0.5, bg[:, :, 2, 2].shape)  # a zone of shot noise only
    ends = pp.direct_end(bg.mean(axis=(0, 1)).reshape(9, -1), n_averaged=30)
    assert ends[8] == -1 and (ends[:8] > 0).all()
    w = pp.crop_window([bg], NO_LEAD)
    assert w.crop_start == ends[:8].min() and w.zone_starts[2, 2] == w.crop_start


def test_crop_window_round_trips_through_json():
    w = pp.crop_window([_set(L=4, seed=1)], NO_LEAD)
    back = pp.CropWindow.from_dict(w.to_dict())
    assert back.crop_start == w.crop_start and np.array_equal(back.zone_starts, w.zone_starts)


def test_preprocess_matches_locations_crops_and_masks_late_zones():
    bg = _set(L=4, seed=1)
    h = _set(L=3, bump=150.0, seed=2)
    starts = np.full((3, 3), 80)
    starts[2, 2] = 85
    window = pp.CropWindow(80, starts)
    bg = pp.background_means(bg)
    f = pp.preprocess(h, np.array([7, 3, 9]), bg, np.array([3, 5, 7, 9]), window)
    assert f.values.shape == (3, 3, 3, 3, 48)
    assert f.values[..., 1, 1, 10:15].mean() == pytest.approx(150, abs=25)
    assert np.all(f.values[..., 2, 2, :5] == 0) and np.any(f.values[..., 2, 2, 5:] != 0)
    with pytest.raises(ValueError, match="no capture at locations \\[8\\]"):
        pp.preprocess(h, np.array([7, 3, 8]), bg, np.array([3, 5, 7, 9]), window)
    with pytest.raises(ValueError, match="zones"):
        pp.preprocess(h, np.array([7, 3, 9]), bg, np.array([3, 5, 7, 9]), pp.CropWindow(80, np.full((8, 8), 80)))


def test_normalise_log_z_uses_given_statistics():
    x = np.array([[0.0, 10.0, -10.0, 100.0]])
    y, stats = pp.normalise(x, "log_z")
    assert abs(y.mean()) < 1e-5 and y.std() == pytest.approx(1, abs=1e-4)
    y2, stats2 = pp.normalise(x * 2, "log_z", stats)
    assert stats2 == stats and not np.allclose(y2, y)
    # on non-negative counts the signed log is the reference's log1p(clip(x, 0))
    counts = np.array([0.0, 3.0, 1e4])
    z, (mu, sigma) = pp.normalise(counts, "log_z")
    assert np.allclose(z * sigma + mu, np.log1p(counts), atol=1e-5)
    raw, none = pp.normalise(x, "raw")
    assert none is None and raw.dtype == np.float32
    with pytest.raises(ValueError, match="unknown normalisation"):
        pp.normalise(x, "minmax")


def test_normalise_never_produces_nan_on_constant_input():
    y, _ = pp.normalise(np.zeros((5, 3)), "log_z")
    assert np.isfinite(y).all()


def test_alignment_works_on_photon_starved_8x8_zones():
    rng = np.random.default_rng(5)
    base = np.stack([_pulse(at=43 + z % 8 * 2, height=1.5, floor=0.6) for z in range(64)]).reshape(8, 8, -1)
    bg = rng.poisson(np.broadcast_to(base, (4, 3, 8, 8, 128)))
    h = rng.poisson(np.broadcast_to(np.roll(base, 2, axis=-1), (4, 3, 8, 8, 128)))
    found = pp.alignment_shifts(h, bg.mean(axis=1))
    assert (found == -2).mean() >= 0.75 and np.abs(found + 2).max() <= 1
