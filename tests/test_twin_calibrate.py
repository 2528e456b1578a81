"""The twin's calibration: parameters planted in synthetic captures made by
the twin itself come back within their bootstrap uncertainties, the held-out
residual falls, and the file round-trips into calibrated twins."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from denali_pipe.core.pulse import Pulse
from denali_pipe.twin import calibrate as C
from denali_pipe.twin.layout import ZoneGeometry, load_calibration, nominal_scene, zone_footprints

LOCATIONS = list(range(0, 100, 7))
CROP, T, R = 60, 60, 3
SETTINGS = {
    "wall_albedo": 1.0, "object_albedo": 0.5, "table": False, "table_albedo": 0.5,
    "material": "retroreflective", "retroreflective": {"lobe_width_deg": 10.0, "diffuse_share": 0.3},
    "footprint": {"film": 8, "scale": 1.0},
    "calibration": {
        "film": 2, "samples": 10, "validation_fraction": 0.2, "max_captures": 0,
        "bootstrap_resamples": 50, "level": 0.9, "max_evaluations": 500,
        "pulse": {"sigma_bins": 1.0, "tail_bins": 1.0},
    },
}  # fmt: skip
GLOBALS = (*C.GLOBALS, "lobe_width_deg", "diffuse_share")
FLOOD = {**SETTINGS, "illumination": "flood", "flood": {"grid": 2, "beam_hwhm_deg": [26.0, 20.5]}}


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "scene.json"
    path.write_text(json.dumps(nominal_scene(LOCATIONS)))
    return load_calibration(path)


def _plant(cal, catalogue, settings, tail):
    """Captures drawn from the twin at known parameters: (truth, captures, specs);
    `tail` the fit coordinates after the zones' (`C.tail_names`)."""
    specs = {k: catalogue[k] for k in ("A", "circle")}
    keys = pd.DataFrame(
        [(f"{o}_{s}_3x3_lighton", o, s, loc) for o, s in (("A", "8inch"), ("circle", "4inch")) for loc in LOCATIONS],
        columns=["set", "object", "size", "location"],
    )
    rng = np.random.default_rng(1)
    truth = C.initial(settings)
    truth[:18] = rng.uniform(-1.5, 1.5, 18)  # cm
    truth[18:27] = np.log(rng.uniform(0.9, 1.15, 9))
    truth[27:] = tail
    dummy = C.Captures(np.zeros((len(keys), R, 3, 3, T), np.float32), keys, CROP)
    m = C.Problem(C.Model(cal, specs, keys, settings), dummy, settings).twins(truth)
    mean = rng.uniform(0.5, 2, 9)[None, :, None] * m * 1e3 / m.max()
    real = mean[:, None] + rng.normal(0, 0.005 * mean.max(), (len(keys), R, 9, T))
    return truth, C.Captures(real.reshape(len(keys), R, 3, 3, T).astype(np.float32), keys, CROP), specs


@pytest.fixture(scope="module")
def planted(cal, catalogue):
    # a pulse that rises within a bin and decays over several, as a SPAD's does
    return _plant(cal, catalogue, SETTINGS, [1.7, np.log(0.8), np.log(2.5), np.log(14.0), np.log(0.4 / 0.6)])


@pytest.fixture(scope="module")
def fitted(cal, planted):
    truth, captures, specs = planted
    return C.calibrate(cal, specs, captures, SETTINGS, seed=0)


