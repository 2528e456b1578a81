"""Template fitting (`poses/template.py`): corners of rendered tags against
the projected truth, saturated whites, and the cases it must decline."""

from __future__ import annotations

import numpy as np
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.poses.detect import TagDetector, to_grey
from denali_pipe.poses.template import fit_template, render_model
from denali_pipe.rig.frames import frame_tags, render_frame

CAM = geo.TRACKING_CAMERA.scaled(0.5)


@pytest.fixture(scope="module")
def frame():
    """A half-scale frame, its tags' true corners and their detections (refined)."""
    tags = frame_tags(40, "tracking")
    grey = to_grey(render_frame(CAM, tags, True, np.random.default_rng(3))[0])
    truth = {t: CAM.project(p.apply(geo.tag_corners_local()))[0] for t, p in tags.items()}
    return grey, truth, {d.tag_id: d.corners for d in TagDetector().detect(grey)}


def test_corners_closer_to_the_truth_than_the_detector(frame):
    grey, truth, dets = frame
    before, after = [], []
    for t, c in dets.items():
        fit = fit_template(grey, c, t)
        assert fit is not None and fit.n_pixels > 100, t
        before.append(np.abs(c - truth[t]).max())
        after.append(np.abs(fit.corners - truth[t]).max())
    # one noisy frame: the fit uses every pixel of the tag, the detector its edges
    assert np.median(after) < 0.5 * np.median(before) and max(after) < 0.1, (np.round(before, 3), np.round(after, 3))


def test_saturated_white_with_a_fixed_blur(frame):
    """Tag 1's paper clips at 255: with the camera's blur fixed the edges still place it."""
    grey, truth, dets = frame
    assert grey[np.round(truth[1]).astype(int)[:, 1], np.round(truth[1]).astype(int)[:, 0]].max() > 200
    fit = fit_template(grey, dets[1], 1, sigma=0.3, fit_sigma=False)
    assert fit.sigma_px == 0.3 and np.abs(fit.corners - truth[1]).max() < 0.06


def test_model_of_an_exact_render_is_recovered():
    """Noise-free, the model itself: corners shifted by 0.3 px come back to 1e-3 px."""
    c = np.array([[20.3, 15.2], [45.1, 16.0], [44.2, 38.7], [19.6, 37.9]])
    img = 20 + 200 * render_model(c, 7, (0, 0, 70, 60), 0.6)
    fit = fit_template(img, c + [0.3, -0.2], 7, sigma=0.6, fit_sigma=False)
    np.testing.assert_allclose(fit.corners, c, atol=1e-3)
    assert fit.rms_dn < 0.05


def test_declines_a_tag_cut_by_the_image_edge_or_a_wild_start(frame):
    grey, _, dets = frame
    c = dets[14]
    assert fit_template(grey[:, : int(c[:, 0].max()) + 1], c, 14) is None  # its margin is off the image
    assert fit_template(grey, c + [3.0, 0.0], 14) is None  # nothing like the tag there: the fit wanders off
