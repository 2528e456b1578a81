"""`rig/feature_moments.py` on the release's own statistics (REFERENCE Part 7)."""

import numpy as np
import pytest
from conftest import ASSETS

from denali_pipe.report.paper import REAL_LOG_ZONE_MEANS, REAL_ZONE_MEANS
from denali_pipe.rig import feature_moments as fm

STATS = ASSETS / "feature_stats"
pytestmark = pytest.mark.skipif(not (STATS / fm.NPZ).exists(), reason="the release's feature statistics are not present")


@pytest.fixture(scope="module")
def nets():
    return fm.load_backbones(STATS)


def reference_moments(net, hist):
    """The backbone written out plainly in float64 (loops over taps, erf GELU)."""
    from scipy.special import erf

    x = net.transform(hist)
    out = []
    for layer in net.layers:
        k = layer.conv.shape[-1]
        xp = np.pad(x, ((0, 0), (0, 0), (k // 2, k // 2)))
        y = sum(np.einsum("oc,nct->not", layer.conv[:, :, j], xp[:, :, j : j + x.shape[-1]]) for j in range(k))
        out.append((y.mean(axis=(0, 2)), y.var(axis=(0, 2))))
        z = (y - layer.running_mean[:, None]) / np.sqrt(layer.running_var[:, None] + layer.eps) * layer.bn_weight[:, None] + layer.bn_bias[:, None]
        x = 0.5 * z * (1 + erf(z / np.sqrt(2)))
    return out


def test_all_eighteen_nets_with_their_own_inputs(nets):
    assert len(nets) == 18
    assert sum(n.input == "raw" for n in nets) == 3
    for n in nets:
        assert [layer.conv.shape for layer in n.layers] == [(128, 9, 5), (128, 128, 3), (64, 128, 3)]
        if n.input == "log_z":
            assert n.log_mean == pytest.approx(fm.LOG_MEAN, abs=0.002) and n.log_std == pytest.approx(fm.LOG_STD, abs=0.002)


def test_forward_pass_matches_a_plain_float64_backbone(nets):
    rng = np.random.default_rng(0)
    hist = rng.poisson(np.asarray(REAL_ZONE_MEANS).reshape(1, 9, 1) * rng.uniform(0.3, 3.0, (12, 9, 128))).astype(float)
    for net in (nets[0], next(n for n in nets if n.input == "raw")):
        for (m, v), (rm, rv) in zip(fm.layer_moments(net, hist), reference_moments(net, hist)):
            np.testing.assert_allclose(m, rm, atol=1e-4 * np.sqrt(rv.max()))
            np.testing.assert_allclose(v, rv, rtol=1e-4, atol=1e-6 * rv.max())
        # the first layer alone, as the fit reads it
        np.testing.assert_array_equal(fm.layer_moments(net, hist, depth=1)[0][1], fm.layer_moments(net, hist)[0][1])


def test_the_real_zone_means_give_the_real_layer_1_means(nets):
    # Layer 1 is linear and bias-free: flat histograms at the real zone means
    # (Part 5's counts for the raw nets, Part 7's z for the log nets) have the
    # real running means, up to the time padding (~1 %)
    raw = np.broadcast_to(np.asarray(REAL_ZONE_MEANS).reshape(1, 9, 1), (1, 9, 128))
    logs = np.broadcast_to(np.expm1(fm.LOG_MEAN + fm.LOG_STD * np.asarray(REAL_LOG_ZONE_MEANS)).reshape(1, 9, 1), (1, 9, 128))
    for net in nets:
        mean, var = fm.layer_moments(net, raw if net.input == "raw" else logs)[0]
        assert fm.moment_terms(mean, var, net.layers[0])[0] < 0.02, net.name
        # a centre zone 30 % too bright is plainly seen
        bright = (raw if net.input == "raw" else logs).copy()
        bright[0, 4] *= 1.3
        mean, var = fm.layer_moments(net, bright)[0]
        assert fm.moment_terms(mean, var, net.layers[0])[0] > 0.05, net.name


def test_features_drawn_at_the_real_moments_are_at_distance_zero(nets):
    rng = np.random.default_rng(1)
    for net in (nets[0], next(n for n in nets if n.input == "raw")):
        for layer in net.layers:
            feats = layer.running_mean[:, None] + np.sqrt(layer.running_var)[:, None] * rng.standard_normal((len(layer.running_mean), 20_000))
            m, v, signed = fm.moment_terms(feats.mean(1), feats.var(1), layer)
            assert m < 0.02 and v < 0.03
            # e times the real variance: the variance term reads 1, signed +1
            wide = layer.running_mean[:, None] + np.sqrt(np.e * layer.running_var)[:, None] * rng.standard_normal((len(layer.running_mean), 20_000))
            m, v, signed = fm.moment_terms(wide.mean(1), wide.var(1), layer)
            assert v == pytest.approx(1.0, abs=0.05) and signed == pytest.approx(1.0, abs=0.05)


def test_distance_table_and_summary(nets):
    rng = np.random.default_rng(2)
    hist = rng.poisson(np.asarray(REAL_ZONE_MEANS).reshape(1, 9, 1), (8, 9, 128))
    table = fm.feature_distances(nets, hist)
    assert list(table.columns) == list(fm.COLUMNS) and len(table) == 54
    np.testing.assert_allclose(table.distance, table.mean_term + table.var_term)
    s = fm.summary(table)
    assert s["distance"] == pytest.approx(table.distance.mean())
    assert s["raw layer-1 var"] == pytest.approx(table[(table.input == "raw") & (table.layer == 1)].var_term.mean())
    # flat Poisson floors hold far less temporal contrast than real captures
    assert s["raw layer-1 var"] > 1.0


def test_time_profile_of_flat_histograms(nets):
    # flat in time: away from the padded ends every position holds the same
    # layer-1 output, sum_k W[:, :, k] @ m, with no variance over samples
    net = next(n for n in nets if n.input == "raw")
    m = np.asarray(REAL_ZONE_MEANS).ravel() * 1.2
    profile = fm.time_profile(net, np.broadcast_to(m[None, :, None], (2, 9, 128)))
    layer = net.layers[0]
    y = layer.conv.sum(-1) @ m
    expected = np.median((y - layer.running_mean) ** 2 / layer.running_var)
    assert profile.shape == (3, 128)
    np.testing.assert_allclose(profile[0, 4:-4], expected, rtol=1e-4)


def test_log_zone_means_are_the_transform_averaged():
    hist = np.full((2, 9, 128), np.expm1(fm.LOG_MEAN + fm.LOG_STD * 0.5))
    np.testing.assert_allclose(fm.log_zone_means(hist), 0.5)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match=fm.NPZ):
        fm.load_backbones(tmp_path)


def test_the_size_nets_hold_the_two_halves_of_the_base_captures(nets):
    """The 4 in and 8 in nets' log moments pool exactly into the both-size
    net's: each held every base capture of its size, which is what lets their
    difference stand for the real size contrast."""
    m = fm.real_log_moments_by_size(nets)
    (mu4, sd4), (mu8, sd8), (mu, sd) = m["4inch"], m["8inch"], m["both"]
    assert (mu4 + mu8) / 2 == pytest.approx(mu, abs=1e-5)
    assert (sd4**2 + sd8**2) / 2 + ((mu8 - mu4) / 2) ** 2 == pytest.approx(sd**2, abs=1e-5)
    # the real 8 in objects raise the log counts a little and narrow their spread
    assert 0 < mu8 - mu4 < 0.01 and -0.01 < sd8 - sd4 < 0


def test_log_moments_and_a_missing_size_net(nets):
    hist = np.array([[[0.0, np.e - 1]], [[-5.0, np.e**3 - 1]]])  # log1p: 0, 1, 0 (clipped), 3
    assert fm.log_moments(hist) == pytest.approx((1.0, np.sqrt(1.5)))
    with pytest.raises(KeyError, match="italics_loc"):
        fm.real_log_moments_by_size([n for n in nets if n.name != "italics_loc"])
