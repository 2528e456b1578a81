import json

import numpy as np
import pytest
from conftest import ASSETS

from denali_pipe.core import geometry as geo

# tag1_positions.json (the release's labels) sits at a constant offset from the
# tag-1 centres that poses.json and the digital twin use (REFERENCE Part 1 §7.1).
TAG1_POSITIONS_OFFSET = np.array([0.0384, 0.0284, 0.0045])


def test_object_distance_from_wall():
    d = geo.wall_distance(np.array([geo.object_pose(k).t for k in range(geo.N_LOCATIONS)]))
    assert d.min() == pytest.approx(0.29, abs=0.01) and d.max() == pytest.approx(0.62, abs=0.01)
    assert np.all((d >= 0.28) & (d <= 0.63))


def test_serpentine_grid_order():
    row, col = geo.gantry_row_col(np.arange(100))
    assert row.tolist() == np.repeat(np.arange(10), 10).tolist()
    assert col[:10].tolist() == list(range(10)) and col[10:20].tolist() == list(range(9, -1, -1))
    p = geo.tag1_position(np.arange(100))
    # location 0 is nearest the wall and at the largest x
    assert p[0, 0] == p[:, 0].max() and p[0, 1] == p[:, 1].max()
    # consecutive locations are one step apart (the serpentine never jumps)
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    assert np.allclose(steps, 0.0365)
    # even rows move toward -x, odd rows toward +x
    assert np.all(np.diff(p[0:10, 0]) < 0) and np.all(np.diff(p[10:20, 0]) > 0)


@pytest.mark.skipif(not (ASSETS / "tag1_positions.json").exists(), reason="denali-assets not present")
def test_grid_matches_release_labels():
    labels = json.loads((ASSETS / "tag1_positions.json").read_text())
    real = np.array([labels[f"frame{k}_tag1"] for k in range(100)]) - TAG1_POSITIONS_OFFSET
    err = geo.tag1_position(np.arange(100)) - real
    # In x and y (the regression targets) the regular grid matches the measured
    # labels to 5 mm RMS per axis. Single locations deviate by up to 1-2 cm in a
    # bowl along the fast axis, in y and z together: the reference tracking's
    # single-tag line-of-sight bias (REFERENCE Part 3), not gantry motion.
    assert np.sqrt((err[:, :2] ** 2).mean(0)).max() < 0.005
    assert np.abs(err.mean(0)).max() < 0.005


@pytest.mark.skipif(not (ASSETS / "tag1_positions.json").exists(), reason="denali-assets not present")
def test_the_release_labels_lie_in_the_workspace_only_with_its_margin():
    labels = json.loads((ASSETS / "tag1_positions.json").read_text())
    real = np.array([labels[f"frame{k}_tag1"] for k in range(100)])[:, :2] - TAG1_POSITIONS_OFFSET[:2]
    assert geo.outside_workspace(real).max() == 0.0
    # without it, the reference tracking's bias puts some a centimetre beyond the design grid's box
    assert 0.005 < geo.outside_workspace(real, margin=0.0).max() < geo.WORKSPACE_MARGIN


def test_outside_workspace_is_the_distance_beyond_the_box():
    lo, hi = geo.gantry_workspace()
    centre = (lo + hi) / 2
    assert hi - lo == pytest.approx(np.full(2, 9 * 0.0365 + 2 * geo.WORKSPACE_MARGIN))
    points = np.array([centre, lo, [hi[0] + 0.3, centre[1]], [lo[0] - 0.03, hi[1] + 0.04]])
    assert geo.outside_workspace(points) == pytest.approx([0.0, 0.0, 0.3, 0.05])
    assert geo.outside_workspace(points.reshape(2, 2, 2)).shape == (2, 2)


def test_object_mount_offset():
    for k in (0, 55, 99):
        d = geo.object_pose(k).t - geo.tag1_position(k)
        assert d[1] == pytest.approx(0.040, abs=0.002) and d[2] == pytest.approx(-0.005, abs=0.003)
        # local x -> +x, local y -> up, local z -> away from the wall
        R = geo.object_pose(k).R
        assert R[:, 0] @ [1, 0, 0] > 0.99 and R[:, 1] @ [0, 0, 1] > 0.99 and R[:, 2] @ [0, -1, 0] > 0.99


def test_cameras_see_the_scene():
    uv, z = geo.TRACKING_CAMERA.project(np.array([p.t for p in geo.STATIC_TAGS.values()]))
    assert np.all(z > 0)
    assert np.all((uv >= 0) & (uv < [geo.TRACKING_CAMERA.width, geo.TRACKING_CAMERA.height]))
    uv, z = geo.TRACKING_CAMERA.project(geo.tag1_position(np.arange(100)))
    assert np.all(z > 0) and np.all((uv >= 0) & (uv < [1280, 720]))
    # the co-located camera looks at the wall, 51 deg-down tracking camera looks at the table
    assert geo.COLOCATED_CAMERA.project(geo.WALL.centre)[1] > 0
    fwd = geo.TRACKING_CAMERA.R_wc[2]
    assert np.degrees(np.arcsin(-fwd[2])) == pytest.approx(51.4, abs=0.3)


