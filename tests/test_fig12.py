"""Figure 12 (`report/fig12.py`): the annotated tracking frame and the world
positions, PNG plus the CSV of its data, written atomically."""

from __future__ import annotations

import cv2
import numpy as np
import pandas as pd
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.poses import estimate_frames, filter_estimates
from denali_pipe.report.fig12 import CSV_COLUMNS, annotate_frame, write_fig12
from denali_pipe.rig.frames import frame_tags, render_frame


@pytest.fixture(scope="module")
def data():
    cam = geo.TRACKING_CAMERA.scaled(0.5)
    intr = cam.intrinsics
    frames = [(k, render_frame(cam, frame_tags(k, "tracking"), True, np.random.default_rng(k))[0]) for k in (0, 45, 99)]
    est = estimate_frames(frames, intr, set_name="A_8inch_3x3_lighton", light="lighton")
    return frames, est, filter_estimates(est)


def test_writes_png_and_csv(data, tmp_path):
    frames, est, filt = data
    k, frame = frames[1]
    rows = est[est["location"] == k]
    out = tmp_path / "fig" / "fig12.png"
    plotted = write_fig12(frame, rows, filt, out)
    img = cv2.imread(str(out))
    assert img is not None and img.shape[0] > 300 and img.shape[1] > 800
    csv = pd.read_csv(out.with_suffix(".csv"))
    assert csv.columns.tolist() == list(CSV_COLUMNS) and len(csv) == len(plotted)
    image = csv[csv["panel"] == "image"]
    assert sorted(image["tag_id"]) == sorted(rows.loc[rows["detected"], "tag_id"])
    world = csv[csv["panel"] == "world"]
    assert set(world["tag_id"]) == set(geo.STATIC_TAGS) | {geo.OBJECT_TAG_ID}
    assert sorted(world.loc[world["tag_id"] == geo.OBJECT_TAG_ID, "location"]) == [0, 45, 99]
    static = world[world["tag_id"] != geo.OBJECT_TAG_ID].set_index("tag_id")
    for tid, p in geo.STATIC_TAGS.items():
        np.testing.assert_allclose(static.loc[tid, ["x_m", "y_m", "z_m"]].to_numpy(float), p.t, atol=0.003)
    assert not list(out.parent.glob(".*tmp*"))  # no temporary files left


def test_annotation_draws_axes_where_the_tags_are(data):
    frames, est, _ = data
    k, frame = frames[0]
    rows = est[est["location"] == k]
    img = annotate_frame(frame, rows)
    assert img.shape == frame.shape and not np.array_equal(img, frame)
    assert np.array_equal(frame, frames[0][1])  # the input is not modified
    # pixels change around every located tag's centre
    diff = np.any(img != frame, axis=2)
    for r in rows[rows["status"] == "ok"].itertuples():
        u, v = int(round(r.u)), int(round(r.v))
        assert diff[max(v - 12, 0) : v + 12, max(u - 12, 0) : u + 12].any(), r.tag_id
