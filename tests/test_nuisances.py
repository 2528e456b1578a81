"""The campaign's nuisances: seeded, of the configured size, and where they act."""

import numpy as np
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.rig import nuisances as N
from denali_pipe.rig.frames import frame_tags


@pytest.fixture(scope="module")
def cfg(demo_config):
    return demo_config["rig"]["nuisances"]


def test_draws_are_seeded_per_set(cfg):
    a = N.draw_set(cfg, 1, "A_8inch_3x3_lighton")
    assert a == N.draw_set(cfg, 1, "A_8inch_3x3_lighton")
    assert a != N.draw_set(cfg, 1, "A_8inch_3x3_lightoff")
    assert np.array_equal(N.gantry_offset(cfg, 1, "s", 4), N.gantry_offset(cfg, 1, "s", 4))


def test_magnitudes_follow_the_config(cfg):
    sets = [N.draw_set(cfg, 7, f"set{i}") for i in range(400)]
    assert np.std([s.tilt_deg for s in sets]) == pytest.approx(cfg["object_tilt_deg"], rel=0.15)
    assert np.std([s.yaw_deg for s in sets]) == pytest.approx(cfg["object_yaw_deg"], rel=0.15)
    assert np.std([s.power_gain for s in sets]) == pytest.approx(cfg["power_drift"], rel=0.15)
    assert np.std([s.ambient_gain for s in sets]) == pytest.approx(cfg["ambient_drift"], rel=0.15)
    offsets = np.array([N.gantry_offset(cfg, 7, "s", k) for k in range(100)])
    assert np.all(offsets[:, 2] == 0)  # the carriage rides on rails
    assert offsets[:, :2].std() == pytest.approx(cfg["gantry_repeatability_m"], rel=0.2)
    shifts = [N.capture_conditions(cfg, 7, "s", k, r, sets[0], 1).time_shift_bins for k in range(50) for r in range(3)]
    assert np.std(shifts) == pytest.approx(cfg["timing_drift_bins"], rel=0.2)


def test_subcaptures_deviate_about_the_capture(cfg):
    s = N.SetNuisance(tilt_deg=0.0, yaw_deg=0.0, power_gain=1.1, ambient_gain=1.0)
    one = N.capture_conditions(cfg, 7, "s", 3, 0, s, 1)
    assert one.power_gain == (1.1,)
    caps = [N.capture_conditions(cfg, 7, "s", k, 0, s, 8) for k in range(100)]
    shifts, powers = np.array([c.time_shift_bins for c in caps]), np.array([c.power_gain for c in caps])
    assert shifts.shape == powers.shape == (100, 8)
    # the capture's own drift is shared; the subcaptures scatter about it (sd x sqrt(7/8) about their mean)
    assert shifts.mean(1).std() == pytest.approx(cfg["timing_drift_bins"], rel=0.2)
    assert (shifts - shifts.mean(1, keepdims=True)).std() == pytest.approx(cfg["subcapture_timing_bins"] * np.sqrt(7 / 8), rel=0.1)
    assert powers.mean(1) == pytest.approx(1.1)
    assert (powers / 1.1 - 1).std() == pytest.approx(cfg["subcapture_power_drift"] * np.sqrt(7 / 8), rel=0.1)


def test_mounting_turns_the_plate_about_its_mount_point():
    s = N.SetNuisance(tilt_deg=3.0, yaw_deg=-2.0, power_gain=1.0, ambient_gain=1.0)
    offset = np.array([0.001, -0.002, 0.0])
    nominal, mounted = geo.object_pose(45), s.object_pose(geo.tag1_pose(45), offset)
    assert mounted.t == pytest.approx(nominal.t + offset)
    normal_nominal, normal = nominal.R[:, 2], mounted.R[:, 2]
    angle = np.degrees(np.arccos(normal_nominal @ normal))
    assert angle == pytest.approx(np.hypot(3.0, 2.0), abs=0.1)


def test_tracking_frames_see_the_gantry_offset():
    offset = (0.002, -0.001, 0.0)
    tag1 = frame_tags(45, "tracking", offset)[geo.OBJECT_TAG_ID]
    assert tag1.t == pytest.approx(geo.tag1_pose(45).t + np.array(offset))
