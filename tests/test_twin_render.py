"""The twin's renderers: Mitsuba scenes for every object, mitransient against
the analytic model, arrival times, tables, the render job and its store."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from denali_pipe.cli import main
from denali_pipe.core import geometry as geo
from denali_pipe.core import pulse
from denali_pipe.core.meshes import front_samples, object_mesh
from denali_pipe.core.pulse import Pulse
from denali_pipe.twin.analytic import AnalyticRenderer
from denali_pipe.twin.layout import Emission, Flood, Material, laser_spot, load_calibration, nominal_scene, pixel_centres, twin_scene, zone_footprints
from denali_pipe.twin.render import read_twin, render_twin

LOCATIONS = (0, 9, 55, 99)  # near/far from the wall, both ends of the gantry
# The reference twin's bins, and a measured-like axis (docs/sensor.md): 93 ps, zero path at bin 16.
AXIS = geo.PAPER_TIME_AXIS
AXIS_93 = geo.TimeAxis(bin_width_ps=93.0, zero_bin=16.0)
SETTINGS = {
    "renderer": "analytic",
    "wall_albedo": 1.0,
    "object_albedo": 0.5,
    "material": "lambertian",
    "retroreflective": {"lobe_width_deg": 10.0, "diffuse_share": 0.3},
    "table": False,
    "table_albedo": 0.5,
    "footprint": {"film": 8, "scale": 1.0},
    "analytic": {"samples": 60},
    "mitransient": {"variant": "auto", "spp": 4000, "max_depth": 3},
}
FLOOD = {**SETTINGS, "illumination": "flood", "flood": {"grid": 3, "beam_hwhm_deg": [26.0, 20.5], "core_share": 0.5, "core_hwhm_deg": 5.0}}


@pytest.fixture(scope="module")
def scene_json(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "scene.json"
    path.write_text(json.dumps(nominal_scene(LOCATIONS)))
    return path


@pytest.fixture(scope="module")
def cal(scene_json):
    return load_calibration(scene_json)


@pytest.fixture(scope="module")
def mi():
    from denali_pipe.twin.variant import load_mitsuba

    return load_mitsuba("auto")


def mitransient(twin, spp, seed=1):
    from denali_pipe.twin.mitransient import MitransientRenderer

    return MitransientRenderer(twin, spp, 3, seed)


def test_every_catalogue_object_builds_a_scene(mi, cal, catalogue):
    from denali_pipe.twin.scene import transient_scene

    for spec in catalogue.values():
        for size in spec.sizes:
            twin = twin_scene(cal, object_mesh(spec, size), SETTINGS, AXIS)
            scene = mi.load_dict(transient_scene(mi, twin, twin.relays[0], 3, "transient_nlos_path", LOCATIONS[0]))
            ids = sorted(s.id() for s in scene.shapes())
            assert ids == ["object", "relay", "spot"], (spec.name, size)
            area = scene.shapes()[ids.index("object")].surface_area()[0]
            assert area == pytest.approx(front_samples(twin.mesh, 0.002)[1].sum(), rel=0.01), (spec.name, size)


CORNER_CENTRE_EDGE = (0, 4, 5)  # zones away from the spot, holding it, beside it


@pytest.mark.parametrize(
    "name,size,material",
    [("A", "8inch", Material("lambertian", 0.5)), ("1", "4inch", Material("lambertian", 0.5)), ("A", "8inch", Material("retroreflective", 0.5, 10.0, 0.3))],
)
def test_mitransient_agrees_with_the_analytic_model_zone_by_zone(cal, catalogue, name, size, material):
    """Off-centre zones (the laser lands on the spot patch) and the centre
    one, a Lambertian object and the retroreflective BSDF plugin."""
    zones = tuple(zone_footprints(cal, 3)[z] for z in CORNER_CENTRE_EDGE)
    twin = twin_scene(cal, object_mesh(catalogue[name], size), SETTINGS, AXIS, relays=zones, film=8, material=material)
    mt, an = mitransient(twin, 4000), AnalyticRenderer(twin, 60)
    for location in (0, 99):
        m, a = mt.render(location), an.render(location)
        assert m.shape == a.shape == (len(zones), 8, 8, geo.N_BINS)
        for z in range(len(zones)):
            m1, a1 = m[z].mean(axis=(0, 1)), a[z].mean(axis=(0, 1))
            assert np.corrcoef(m1, a1)[0, 1] >= 0.99, (location, z)
            # same units: the scale factor is 1 (not fitted)
            assert a1.sum() / m1.sum() == pytest.approx(1.0, abs=0.03), (location, z)
            assert np.linalg.norm(a1 - m1) / np.linalg.norm(m1) < 0.03, (location, z)
        # per pixel too: the films are laid out alike
        assert np.corrcoef(m.sum(-1).ravel(), a.sum(-1).ravel())[0, 1] > 0.99


def test_retroreflective_lobe_returns_toward_the_spot(cal, catalogue):
    """A narrow lobe sends the object's light back toward the spot: the
    centre zone (around the spot) gains on a corner zone against the Lambertian plate."""
    zones = tuple(zone_footprints(cal, 3)[z] for z in (0, 4))
    mesh = object_mesh(catalogue["square"], "8inch")
    lam = AnalyticRenderer(twin_scene(cal, mesh, SETTINGS, AXIS, relays=zones, film=4, material=Material("lambertian", 0.5)), 30).render(55)
    rr = AnalyticRenderer(twin_scene(cal, mesh, SETTINGS, AXIS, relays=zones, film=4, material=Material("retroreflective", 0.5, 5.0, 0.1)), 30).render(55)
    ratio = lambda h: h[1].sum() / h[0].sum()  # noqa: E731
    assert ratio(rr) > 1.5 * ratio(lam)


def _sum_of_spots(twin, samples, location, points, solid):
    """The flood's render as the sum of single-spot renders at `points` (M,
    3), each lit by intensity x solid angle `solid` (M,) sr (a spot's render
    is per unit intensity: its weight is solid r^2 / cos)."""
    rel = points - twin.sensor
    r = np.linalg.norm(rel, axis=1)
    weights = solid * r**3 / np.abs(rel @ twin.relays[0].normal)
    out = 0
    for p, w in zip(points, weights):
        out = out + w * AnalyticRenderer(dataclasses.replace(twin, flood=None, spot=p), samples).render(location)
    return out


@pytest.mark.parametrize("location", [9, 55])
def test_flood_is_the_sum_of_its_spots_for_a_lambertian_plate(cal, catalogue, location):
    """Light transport is linear: the flood's render of a Lambertian plate
    is the sum of spot renders at its lit points (the flood lobe's grid
    and the core's spot), each weighted by the light the emission sends it. Its energy exactly; its shape, seen
    through the sensor's pulse (the calibration's starting one), within 5 %
    in every zone: the first leg's spread, binned once per location
    (twin.analytic), leaves up to 11 % before the pulse at location 9, the
    plate nearest the wall."""
    twin = twin_scene(cal, object_mesh(catalogue["A"], "8inch"), FLOOD, AXIS, film=4, material=Material("lambertian", 0.5))
    flood = AnalyticRenderer(twin, 20).render(location).mean(axis=(1, 2))
    spots = _sum_of_spots(twin, 20, location, *twin.flood.lit()).mean(axis=(1, 2))
    np.testing.assert_allclose(flood.sum(axis=1), spots.sum(axis=1), rtol=1e-9)
    k = pulse.kernel(Pulse(1.0, 1.0), 0.0)
    seen, truth = pulse.convolve(flood, k), pulse.convolve(spots, k)
    assert (np.linalg.norm(seen - truth, axis=1) / np.linalg.norm(truth, axis=1)).max() < 0.05


def test_flood_retroreflection_is_the_narrow_lobe_limit_of_its_spots(cal, catalogue):
    """Sheeting with no diffuse part under a flood over a patch 1.6x the
    centre zone's footprint: the narrow-lobe limit the renderer takes agrees
    with the sum of spot renders, 1 cm apart, of a 2 deg lobe (its footprint
    on the wall ~3 cm across) in the zone's energy and shape."""
    centre = zone_footprints(cal, 3)[4]
    lit = dataclasses.replace(centre, size=(1.6 * centre.size[0], 1.6 * centre.size[1]))
    n_u, n_v = (int(round(s / 0.01)) for s in lit.size)
    t_u, t_v = (np.arange(n_u) + 0.5) / n_u - 0.5, (np.arange(n_v) + 0.5) / n_v - 0.5
    points = (lit.centre + t_u[None, :, None] * lit.size[0] * lit.u + t_v[:, None, None] * lit.size[1] * lit.v).reshape(-1, 3)
    areas = np.full(len(points), lit.size[0] * lit.size[1] / len(points))
    twin = twin_scene(
        cal, object_mesh(catalogue["square"], "8inch"), FLOOD, AXIS, relays=(centre,), film=3, material=Material("retroreflective", 0.5, 2.0, 0.0)
    )
    lit_patch = Flood(Emission((26.0, 20.5)), points, areas, cal.sensor_position, cal.sensor_rotation, laser_spot(cal), cal.wall.normal)
    twin = dataclasses.replace(twin, flood=lit_patch)
    flood = AnalyticRenderer(twin, 12).render(55).mean(axis=(0, 1, 2))
    spots = _sum_of_spots(twin, 12, 55, *lit_patch.lit()).mean(axis=(0, 1, 2))
    assert flood.sum() == pytest.approx(spots.sum(), rel=0.05)
    assert np.linalg.norm(flood - spots) / np.linalg.norm(spots) < 0.15


