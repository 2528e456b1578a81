"""The tracked scene (`rig/tracked_scene.py`): our design drawing, a
release's poses.json (where present), and poses.json files that are wrong."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import ASSETS

from denali_pipe.core import geometry as geo
from denali_pipe.rig.tracked_scene import WALL_GAP_M, design_scene, release_scene, tracked_scene

POSES_JSON = ASSETS / "poses.json"


def _doc() -> dict:
    """A minimal valid poses.json: the design's static tags and gantry grid."""

    def pose(p):
        return {"center": p.t.tolist(), "rotation_matrix": p.R.tolist()}

    return {
        "tracking_avgposes": {str(i): pose(p) for i, p in geo.STATIC_TAGS.items()},
        "tracking_tag1_index_avgposes": {str(k): pose(geo.tag1_pose(k)) for k in range(geo.N_LOCATIONS)},
    }


def test_design_scene_is_the_drawing():
    sc = tracked_scene(None)
    assert sc is design_scene() and sc.source == "design"
    assert sc.static_tags == geo.STATIC_TAGS and sc.tables == geo.TABLES and sc.wall is geo.WALL
    np.testing.assert_allclose(sc.tag1_pose(42).t, geo.tag1_position(42))


def test_a_poses_json_of_the_drawing_gives_the_drawing(tmp_path):
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(_doc()))
    sc = release_scene(path)
    for k, rect in geo.TABLES.items():
        np.testing.assert_allclose(sc.tables[k].centre, rect.centre, atol=1e-12)
        np.testing.assert_allclose(sc.tables[k].normal, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(sc.wall.centre, geo.WALL.centre, atol=1e-12)  # the design wall sits 1 mm behind its tags
    np.testing.assert_allclose(sc.tag1_pose(99).t, geo.tag1_position(99), atol=1e-12)
    assert sc.to_dict()["source"] == str(path)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.pop("tracking_avgposes"), "needs 'tracking_avgposes'"),
        (lambda d: d["tracking_avgposes"].pop("7"), r"lacks static tag\(s\) \[7\]"),
        (lambda d: d["tracking_tag1_index_avgposes"].pop("55"), r"lacks gantry location\(s\) \[55\]"),
        (lambda d: d["tracking_avgposes"]["5"].pop("center"), r"tracking_avgposes\[5\] needs 'center'"),
        (lambda d: d["tracking_avgposes"]["6"].update(center=[0, 1]), r"tracking_avgposes\[6\]: center must be 3 finite numbers"),
        (lambda d: d["tracking_tag1_index_avgposes"]["3"].update(rotation_matrix=np.diag([1, 1, 2.0]).tolist()), r"\[3\]: rotation_matrix is not a rotation"),
    ],
)
def test_malformed_poses_json_names_the_file_and_the_fault(tmp_path, edit, message):
    doc = _doc()
    edit(doc)
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=message) as e:
        release_scene(path)
    assert str(path) in str(e.value)


def test_missing_or_unreadable_poses_json(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        release_scene(tmp_path / "nowhere.json")
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="bad.json: not valid JSON"):
        release_scene(tmp_path / "bad.json")


@pytest.mark.skipif(not POSES_JSON.exists(), reason=f"the release's poses.json is not at {POSES_JSON}")
def test_release_scene_follows_its_tags():
    doc = json.loads(POSES_JSON.read_text())
    sc = tracked_scene(POSES_JSON)
    for i, p in sc.static_tags.items():
        np.testing.assert_allclose(p.t, doc["tracking_avgposes"][str(i)]["center"])
    # each table top holds its tags: table 15 higher (1-1.5 cm) and tilted ~0.6 deg, table 14 the world's z = 0
    for table, ids in geo.TABLE_TAGS.items():
        top = sc.tables[table]
        assert max(abs((sc.static_tags[i].t - top.centre) @ top.normal) for i in ids) < 1e-4
    assert np.degrees(np.arccos(sc.tables[15].normal[2])) == pytest.approx(0.57, abs=0.05)
    assert np.degrees(np.arccos(sc.tables[14].normal[2])) < 1e-6
    # the visual wall 1 mm behind the wall tags, facing the room
    for i in geo.WALL_TAG_IDS:
        assert (sc.static_tags[i].t - sc.wall.centre) @ sc.wall.normal == pytest.approx(WALL_GAP_M, abs=1e-4)
    assert sc.wall.normal[1] < -0.99
    z = np.array([sc.tag1_pose(k).t[2] for k in range(geo.N_LOCATIONS)])
    assert np.ptp(z) > 0.03  # tag 1's height varies over the gantry by 3 cm
