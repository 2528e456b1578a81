"""PnP and geometry helpers (`poses/pnp.py`): intrinsics and their fallback,
board PnP on exact and corrupted corners, the IPPE ambiguity, rays and planes."""

from __future__ import annotations

import numpy as np
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.poses.pnp import (
    REAL_TRACKING_INTRINSICS,
    Fit,
    Intrinsics,
    choose_by_normal,
    intersect_plane,
    mean_rotation,
    pixel_ray,
    rigid_fit,
    solve_board,
    solve_tag,
    tracking_intrinsics,
)

CAM = geo.TRACKING_CAMERA.scaled(0.5)
TABLE = {i: geo.STATIC_TAGS[i] for i in geo.TABLE_TAG_IDS}


def _corners(cam: geo.Camera, tags: dict[int, geo.Pose]) -> dict[int, np.ndarray]:
    return {t: cam.project(p.apply(geo.tag_corners_local()))[0] for t, p in tags.items()}


def _intr(cam: geo.Camera) -> Intrinsics:
    return cam.intrinsics


def test_intrinsics_from_metadata_and_fallback():
    md = {"tracking_camera": _intr(CAM).to_dict()}
    intr, src = tracking_intrinsics(md, (CAM.height, CAM.width, 3))
    assert src == "metadata" and intr == _intr(CAM)
    # no record (the public release): the real camera's, scaled like Camera.scaled
    for scale in (1.0, 0.5, 0.35):
        cam = geo.TRACKING_CAMERA.scaled(scale)
        intr, src = tracking_intrinsics({}, (cam.height, cam.width))
        assert src == "fallback"
        np.testing.assert_allclose([intr.fx, intr.fy, intr.cx, intr.cy], [cam.fx, cam.fy, cam.cx, cam.cy], rtol=2e-3)
    assert tracking_intrinsics(None, (720, 1280))[0] == REAL_TRACKING_INTRINSICS
    assert (REAL_TRACKING_INTRINSICS.fx, REAL_TRACKING_INTRINSICS.cy) == (923.57, 365.96)
    # a record for another size is rescaled to the frame
    intr, _ = tracking_intrinsics({"tracking_camera": REAL_TRACKING_INTRINSICS.to_dict()}, (360, 640))
    assert intr.width == 640 and intr.fx == pytest.approx(923.57 / 2)


def test_board_recovers_the_camera_from_exact_corners():
    fit = solve_board(_corners(CAM, TABLE), TABLE, CAM.K)
    assert fit is not None and fit.rms_px < 1e-6 and fit.tag_ids == tuple(sorted(TABLE))
    np.testing.assert_allclose(fit.camera_centre, CAM.position, atol=1e-7)
    np.testing.assert_allclose(fit.R, CAM.R_wc, atol=1e-8)


def test_board_drops_a_corrupted_tag_and_needs_two():
    c = _corners(CAM, TABLE)
    c[13] = c[13] + [4.0, -3.0]  # a tag misplaced by 5 px (e.g. half occluded)
    fit = solve_board(c, TABLE, CAM.K)
    assert 13 not in fit.tag_ids and len(fit.tag_ids) == 5
    np.testing.assert_allclose(fit.camera_centre, CAM.position, atol=1e-6)
    assert solve_board({14: c[14]}, TABLE, CAM.K) is None
    assert solve_board({}, TABLE, CAM.K) is None
    assert solve_board({14: c[14], 15: c[15]}, TABLE, CAM.K) is not None


def test_ippe_ambiguity_resolved_by_the_known_normal():
    p = geo.STATIC_TAGS[geo.SENSOR_TAG_ID]
    fits = solve_tag(_corners(CAM, {0: p})[0], CAM.K)
    assert len(fits) == 2 and fits[0].rms_px <= fits[1].rms_px
    R_cw = CAM.R_wc.T
    k, angle = choose_by_normal(fits, R_cw, p.R[:, 2])
    assert angle < 1.0
    np.testing.assert_allclose(R_cw @ fits[k].R, p.R, atol=1e-6)
    np.testing.assert_allclose(R_cw @ fits[k].t + CAM.position, p.t, atol=1e-6)
    # the better-reprojecting solution is the wrong one: the normal still decides
    flipped = [fits[1 - k], fits[k]]
    assert choose_by_normal(flipped, R_cw, p.R[:, 2])[0] == 1
    assert solve_tag(np.zeros((4, 2)), CAM.K) == []  # degenerate corners: no solution, no crash


def test_rays_planes_and_fits():
    p = geo.STATIC_TAGS[15].t
    uv, _ = CAM.project(p)
    d = pixel_ray(uv, CAM.K, CAM.R_wc.T)
    np.testing.assert_allclose(intersect_plane(CAM.position, d, np.zeros(3), [0, 0, 1.0]), p, atol=1e-9)
    assert intersect_plane(CAM.position, d, np.array([0, 0, 2.0]), [0, 0, 1.0]) is None  # plane behind
    assert intersect_plane(CAM.position, np.array([1.0, 0, 0]), np.zeros(3), [0, 0, 1.0]) is None  # parallel
    R = geo.rot_z(20) @ geo.rot_x(5)
    src = np.random.default_rng(0).standard_normal((5, 3))
    Rf, tf = rigid_fit(src, src @ R.T + [1, 2, 3])
    np.testing.assert_allclose(Rf, R, atol=1e-12)
    np.testing.assert_allclose(tf, [1, 2, 3], atol=1e-12)
    np.testing.assert_allclose(mean_rotation(np.stack([R, R])), R, atol=1e-12)
    assert Fit(np.eye(3), np.array([0, 0, 1.0]), 0.0).camera_centre.tolist() == [0, 0, -1.0]