def test_under_the_flood_every_zone_gets_its_own_retroreflected_return(cal, catalogue):
    """Under the spot a corner zone, away from it, sees only the sheeting's
    diffuse part (a 10 % share: its return ~0.16x the Lambertian plate's);
    under the flood its own footprint is lit and the lobe sends that light
    back to it (~2.8x): more than ten times the spot's share."""
    corner = (zone_footprints(cal, 3)[0],)
    mesh = object_mesh(catalogue["square"], "8inch")

    def rr_over_lambertian(settings):
        lam = AnalyticRenderer(twin_scene(cal, mesh, settings, AXIS, relays=corner, film=4, material=Material("lambertian", 0.5)), 30).render(55)
        rr = AnalyticRenderer(twin_scene(cal, mesh, settings, AXIS, relays=corner, film=4, material=Material("retroreflective", 0.5, 5.0, 0.1)), 30).render(55)
        return rr.sum() / lam.sum()

    assert rr_over_lambertian(SETTINGS) < 0.3
    assert rr_over_lambertian(FLOOD) > 10 * rr_over_lambertian(SETTINGS)


def test_mitransient_refuses_the_flood(cal, catalogue):
    from denali_pipe.twin.mitransient import MitransientRenderer

    twin = twin_scene(cal, object_mesh(catalogue["A"], "4inch"), FLOOD, AXIS)
    with pytest.raises(ValueError, match="illumination: spot"):
        MitransientRenderer(twin, 16, 3, 1)


