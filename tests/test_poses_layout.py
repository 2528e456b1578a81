"""The static layout fit (`poses/layout.py`) on exact corners: a rig that is
not our drawing is recovered, the world frame is tag 14's, a tag whose
corners are wrong is dropped, and a set without tag 14 has no layout."""

from __future__ import annotations

import cv2
import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import Pose, rot_x, rot_y, rot_z
from denali_pipe.poses.layout import GROUPS, solve_layout

CAM = geo.TRACKING_CAMERA.scaled(0.5)


def _turn(axis: np.ndarray, deg: float) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(axis, float) * np.radians(deg))[0]


def _off_drawing() -> dict[int, Pose]:
    """A rig like a release's: tags off the grid by up to 2 cm and turned in
    their plane by up to 1.5 deg, table 15 higher and tilted, the wall and
    tag 0 tilted; table 14 stays the world's z = 0 with tag 14 at the origin."""
    rng = np.random.default_rng(0)
    surfaces = {"table15": (rot_x(-0.5) @ rot_y(0.2), [0, 0, 0.012]), "wall": (rot_x(2.0) @ rot_z(0.3), [0, 0.004, 0]), "sensor": (rot_x(4.0), [0.002, 0, 0])}
    out = {}
    for g, ids in GROUPS.items():
        R, shift = surfaces.get(g, (np.eye(3), [0, 0, 0]))
        about = np.mean([geo.STATIC_TAGS[i].t for i in ids], axis=0)
        for i in ids:
            d = geo.STATIC_TAGS[i]
            p = Pose(R @ d.R, R @ (d.t - about) + about + shift)
            if i != geo.WORLD_ORIGIN_TAG_ID:
                n = p.R[:, 2]
                slide = rng.uniform(-0.02, 0.02, 3)
                p = Pose(_turn(n, rng.uniform(-1.5, 1.5)) @ p.R, p.t + slide - (slide @ n) * n)
            out[i] = p
    return out


def _corners(tags: dict[int, Pose]) -> dict[int, np.ndarray]:
    return {i: CAM.project(p.apply(geo.tag_corners_local()))[0] for i, p in tags.items()}


def test_a_rig_off_the_drawing_is_recovered():
    truth = _off_drawing()
    assert max(np.linalg.norm(truth[i].t - geo.STATIC_TAGS[i].t) for i in truth) > 0.015
    camera, tags, rms = solve_layout(_corners(truth), CAM.K)
    for i, p in truth.items():
        np.testing.assert_allclose(tags[i].t, p.t, atol=1e-6, err_msg=f"tag {i}")
        np.testing.assert_allclose(tags[i].R, p.R, atol=1e-6, err_msg=f"tag {i}")
    np.testing.assert_allclose(camera.camera_centre, CAM.position, atol=1e-6)
    assert max(rms.values()) < 1e-6 and camera.tag_ids == tuple(sorted(truth))


def test_world_frame_is_tag_14s():
    """Tag 14 fixes the gauge: it comes out at the origin, face up, and tags 10 and 12 on z = 0."""
    _, tags, _ = solve_layout(_corners(dict(geo.STATIC_TAGS)), CAM.K)
    np.testing.assert_allclose(tags[14].t, 0, atol=1e-12)
    np.testing.assert_allclose(tags[14].R, geo.FACE_UP, atol=1e-12)
    for i in geo.TABLE_TAGS[14]:
        assert abs(tags[i].t[2]) < 1e-12 and np.allclose(tags[i].R[:, 2], [0, 0, -1])


def test_a_tag_with_wrong_corners_is_dropped(caplog):
    corners = _corners(dict(geo.STATIC_TAGS))
    corners[7] = corners[7] + [[3.0, 0], [0, 0], [0, 0], [0, -2.0]]  # not a square in any pose
    camera, tags, _ = solve_layout(corners, CAM.K)
    assert 7 not in tags and 7 not in camera.tag_ids and "static tag 7 dropped" in caplog.text
    for i, p in tags.items():
        np.testing.assert_allclose(p.t, geo.STATIC_TAGS[i].t, atol=1e-6)


def test_no_tag_14_no_layout():
    corners = _corners(dict(geo.STATIC_TAGS))
    del corners[14]
    assert solve_layout(corners, CAM.K) is None