def test_planted_parameters_come_back(planted, fitted):
    truth, _, _ = planted
    result, _, _ = fitted
    want, got = C.to_physical(truth, SETTINGS), C.to_physical(result.x, SETTINGS)
    for k in GLOBALS:
        se = float(np.asarray(result.se[k]))
        assert 0 < se and abs(got[k] - want[k]) <= 4 * se + 1e-3 * abs(want[k]), (k, got[k], want[k], se)
    # the zones' footprints: each within 4 standard errors, but for a few
    # that trade centre against size along the object's path (weakly identified)
    hits = [np.abs(np.asarray(got[k]) - want[k]) <= 4 * np.asarray(result.se[k]) + 1e-3 for k in ("offset_u", "offset_v", "scale")]
    assert np.mean(hits) >= 0.8, hits
    # the standard errors are the errors' size, neither far wider (an
    # interval that cannot fail) nor far narrower (a median |error| / se of
    # ~0.67 for calibrated normal errors)
    z = np.concatenate([np.abs(np.ravel(got[k]) - np.ravel(want[k])) / np.ravel(result.se[k]) for k in want])
    assert 0.2 < np.median(z) < 3, np.median(z)


def test_the_fit_records_its_evaluations_and_stops_at_its_budget(fitted):
    result, problem, _ = fitted
    assert result.fit["converged"] and 0 < result.fit["evaluations"] <= 500
    _, record = C.fit(problem, C.initial(SETTINGS), max_evaluations=2)
    assert record == {"evaluations": 2, "converged": False}


def test_held_out_residual_falls_in_every_zone(fitted):
    result, _, held = fitted
    before, after = np.array(result.before["nl2"]), np.array(result.after["nl2"])
    assert (after < before).all() and (after < 0.2).all()
    # as close as the noise allows: held-out chi2 per zone near 1
    assert (np.array(result.after["chi2"]) < 1.5).all()


def test_the_fit_never_sees_held_out_captures(planted, fitted):
    _, captures, _ = planted
    _, problem, held = fitted
    fit_keys = set(map(tuple, problem.model.keys[["set", "location"]].values))
    held_keys = set(map(tuple, held.model.keys[["set", "location"]].values))
    assert fit_keys and held_keys and not fit_keys & held_keys and len(fit_keys | held_keys) == len(captures.keys)


def test_file_round_trips_into_calibrated_twins(cal, catalogue, fitted, tmp_path):
    result, _, _ = fitted
    path = tmp_path / "twin_calibration.json"
    C.write_calibration(path, result, SETTINGS, {"n_captures": 1})
    f = C.read_calibration(path)
    phys = C.to_physical(result.x, SETTINGS)
    assert np.allclose(f.offsets[..., 0], phys["offset_u"]) and np.allclose(f.scales, phys["scale"])
    assert f.material.lobe_width_deg == pytest.approx(phys["lobe_width_deg"]) and f.time_offset == pytest.approx(phys["time_offset"])
    doc = json.loads(path.read_text())
    assert set(doc["se"]) == set(doc["parameters"]) and np.shape(doc["interval"]["scale"]) == (3, 3, 2)
    # the calibrated twin: its 3x3 footprints are the fit's, a non-RR object stays Lambertian
    tw = f.twin_scene(cal, _mesh(catalogue), SETTINGS, 3, catalogue["generalization1white"])
    assert tw.material.kind == "lambertian" and tw.time_offset_opl > 0
    assert np.allclose(tw.relays[2].size, zone_footprints(cal, 3, ZoneGeometry(f.offsets, f.scales))[2].size)
    with pytest.raises(ValueError, match="not a twin calibration"):
        C.read_calibration(tmp_path / "missing.json")
    # how the fit ended, as the stability report reads it: one named value per fit coordinate
    status = C.read_fit_status(path)
    assert status.n_coordinates == len(result.x) and status.at_bound == tuple(C.at_bound(result.x, SETTINGS))
    assert (status.converged, status.evaluations) == (result.fit["converged"], result.fit["evaluations"])
    with pytest.raises(ValueError, match="not a twin calibration"):
        C.read_fit_status(tmp_path / "missing.json")