def test_tent_filter_keeps_the_mass_and_the_mean_path(cal, catalogue):
    twin = twin_scene(cal, object_mesh(catalogue["A"], "8inch"), SETTINGS, AXIS)
    box, tent = AnalyticRenderer(twin, 30, "box").render(55), AnalyticRenderer(twin, 30, "tent").render(55)
    b = np.arange(geo.N_BINS) + 0.5
    assert tent.sum() == pytest.approx(box.sum(), rel=1e-9)
    mean = lambda h: (h.sum(axis=(0, 1, 2)) * b).sum() / h.sum()  # noqa: E731
    assert mean(tent) == pytest.approx(mean(box), abs=0.05)


@pytest.mark.parametrize("axis", [AXIS, AXIS_93], ids=["78ps", "93ps"])
def test_arrival_bin_matches_the_geometric_path(cal, catalogue, axis):
    """The first non-empty bin is where the shortest laser -> spot -> object ->
    footprint -> sensor path lands on the twin's time axis, for both renderers."""
    twin = twin_scene(cal, object_mesh(catalogue["square"], "4inch"), SETTINGS, axis)
    pts, _ = front_samples(twin.mesh, 0.001)
    twin = twin_scene(cal, twin.mesh, SETTINGS, axis, relays=(zone_footprints(cal, 3)[4],))
    x = pixel_centres(twin.relays[0], twin.film).reshape(-1, 3)
    for location in (0, 55):
        o = twin.poses[location].apply(pts)
        opl = (
            np.linalg.norm(twin.spot - twin.sensor) + np.linalg.norm(o - twin.spot, axis=1)[None, :]
            + np.linalg.norm(x[:, None] - o[None], axis=-1) + np.linalg.norm(x - twin.sensor, axis=1)[:, None]
        )  # fmt: skip
        first, last = axis.opl_to_bin(opl.min()), axis.opl_to_bin(opl.max())
        for h in (mitransient(twin, 2000).render(location), AnalyticRenderer(twin, 60).render(location)):
            bins = np.flatnonzero(h.mean(axis=(0, 1, 2)) > 0)
            assert abs(bins[0] - np.floor(first)) <= 1 and abs(bins[-1] - np.floor(last)) <= 1, (location, bins[[0, -1]], first, last)


