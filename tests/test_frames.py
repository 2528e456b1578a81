"""Synthetic RGB-D frames: layout, determinism, exposure, and that the real
AprilTag detector finds the tags where the geometry puts them."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from denali_pipe.core import geometry as g
from denali_pipe.core.tags import tag_texture
from denali_pipe.rig.frames import frame_tags, render_frame

pyapriltags = pytest.importorskip("pyapriltags")

LOCATION = 50
CAMERAS = {"tracking": g.TRACKING_CAMERA, "colocated": g.COLOCATED_CAMERA}


@pytest.fixture(scope="module")
def detector():
    return pyapriltags.Detector(families="tag36h11", quad_decimate=1.0)


def _grey(bgr: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


def _visible(camera: g.Camera, tags: dict[int, g.Pose], margin_px: float = 3.0) -> set[int]:
    """Tags in front of the camera, facing it, whose black square projects
    inside the image with `margin_px` of white quiet zone to spare (the
    detector needs the whole border): those a detector must find."""
    out = set()
    for tid, p in tags.items():
        uv, z = camera.project(p.apply(g.tag_corners_local(g.TAG_SIZE)))
        facing = (camera.position - p.t) @ (-p.R[:, 2]) > 0
        inside = (
            (uv[:, 0] >= margin_px).all()
            and (uv[:, 0] <= camera.width - 1 - margin_px).all()
            and (uv[:, 1] >= margin_px).all()
            and (uv[:, 1] <= camera.height - 1 - margin_px).all()
        )
        if facing and (z > 0).all() and inside and not _occluded(camera, tags, tid):
            out.add(tid)
    return out


def _occluded(camera: g.Camera, tags: dict[int, g.Pose], tid: int) -> bool:
    """Whether a nearer tag's printed 8 cm square overlaps tag `tid`'s black
    square in the image (the object tag 1 hides table tags 11 or 13 from the
    tracking camera at some gantry locations)."""
    mine, z_mine = camera.project(tags[tid].apply(g.tag_corners_local(g.TAG_SIZE)))
    for other, p in tags.items():
        if other == tid:
            continue
        theirs, z = camera.project(p.apply(g.tag_corners_local(0.08)))
        if (z <= 0).any() or z.mean() >= z_mine.mean():
            continue
        area, _ = cv2.intersectConvexConvex(mine.astype(np.float32), theirs.astype(np.float32))
        if area > 0:
            return True
    return False


def _detect(detector, bgr: np.ndarray) -> dict[int, np.ndarray]:
    """tag id -> detected centre in OpenCV pixel coordinates (the AprilTag
    library puts pixel centres at +0.5)."""
    return {d.tag_id: np.asarray(d.center) - 0.5 for d in detector.detect(_grey(bgr))}


def test_tag_texture_is_the_dictionary_marker():
    img = tag_texture(7, 64)
    assert img.shape == (64, 64) and img.dtype == np.uint8
    cells = img[4::8, 4::8] > 127  # 8x8 cells: 1 black border + 6x6 data
    assert not cells[0].any() and not cells[-1].any() and not cells[:, 0].any() and not cells[:, -1].any()
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    _, found, _ = cv2.aruco.ArucoDetector(d).detectMarkers(np.pad(img, 16, constant_values=255))
    assert found is not None and found.ravel().tolist() == [7]
    assert tag_texture(7, 64) is img  # cached


def test_frame_tags():
    tags = frame_tags(LOCATION, "tracking")
    assert set(tags) == set(g.STATIC_TAGS) | {g.OBJECT_TAG_ID}
    np.testing.assert_allclose(tags[1].t, g.tag1_position(LOCATION))
    assert set(frame_tags(0, "colocated")) == set(tags)
    with pytest.raises(ValueError):
        frame_tags(0, "nope")


@pytest.mark.parametrize("name", list(CAMERAS))
@pytest.mark.parametrize("scale", [0.5, 1.0])
def test_shapes_and_dtypes(name, scale):
    cam = CAMERAS[name].scaled(scale)
    bgr, depth = render_frame(cam, frame_tags(LOCATION, name), True, np.random.default_rng(0))
    assert bgr.shape == (cam.height, cam.width, 3) and bgr.dtype == np.uint8
    assert depth.shape == (cam.height, cam.width) and depth.dtype == np.uint16
    assert cam.width == round(CAMERAS[name].width * scale)


def test_deterministic_per_seed():
    cam = g.TRACKING_CAMERA.scaled(0.5)
    tags = frame_tags(LOCATION, "tracking")
    a = render_frame(cam, tags, True, np.random.default_rng(123))
    b = render_frame(cam, tags, True, np.random.default_rng(123))
    c = render_frame(cam, tags, True, np.random.default_rng(124))
    assert a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes()
    assert a[0].tobytes() != c[0].tobytes()  # the noise really comes from the rng


@pytest.mark.parametrize("name", list(CAMERAS))
def test_exposure_lights_on_and_off(name):
    cam = CAMERAS[name].scaled(0.5)
    tags = frame_tags(LOCATION, name)
    on, d_on = render_frame(cam, tags, True, np.random.default_rng(1))
    off, d_off = render_frame(cam, tags, False, np.random.default_rng(1))
    assert 60 < _grey(on).mean() < 200
    assert _grey(off).mean() < 30  # the real capture's lights-off criterion
    assert _grey(off).std() > 0.5  # noisy, not a constant image
    # Active stereo depth ignores the room lights: same rng draws, same depth.
    assert np.array_equal(d_on, d_off)


def test_tracking_half_scale_detects_tags_at_true_centres(detector):
    cam = g.TRACKING_CAMERA.scaled(0.5)
    tags = frame_tags(LOCATION, "tracking")
    bgr, depth = render_frame(cam, tags, True, np.random.default_rng(2))
    expected = _visible(cam, tags)
    # The test must not pass by expecting nothing: the sensor tag, the object
    # tag, all wall tags and most table tags are in view of the tracking camera.
    assert {0, 1, 5, 6, 7} <= expected
    assert len(expected & set(g.TABLE_TAG_IDS)) >= 4
    found = _detect(detector, bgr)
    assert expected <= set(found), f"missing {sorted(expected - set(found))}"
    assert set(found) <= set(tags)  # no false ids
    for tid, centre in found.items():
        uv, _ = cam.project(tags[tid].t)
        assert np.linalg.norm(centre - uv) < 1.5, (tid, centre, uv)


def test_tracking_depth_on_table_tag():
    cam = g.TRACKING_CAMERA.scaled(0.5)
    tags = frame_tags(LOCATION, "tracking")
    _, depth = render_frame(cam, tags, True, np.random.default_rng(3))
    checked = 0
    for tid in g.TABLE_TAG_IDS:
        uv, z = cam.project(tags[tid].t)
        u, v = np.rint(uv).astype(int)
        if not (0 <= u < cam.width and 0 <= v < cam.height):
            continue
        # Depth at the pixel nearest the centre vs the z-depth of the ray
        # through that pixel centre hitting the table plane z = 0.
        ray = (np.array([(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1.0])) @ cam.R_wc
        t = -cam.position[2] / ray[2]
        z_true = t * (ray @ cam.R_wc[2]) * 1000.0
        assert abs(depth[v, u] / z_true - 1) < 0.01, (tid, depth[v, u], z_true)
        assert abs(depth[v, u] / (z * 1000.0) - 1) < 0.01
        checked += 1
    assert checked >= 4


def test_object_tag_tracked_over_the_gantry(detector):
    cam = g.TRACKING_CAMERA.scaled(0.5)
    for k in (0, 9, 90, 99):
        tags = frame_tags(k, "tracking")
        bgr, _ = render_frame(cam, tags, True, np.random.default_rng(k))
        found = _detect(detector, bgr)
        assert 1 in found, k
        uv, _ = cam.project(tags[1].t)
        assert np.linalg.norm(found[1] - uv) < 1.5


def test_full_scale_detects_all_visible(detector):
    for name in CAMERAS:
        cam = CAMERAS[name]
        tags = frame_tags(LOCATION, name)
        bgr, _ = render_frame(cam, tags, True, np.random.default_rng(4))
        expected = _visible(cam, tags)
        found = _detect(detector, bgr)
        assert expected <= set(found), (name, sorted(expected - set(found)))
        for tid in expected:
            uv, _ = cam.project(tags[tid].t)
            assert np.linalg.norm(found[tid] - uv) < 1.5
        if name == "colocated":
            assert {5, 6, 7} <= expected  # it looks at the relay wall


def test_config_knobs_and_small_scale():
    """The capture stage passes `rig.camera` config as keywords and may render
    the co-located camera at a quarter scale."""
    cam = g.COLOCATED_CAMERA.scaled(0.25)
    tags = frame_tags(LOCATION, "colocated")
    a, d = render_frame(cam, tags, True, np.random.default_rng(5), blur_sigma_px=0.6, read_noise_dn=2.0)
    assert a.shape == (120, 212, 3) and d.shape == (120, 212)
    b, _ = render_frame(cam, tags, True, np.random.default_rng(5))
    assert a.tobytes() == b.tobytes()  # the defaults are the config defaults
    c, _ = render_frame(cam, tags, True, np.random.default_rng(5), blur_sigma_px=0.0, read_noise_dn=0.0)
    assert c.tobytes() != a.tobytes() and 60 < _grey(c).mean() < 200
