"""Physics of the synthetic rig's histogram model, asserted with noise off."""

import numpy as np
import pytest

from denali_pipe import geometry as geo
from denali_pipe.objects import load_catalogue
from denali_pipe.rig import histograms as H
from denali_pipe.rig.scene import mount_scatterer, object_scatterer

from conftest import REPO


@pytest.fixture(scope="module")
def phot(demo_config):
    return H.Photometry.from_config(demo_config["rig"]["photometry"])


@pytest.fixture(scope="module")
def catalogue():
    return load_catalogue(REPO / "config" / "objects.tsv")


def plate(centre, normal, side=0.2, spacing=0.01, rho_diffuse=0.0, rho_retro=0.6):
    """A square plate facing `normal`, in a vertical plane (tests only)."""
    u = np.cross([0, 0, 1.0], normal)
    u /= np.linalg.norm(u)
    xs = np.arange(-side / 2 + spacing / 2, side / 2, spacing)
    X, Z = np.meshgrid(xs, xs)
    pts = centre + X.ravel()[:, None] * u + Z.ravel()[:, None] * np.array([0, 0, 1.0])
    n = len(pts)
    return H.Scatterer(pts, np.tile(normal, (n, 1)), np.full(n, spacing**2), rho_diffuse, rho_retro)


def object_only(res, scene, phot, light_on=True):
    return H.expected_counts(res, light_on, scene, phot) - H.expected_counts(res, light_on, [], phot)


def peak_bin(h):
    """Sub-bin peak position by a parabola through the maximum and its neighbours."""
    i = int(np.argmax(h))
    a, b, c = h[i - 1], h[i], h[i + 1]
    return i + 0.5 * (a - c) / (a - 2 * b + c)


@pytest.mark.parametrize("shift", [0.05, 0.1, 0.2])
def test_bump_arrives_later_with_distance(phot, shift):
    # a plate straight in front of the centre zone's wall patch, facing the wall
    ws = H.wall_samples("3x3")
    patch = ws.q[4].mean(0)
    near = patch + np.array([0, -0.3, 0])
    far = near + np.array([0, -shift, 0])
    normal = -geo.WALL.normal
    h_near = object_only("3x3", [plate(near, normal)], phot)[1, 1]
    h_far = object_only("3x3", [plate(far, normal)], phot)[1, 1]
    expected = 2 * shift / geo.BIN_WIDTH_OPL
    assert peak_bin(h_far) - peak_bin(h_near) == pytest.approx(expected, abs=1.0)


def test_bump_moves_with_the_gantry(phot, catalogue):
    # moving one row away from the wall delays the return in every zone's sum
    spec = catalogue["square"]
    peaks = []
    for row in range(0, 10, 3):
        k = row * 10 + (0 if row % 2 == 0 else 9)  # physical column 0 on every row
        h = object_only("3x3", [object_scatterer(spec, "8inch", k)], phot).sum((0, 1))
        peaks.append(peak_bin(h))
    assert np.all(np.diff(peaks) > 0)


def test_signal_bigger_for_8in_and_for_retroreflective(phot, catalogue):
    k = 44

    def total(name, size):
        return object_only("3x3", [object_scatterer(catalogue[name], size, k)], phot).sum()

    assert total("1", "8inch") > 2 * total("1", "4inch")
    assert total("1", "8inch") > 2 * total("generalization1white", "8inch")
    assert total("generalization1white", "8inch") > total("generalization1cardstock", "8inch") > 0


def test_lights_on_raise_the_floor(phot):
    on = H.expected_counts("3x3", True, [], phot)
    off = H.expected_counts("3x3", False, [], phot)
    assert np.all(on[..., :20] > off[..., :20])
    assert np.allclose(on[..., :20] - off[..., :20], on[..., :20].mean() - off[..., :20].mean(), rtol=0.3)


def test_8x8_zones_hold_far_fewer_counts(phot):
    z3 = H.expected_counts("3x3", True, [mount_scatterer(50)], phot).sum(-1)
    z8 = H.expected_counts("8x8", True, [mount_scatterer(50)], phot).sum(-1)
    assert z8.max() * 100 <= z3.min()


def test_magnitudes_follow_the_real_sensor(phot, catalogue):
    # pooled over both lightings, mean log1p(counts) on 3x3 is about 7.1; the
    # direct wall peak is several thousand counts
    rng = np.random.default_rng(0)
    scene = [mount_scatterer(30), object_scatterer(catalogue["A"], "8inch", 30)]
    hists = [H.sample_counts(H.expected_counts("3x3", light, scene, phot), phot, rng) for light in (True, False)]
    assert np.mean(np.log1p(hists)) == pytest.approx(7.1, abs=0.25)
    peak = H.expected_counts("3x3", False, [], phot).max(-1)
    assert 2000 < peak[1, 1] < 10000
    assert peak.min() > 1000  # every zone sees the direct return


def test_direct_return_sits_at_the_wall_distance(phot):
    h = H.expected_counts("3x3", False, [], phot)[1, 1]
    r = H.wall_samples("3x3").r[4]
    # pulse delay: the exGaussian's mode lies a little after the true arrival
    assert peak_bin(h) == pytest.approx(geo.opl_to_bin(2 * r.mean()), abs=2.5)


def test_noise_is_poisson_plus_read(phot):
    mean = H.expected_counts("3x3", True, [], phot)
    draws = np.stack([H.sample_counts(mean, phot, np.random.default_rng(s)) for s in range(200)])
    assert draws.dtype == np.int32 and draws.min() >= 0
    var = draws[..., :30].var(0).mean()
    expected = mean[..., :30].mean() + phot.read_noise_counts**2
    assert var == pytest.approx(expected, rel=0.1)


def test_pulse_is_unit_area():
    M = H.pulse_matrix(1.2, 2.5)
    x = np.zeros(128)
    x[40] = 1.0
    assert (x @ M).sum() == pytest.approx(1.0, abs=1e-6)
    assert np.argmax(x @ M) >= 40