def test_table_scene_subtracts_the_table_and_keeps_the_object(cal, catalogue):
    """With table tops at depth 3 the object's three-bounce return is
    unchanged (nothing occludes it): the table-safe sampling and the
    wall-and-table subtraction must give the analytic model back."""
    centre = (zone_footprints(cal, 3)[4],)
    twin = twin_scene(cal, object_mesh(catalogue["square"], "8inch"), {**SETTINGS, "table": True}, AXIS, relays=centre)
    m = mitransient(twin, 8000).render(55).mean(axis=(0, 1, 2))
    a = AnalyticRenderer(twin_scene(cal, twin.mesh, SETTINGS, AXIS, relays=centre), 60).render(55).mean(axis=(0, 1, 2))
    assert np.corrcoef(m, a)[0, 1] > 0.99
    assert m.sum() / a.sum() == pytest.approx(1.0, abs=0.03)
    # the object's share of the samples: ~1 % noise here, ~6 % with mitransient's area-proportional choice
    assert np.linalg.norm(m - a) / np.linalg.norm(a) < 0.03


def test_analytic_refuses_a_table(cal, catalogue):
    twin = twin_scene(cal, object_mesh(catalogue["square"], "8inch"), {**SETTINGS, "table": True}, AXIS)
    with pytest.raises(ValueError, match="table"):
        AnalyticRenderer(twin, 60)


def test_render_job_writes_the_twin_store(scene_json, catalogue, tmp_path):
    out = tmp_path / "circle_8inch.zarr"
    settings = {**SETTINGS, "footprint": {"film": 3, "scale": 1.0}, "analytic": {"samples": 30}}
    render_twin(catalogue["circle"], "8inch", scene_json, {"seed": 7, "resolutions": ["3x3", "8x8"], "twin": settings}, AXIS, out)
    t = read_twin(out)
    assert t.locations.tolist() == list(LOCATIONS)
    assert t.histograms["3x3"].shape == (len(LOCATIONS), 3, 3, geo.N_BINS) and t.histograms["3x3"].dtype == np.float32
    assert t.histograms["8x8"].shape == (len(LOCATIONS), 8, 8, geo.N_BINS)
    assert (t.histograms["3x3"].sum(axis=-1) > 0).all()
    assert t.attrs["renderer"] == "analytic" and t.attrs["object"]["name"] == "circle" and t.attrs["size"] == "8inch"
    assert t.attrs["bin_width_opl"] == AXIS.bin_width_opl and t.attrs["start_opl"] == AXIS.start_opl
    assert len(t.attrs["footprints"]["8x8"]) == 64 and t.attrs["calibration"] is None
    # nearer the wall and the footprint: an earlier return
    assert np.argmax(t.histogram(9)[1, 1]) < np.argmax(t.histogram(99)[1, 1])
    # the 8x8 zones of the 3x3 centre zone's patch see about what it sees (a zone of 8x8 is ~(3/8)^2 of its area)
    assert t.histogram(55, "8x8")[3:5, 3:5].sum(axis=-1).mean() == pytest.approx(t.histogram(55)[1, 1].sum(), rel=0.5)
    with pytest.raises(KeyError, match="no location 3"):
        t.histogram(3)
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())
    assert t.attrs["illumination"] == "spot" and t.attrs["emission"] is None