def test_under_the_flood_the_emission_widths_come_back(cal, catalogue, tmp_path):
    """Planted under the flood (a beam narrower than the design's), the fit
    returns the diffuse share and both emission half widths within 4
    standard errors, fits no lobe width (the flood's narrow limit), and its
    file makes flood twins of the fitted beam."""
    assert C.tail_names(FLOOD) == [*C.GLOBALS, "diffuse_share", *C.EMISSION]
    truth, captures, specs = _plant(cal, catalogue, FLOOD, [1.7, np.log(0.8), np.log(2.5), np.log(0.4 / 0.6), np.log(15.0), np.log(12.0)])
    result, _, _ = C.calibrate(cal, specs, captures, FLOOD, seed=0)
    want, got = C.to_physical(truth, FLOOD), C.to_physical(result.x, FLOOD)
    assert "lobe_width_deg" not in got
    for k in ("diffuse_share", *C.EMISSION):
        se = float(np.asarray(result.se[k]))
        assert 0 < se and abs(got[k] - want[k]) <= 4 * se + 1e-3 * abs(want[k]), (k, got[k], want[k], se)
    assert (np.array(result.after["nl2"]) < np.array(result.before["nl2"])).all()
    path = tmp_path / "twin_calibration.json"
    C.write_calibration(path, result, FLOOD, {"n_captures": 1})
    f = C.read_calibration(path)
    assert f.illumination == "flood" and f.hwhm_deg == pytest.approx((got["beam_hwhm_h_deg"], got["beam_hwhm_v_deg"]))
    tw = f.twin_scene(cal, _mesh(catalogue), {**FLOOD, "illumination": "spot"}, 3, catalogue["A"])  # the file's illumination, whatever the settings say
    assert tw.flood is not None and tw.flood.hwhm_deg == pytest.approx(f.hwhm_deg)
    assert tw.material.lobe_width_deg == SETTINGS["retroreflective"]["lobe_width_deg"]  # kept, unused


def _mesh(catalogue):
    from denali_pipe.core.meshes import object_mesh

    return object_mesh(catalogue["A"], "8inch")


def test_8x8_follows_the_3x3_fit(cal):
    """A shift common to the 3x3 zones moves every 8x8 zone by it; their scale is the mean."""
    offsets = np.zeros((3, 3, 2))
    offsets[..., 0], offsets[..., 1] = 0.012, -0.004
    scales = np.linspace(0.9, 1.1, 9).reshape(3, 3)
    from denali_pipe.twin.layout import Material

    f = C.Fitted(offsets, scales, 0.0, Pulse(1.0, 1.0), np.ones((3, 3)), Material("lambertian", 0.5), "spot", None)
    z8 = f.zones(cal, 8)
    assert np.allclose(z8.offsets[..., 0], 0.012, atol=1e-9) and np.allclose(z8.offsets[..., 1], -0.004, atol=1e-9)
    assert np.allclose(z8.scales, 1.0)


def test_at_bound_names_the_pinned_coordinates():
    x = C.initial(SETTINGS)
    x[0], x[3], x[20], x[27], x[29] = C.OFFSET_CM_BOUND, -C.OFFSET_CM_BOUND, np.log(3.0), -20.0, np.log(15.0)
    assert C.at_bound(x, SETTINGS) == ["offset_u[0, 0]", "offset_v[0, 1]", "scale[0, 2]", "time_offset", "pulse_tail"]
    assert C.at_bound(C.initial(SETTINGS), SETTINGS) == []
    # where the solver stops when pushed against a bound: just inside it
    x = C.initial(SETTINGS)
    x[22], x[24] = np.log(2.9999955), np.log(2.9992)
    assert C.at_bound(x, SETTINGS) == ["scale[1, 1]", "scale[2, 0]"]
    x[24] = np.log(2.9)
    assert C.at_bound(x, SETTINGS) == ["scale[1, 1]"]


def test_gains_are_never_negative():
    # a zone whose data run against its twin (background residue, no return)
    # gets no gain rather than an upside-down twin; elsewhere least squares
    m = np.ones((4, 2, 5))
    problem = SimpleNamespace(y=np.stack([-m[:, 0], 2 * m[:, 1]], axis=1))
    assert C.Problem.gains(problem, m).tolist() == [0.0, 2.0]