def test_camera_scaling_keeps_projection():
    p = geo.tag1_position(42)
    uv, _ = geo.TRACKING_CAMERA.project(p)
    uv2, _ = geo.TRACKING_CAMERA.scaled(0.5).project(p)
    assert np.allclose((uv + 0.5) * 0.5 - 0.5, uv2)


def test_rays_match_projection():
    cam = geo.COLOCATED_CAMERA.scaled(0.25)
    rays = cam.rays()
    pts = cam.position + 2.0 * rays[[0, 50, 119], [0, 100, 211]]
    uv, _ = cam.project(pts)
    assert np.allclose(uv, [[0, 0], [100, 50], [211, 119]], atol=1e-6)


@pytest.mark.parametrize("res", ["3x3", "8x8"])
def test_zones_tile_the_wall(res):
    n = geo.RESOLUTIONS[res]
    dirs, omega = geo.zone_directions(n, 2)
    assert dirs.shape == (n, n, 2, 2, 3) and np.allclose(np.linalg.norm(dirs, axis=-1), 1)
    q = geo.intersect_plane(geo.SENSOR_POSITION, dirs, geo.WALL)
    lo, hi = geo.WALL.corners().min(0), geo.WALL.corners().max(0)
    assert np.all((q[..., [0, 2]] > lo[[0, 2]]) & (q[..., [0, 2]] < hi[[0, 2]]))
    # row 0 looks up; column 0 looks to the sensor's right (toward +x): the
    # captures store the columns mirrored
    assert q[0, :, ..., 2].mean() > q[-1, :, ..., 2].mean()
    assert q[:, 0, ..., 0].mean() > q[:, -1, ..., 0].mean()
    # total solid angle of the 52 x 41 deg field of view
    th, tv = np.tan(np.radians(26)), np.tan(np.radians(20.5))
    exact = 4 * np.arcsin(np.sin(np.arctan(th)) * np.sin(np.arctan(tv)))
    assert omega.sum() == pytest.approx(exact, rel=0.01)


def test_select_locations():
    assert geo.select_locations(100).tolist() == list(range(100))
    sel = geo.select_locations(12)
    assert len(sel) == 12 and sel[0] == 0 and sel[-1] == 99
    with pytest.raises(ValueError):
        geo.select_locations(0)


def test_the_paper_time_axis_is_the_reference_twins_exactly():
    """3/128 m of optical path a bin (78.2 ps), OPL 0 at bin 0's left edge: the
    old module constants, to the last bit (the workflow's outputs depend on them)."""
    axis = geo.PAPER_TIME_AXIS
    assert axis.bin_width_opl == 3.0 / 128 and axis.bin_width_opl * geo.N_BINS == 3.0
    assert axis.bin_width_ps == 3.0 / 128 / geo.SPEED_OF_LIGHT * 1e12 == pytest.approx(78.18, abs=0.005)
    assert axis.start_opl == 0.0 and str(axis.start_opl) == "0.0"  # not -0.0: it is written to JSON
    opl = np.linspace(-0.5, 3.5, 101)
    assert np.array_equal(axis.opl_to_bin(opl), (opl - 0.0) / (3.0 / 128))
    assert axis.opl_to_bin(10 * 3.0 / 128) == 10


def test_a_time_axis_puts_zero_path_at_its_zero_bins_centre():
    axis = geo.TimeAxis(bin_width_ps=93.0, zero_bin=16.0)
    assert axis.bin_width_opl == pytest.approx(93e-12 * geo.SPEED_OF_LIGHT)
    assert axis.opl_to_bin(0.0) == pytest.approx(16.5)  # bin b covers [b, b + 1): the centre of bin 16
    assert axis.start_opl == pytest.approx(-16.5 * axis.bin_width_opl)
    assert axis.opl_to_bin(axis.start_opl) == pytest.approx(0.0)
    # bin b covers OPL [(b - 0.5 - zero_bin) w, (b + 0.5 - zero_bin) w)
    b = np.arange(geo.N_BINS)
    w = axis.bin_width_opl
    assert np.allclose(axis.opl_to_bin((b - 0.5 - axis.zero_bin) * w), b)
    assert np.allclose(axis.opl_to_bin((b + 0.5 - axis.zero_bin) * w), b + 1)
    # round trip: a bin coordinate to OPL and back
    x = np.linspace(-3.0, 130.0, 57)
    assert np.allclose(axis.opl_to_bin(axis.start_opl + x * w), x)


def test_a_time_axis_comes_from_its_config_block():
    assert geo.TimeAxis.from_config({"bin_width_ps": 93, "zero_bin": 13}) == geo.TimeAxis(93.0, 13.0)
    with pytest.raises(KeyError):
        geo.TimeAxis.from_config({"bin_width_ps": 93.0})


def test_centre_zone_is_the_middle_of_the_grid():
    assert geo.centre_zone("3x3") == (1, 1)
    assert geo.centre_zone("8x8") == (4, 4)  # the lower right of the middle four