def test_a_flood_twin_store_says_how_it_was_lit(scene_json, catalogue, tmp_path):
    out = tmp_path / "circle_8inch.zarr"
    settings = {**FLOOD, "footprint": {"film": 2, "scale": 1.0}, "analytic": {"samples": 20}}
    render_twin(catalogue["circle"], "8inch", scene_json, {"seed": 7, "resolutions": ["3x3"], "twin": settings}, AXIS, out)
    t = read_twin(out)
    assert t.attrs["illumination"] == "flood"
    assert t.attrs["emission"] == {"hwhm_deg": [26.0, 20.5], "core_share": 0.5, "core_hwhm_deg": 5.0}
    assert (t.histograms["3x3"].sum(axis=-1) > 0).all()


def test_version_1_twin_store_is_refused(tmp_path):
    import zarr

    path = tmp_path / "old.zarr"
    zarr.open_group(path, mode="w", zarr_format=3).attrs.update({"denali_twin": 1})
    with pytest.raises(ValueError, match="version 1 twin store.*rerender"):
        read_twin(path)


def test_render_verb(scene_json, catalogue, tmp_path, caplog):
    out = tmp_path / "A_4inch.zarr"
    cfg = {
        "seed": 1,
        "resolutions": ["3x3"],
        "twin": {**SETTINGS, "renderer": "mitransient", "footprint": {"film": 2, "scale": 1.0}, "mitransient": {**SETTINGS["mitransient"], "spp": 200}},
    }
    args = ["twin", str(scene_json), "--object", json.dumps(catalogue["A"].to_dict()), "--size", "4inch", "--config", json.dumps(cfg), "--out", str(out)]
    args += ["--time-axis", json.dumps({"bin_width_ps": AXIS.bin_width_ps, "zero_bin": AXIS.zero_bin})]
    assert main(args) == 0
    assert read_twin(out).attrs["renderer"] == "mitransient"
    args[args.index("--config") + 1] = json.dumps({"seed": 1})
    assert main(args) == 1
    assert "lacks the keys ['resolutions', 'twin']" in caplog.text


def test_rgb_view_reproduces_the_calibrated_camera(mi, cal, catalogue):
    """Tags in the Mitsuba render of the tracking camera's view are decoded
    with their ids where the calibrated camera projects them."""
    import cv2
    from pyapriltags import Detector

    from denali_pipe.twin.scene import render_rgb, rgb_scene

    camera = cal.tracking_camera.scaled(0.5)
    twin = twin_scene(cal, object_mesh(catalogue["A"], "8inch"), SETTINGS, AXIS)
    img = render_rgb(mi, rgb_scene(mi, cal, twin, 55, camera, 64), seed=3)
    assert img.shape == (camera.height, camera.width, 3) and img.dtype == np.uint8
    tags = {**cal.tags, geo.OBJECT_TAG_ID: cal.tag1_poses[55]}
    found = Detector(families="tag36h11").detect(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY))
    assert len(found) >= 3
    for d in found:
        expected = camera.project(tags[d.tag_id].t)[0]
        assert np.linalg.norm(d.center - 0.5 - expected) < 1.0, d.tag_id  # AprilTag pixel centres sit at +0.5
