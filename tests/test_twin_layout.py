"""The twin's scene as arrays: calibration reader, footprint, laser spot, object face."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from conftest import REPO

from denali_pipe.core import geometry as geo
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import BOTTOM_Y, load_catalogue
from denali_pipe.twin.layout import (
    Emission,
    Material,
    ZoneGeometry,
    flood,
    front_face,
    laser_spot,
    load_calibration,
    material_of,
    nominal_scene,
    pixel_centres,
    pixels_inside,
    three_bounce_lead,
    twin_scene,
    zone_footprint,
    zone_footprints,
)

LOCATIONS = (0, 45, 99)
AXIS = geo.PAPER_TIME_AXIS


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    path = tmp_path_factory.mktemp("scene") / "scene.json"
    path.write_text(json.dumps(nominal_scene(LOCATIONS)))
    return load_calibration(path)


def test_calibration_reads_the_design_back(cal):
    assert cal.locations == list(LOCATIONS)
    assert np.allclose(cal.wall.centre, geo.WALL.centre) and np.allclose(cal.wall.normal, [0, -1, 0])
    assert np.allclose(cal.sensor_position, geo.SENSOR_POSITION, atol=1e-9)
    assert np.allclose(cal.sensor_rotation[:, 2], geo.SENSOR_FORWARD, atol=1e-9)
    assert np.allclose(cal.object_poses[45].t, geo.object_pose(45).t)
    assert len(cal.tables) == 2


@pytest.mark.parametrize("key", ["wall", "sensor", "locations"])
def test_missing_section_names_file_and_key(tmp_path, key):
    doc = nominal_scene(LOCATIONS)
    doc[key] = None
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as e:
        load_calibration(path)
    assert str(path) in str(e.value) and repr(key) in str(e.value)


def test_footprint_is_the_centre_zone_on_the_wall(cal):
    fp = zone_footprint(cal)
    # the zone's rays as geometry.zone_directions tiles them (nominal sensor = calibrated here)
    dirs, _ = geo.zone_directions(3, 16)
    q = geo.intersect_plane(geo.SENSOR_POSITION, dirs[1, 1].reshape(-1, 3), geo.WALL)
    rel = q - fp.centre
    assert np.allclose(fp.centre, q.mean(axis=0), atol=0.01)
    assert abs(np.ptp(rel @ fp.u) - fp.size[0]) < 0.015 and abs(np.ptp(rel @ fp.v) - fp.size[1]) < 0.015
    assert abs((fp.centre - cal.wall.centre) @ cal.wall.normal) < 1e-9  # on the wall plane
    assert np.allclose(zone_footprint(cal, 0.5).size, np.array(fp.size) / 2)


@pytest.mark.parametrize("n", [3, 8])
def test_zone_footprints_follow_the_sensors_zone_layout(cal, n):
    """Each zone's rectangle covers the wall where geometry.zone_directions'
    rays of that zone land (row 0 at the top, column 0 at the sensor's right)."""
    fps = zone_footprints(cal, n)
    dirs, _ = geo.zone_directions(n, 8)
    for z, fp in enumerate(fps):
        r, c = divmod(z, n)
        q = geo.intersect_plane(geo.SENSOR_POSITION, dirs[r, c].reshape(-1, 3), geo.WALL)
        assert np.allclose(fp.centre, q.mean(axis=0), atol=0.01 * 3 / n + 0.002)
        rel = q - fp.centre
        assert abs(np.ptp(rel @ fp.u) * 8 / 7 - fp.size[0]) < 0.1 * fp.size[0]
    centres = np.array([fp.centre for fp in fps]).reshape(n, n, 3)
    assert (np.diff(centres[..., 2], axis=0) < 0).all()  # row 0 at the top (+z up)
    assert (np.diff(centres[..., 0], axis=1) < 0).all()  # column 0 at the sensor's right (+x): the captures' mirrored order
    if n == 3:
        assert np.allclose(zone_footprint(cal).centre, fps[4].centre) and np.allclose(zone_footprint(cal).size, fps[4].size)


def test_zone_geometry_moves_and_scales_each_zone(cal):
    g = ZoneGeometry.nominal(3)
    offsets = g.offsets.copy()
    offsets[0, 2] = (0.01, -0.02)
    scales = g.scales.copy()
    scales[2, 1] = 1.5
    moved = zone_footprints(cal, 3, ZoneGeometry(offsets, scales))
    design = zone_footprints(cal, 3)
    assert np.allclose(moved[2].centre - design[2].centre, 0.01 * cal.wall.u - 0.02 * cal.wall.v)
    assert np.allclose(moved[7].size, np.array(design[7].size) * 1.5) and np.allclose(moved[7].centre, design[7].centre)
    assert all(np.allclose(moved[z].centre, design[z].centre) for z in (0, 1, 3, 4, 5, 6, 8))
    with pytest.raises(ValueError, match="3x3 grid given for a 8x8"):
        zone_footprints(cal, 8, g)


def test_materials_from_settings():
    s = {"object_albedo": 0.5, "material": "retroreflective", "retroreflective": {"lobe_width_deg": 10.0, "diffuse_share": 0.3}}
    assert material_of(s) == Material("retroreflective", 0.5, 10.0, 0.3)
    assert material_of(s, retroreflective=False) == Material("lambertian", 0.5)  # the non-RR variants
    assert material_of({**s, "material": "lambertian"}).kind == "lambertian"
    assert material_of(s, calibrated={"lobe_width_deg": 4.0}).lobe_width_deg == 4.0
    with pytest.raises(ValueError, match="unknown twin material"):
        Material("mirror", 0.5)
    with pytest.raises(ValueError, match="lobe needs"):
        Material("retroreflective", 0.5, 0.0, 0.3)


def test_laser_spot_is_on_the_axis_inside_the_footprint(cal):
    p = laser_spot(cal)
    fp = zone_footprint(cal)
    d = p - cal.sensor_position
    assert np.allclose(d / np.linalg.norm(d), geo.SENSOR_FORWARD, atol=1e-9)
    assert pixels_inside(fp, 1, fp).all()
    rel = p - fp.centre
    assert abs(rel @ fp.u) < fp.size[0] / 2 and abs(rel @ fp.v) < fp.size[1] / 2


def test_pixel_centres_rows_up_columns_along_u(cal):
    fp = zone_footprint(cal)
    x = pixel_centres(fp, 4)
    assert x.shape == (4, 4, 3)
    assert (np.diff(x[..., 2], axis=0) > 0).all()  # rows climb (+v = +z)
    assert (np.diff(x[..., 0], axis=1) > 0).all()  # columns run along +u = +x
    assert np.allclose(x.reshape(-1, 3).mean(axis=0), fp.centre)
    whole = pixels_inside(cal.wall, 64, fp)
    assert 100 < whole.sum() < 300  # the paper's 64x64 film puts ~1/20 of its pixels in the footprint


def test_front_face_faces_the_wall(cal):
    mesh = object_mesh(load_catalogue(REPO / "config/objects.tsv")["A"], "8inch")
    v, f = front_face(mesh)
    assert f.max() == len(v) - 1
    assert np.allclose(v[:, 2], v[0, 2])  # one plane, the wall side of the plate
    pose = cal.object_poses[0]
    tri = pose.apply(v)[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (n @ cal.wall.normal < 0).all()  # winding normals face the wall (against its normal)


def test_twin_scene_takes_settings(cal):
    mesh = object_mesh(load_catalogue(REPO / "config/objects.tsv")["circle"], "4inch")
    settings = {"footprint": {"film": 8, "scale": 1.0}, "wall_albedo": 0.9, "object_albedo": 0.4, "table": True, "table_albedo": 0.3}
    tw = twin_scene(cal, mesh, settings, AXIS)
    assert tw.film == 8 and tw.object_albedo == 0.4 and len(tw.tables) == 2 and len(tw.relays) == 9
    assert tw.material == Material("lambertian", 0.4)  # no material set: the paper's
    assert twin_scene(cal, mesh, settings, AXIS, 8).film == 3 and len(twin_scene(cal, mesh, settings, AXIS, 8).relays) == 64  # same pixel pitch
    assert len(twin_scene(cal, mesh, {**settings, "table": False}, AXIS).tables) == 0


def _moved(cal, shift):
    return dataclasses.replace(cal, object_poses={k: geo.pose(p.R, p.t + shift) for k, p in cal.object_poses.items()})


def test_three_bounce_lead_is_the_least_extra_path(cal):
    size = 0.2
    lead = three_bounce_lead(cal, 3, size)
    # no return arrives before the direct one, and the zones nearer the gantry
    # (column 0, the far end of the wall) see it soonest
    assert (lead > 0).all() and (lead[:, 0] < lead[:, 1]).all() and (lead[:, 1] < lead[:, 2]).all()
    # a minimum: no sampled path in the centre zone beats it (within the grids' spacing)
    s, feet = cal.sensor_position, zone_footprints(cal, 3)
    rng = np.random.default_rng(0)

    def point(r):
        a, b = rng.uniform(-0.5, 0.5, 2)
        return r.centre + a * r.size[0] * r.u + b * r.size[1] * r.v

    nearest = 2 * min(np.linalg.norm(point(feet[4]) - s) for _ in range(2000))
    for pose in cal.object_poses.values():
        for _ in range(300):
            o = pose.apply([rng.uniform(-size / 2, size / 2), BOTTOM_Y + rng.uniform(0, size), 0.0])
            p, q = point(feet[rng.integers(9)]), point(feet[4])
            path = np.linalg.norm(p - s) + np.linalg.norm(o - p) + np.linalg.norm(q - o) + np.linalg.norm(s - q)
            assert path - nearest >= lead[1, 1] - 0.01
    # larger plates and objects nearer the wall bring the returns forward
    assert (three_bounce_lead(cal, 3, 0.1) > lead).all()
    assert (three_bounce_lead(_moved(cal, np.array([0.0, 0.05, 0.0])), 3, size) < lead).all()


def test_the_cores_spot_carries_its_intensity_over_the_wall(cal):
    """The core lights the wall as one spot of c pi w^2 / ln 2 sr: the core
    lobe's intensity x solid angle summed over the wall at 1.5 mm pixels, within 1 %."""
    lit = flood(cal, Emission((26.0, 20.5), 0.6, 3.0), 3)
    points, solid = lit.lit()
    assert np.allclose(points[-1], laser_spot(cal)) and solid[-1] == pytest.approx(lit.emission.core_solid_angle())
    fine = pixel_centres(cal.wall, 600).reshape(-1, 3)
    rel = fine - cal.sensor_position
    r = np.linalg.norm(rel, axis=1)
    dense = (lit.emission.core(*lit.angles(fine)) * np.prod(cal.wall.size) / 600**2 * np.abs(rel @ cal.wall.normal) / r**3).sum()
    assert solid[-1] == pytest.approx(dense, rel=0.01)
    # the flood's grid carries the flood lobe only
    assert solid[:-1] == pytest.approx(
        lit.emission.flood(*lit.angles(points[:-1]))
        * lit.areas
        * np.abs((points[:-1] - cal.sensor_position) @ cal.wall.normal)
        / np.linalg.norm(points[:-1] - cal.sensor_position, axis=1) ** 3
    )


def test_a_film_pixel_takes_the_emissions_mean_over_it(cal):
    """A 2 deg core on the centre zone's 3x3 film (pixels ~6 deg wide): each
    pixel's emission is its mean over the pixel (a 60 x 60 grid's, within
    1 %), not the value at its centre (75 % above it on the axis)."""
    lit = flood(cal, Emission((26.0, 20.5), 0.9, 2.0), 3)
    centre = zone_footprints(cal, 3)[4]
    fine = lit.intensity(pixel_centres(centre, 180)).reshape(3, 60, 3, 60).mean(axis=(1, 3))
    np.testing.assert_allclose(lit.pixel_intensity(centre, 3), fine, rtol=0.01)
    assert lit.intensity(pixel_centres(centre, 3))[1, 1] > 1.7 * fine[1, 1]


def test_only_a_core_lets_centre_over_edge_exceed_edge_over_corner(cal):
    """The zones' mean emission: a single elliptical Gaussian gives the centre
    zone over its horizontal neighbour what the top row's middle gives over
    its corner (within 4 %: the wall is flat, the profile is in angles); a
    core lifts the centre alone (the real sensor's zone means: 2.46 against
    1.38, docs/twin.md)."""
    feet = zone_footprints(cal, 3)

    def ratios(emission):
        m = np.array([flood(cal, emission, 3).pixel_intensity(r, 8).mean() for r in feet]).reshape(3, 3)
        return m[1, 1] / m[1, 2], m[0, 1] / m[0, 2]

    centre_edge, edge_corner = ratios(Emission((14.3, 6.8)))
    assert centre_edge == pytest.approx(edge_corner, rel=0.04)
    centre_edge, edge_corner = ratios(Emission((26.0, 20.5), 0.9, 3.0))
    assert centre_edge > 2 * edge_corner
