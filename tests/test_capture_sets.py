"""Capture-set names and the sets a config asks for (`capture_sets.py`)."""

from __future__ import annotations

import copy
from collections import Counter

import pytest
from conftest import REPO

from denali_pipe.core.capture_sets import (
    FOLDER_SUFFIX,
    LIGHTINGS,
    PICKLE_SUFFIX,
    CaptureSet,
    background_of,
    expected_sets,
    parse_set_name,
    select_objects,
    select_sets,
)
from denali_pipe.core.objects import BACKGROUNDS

# --- parse_set_name ------------------------------------------------------------------


@pytest.mark.parametrize(
    "name",
    [
        "A_4inch_3x3_lighton",
        "0_8inch_8x8_lightoff",
        "widerectangle_4inch_8x8_lighton",
        "generalization1italic_8inch_3x3_lightoff",
        "NOOBJECT_8inch_3x3_lighton",
        "NOOBJECTMOUNT_8inch_8x8_lightoff",
    ],
)
def test_parse_round_trip(name):
    cs = parse_set_name(name)
    assert cs.name == name
    assert parse_set_name(cs.name) == cs
    assert parse_set_name(name + FOLDER_SUFFIX) == cs
    assert parse_set_name(name + PICKLE_SUFFIX) == cs


def test_parse_fields():
    cs = parse_set_name("circle_8inch_8x8_lightoff_NLOSdata")
    assert cs == CaptureSet("circle", "8inch", "8x8", "lightoff")
    assert (cs.object, cs.size, cs.resolution, cs.light) == ("circle", "8inch", "8x8", "lightoff")
    assert cs.n_zones == 8 and not cs.light_on and not cs.is_background
    cs = parse_set_name("NOOBJECT_8inch_3x3_lighton_short_NLOSdata.pkl")
    assert cs.n_zones == 3 and cs.light_on and cs.is_background


@pytest.mark.parametrize(
    "name",
    [
        "",
        "A",
        "A_4inch_3x3",
        "A_5inch_3x3_lighton",
        "A_4inch_4x4_lighton",
        "A_4inch_3x3_lightsout",
        "A-B_4inch_3x3_lighton",
        "_4inch_3x3_lighton",
        "A_4inch_3x3_lighton_NLOSdata.pkl",
        "A_4inch_3x3_lighton.pkl",
        "A_4inch_3x3_lighton_extra",
        "A_4inch_3x3_lighton/",
        "A_4INCH_3x3_lighton",
    ],
)
def test_parse_rejects_bad_names(name):
    with pytest.raises(ValueError) as e:
        parse_set_name(name)
    assert repr(name) in str(e.value)


@pytest.mark.parametrize("name", ["A_4inch_3x3_lighton\n", "A_4inch_3x3_lighton\n_NLOSdata"])
def test_parse_rejects_trailing_newline(name):
    """A trailing newline is not part of a set name."""
    with pytest.raises(ValueError):
        parse_set_name(name)


# --- expected_sets ---------------------------------------------------------------------


def test_expected_sets_demo_count(catalogue, demo_config):
    sets = expected_sets(catalogue, demo_config)
    base = 30 * 2 * 2 * 2  # 30 base shapes x 2 sizes x 2 resolutions x 2 lightings
    italic = 3 * 2 * 2  # 8inch only
    nonrr = 2 * 2 * 2 * 2  # cardstock and white 1, both sizes
    backgrounds = 2 * 2 * 2  # NOOBJECT, NOOBJECTMOUNT; one size
    assert len(sets) == base + italic + nonrr + backgrounds == 276
    assert len(set(sets)) == len(sets)
    assert [s.name for s in sets] == sorted(s.name for s in sets)

    by_variant = Counter(catalogue[s.object].variant if not s.is_background else "background" for s in sets)
    assert by_variant == {"base": base, "italic": italic, "nonrr": nonrr, "background": backgrounds}
    assert {s.size for s in sets if catalogue.get(s.object) is not None and catalogue[s.object].italic} == {"8inch"}
    assert {(s.object, s.size) for s in sets if s.is_background} == {(b, "8inch") for b in BACKGROUNDS}
    # every name parses back to its set
    assert all(parse_set_name(s.name) == s for s in sets)


def test_expected_sets_follow_config(catalogue, demo_config):
    cfg = copy.deepcopy(demo_config)
    cfg.update(objects=["A", "generalization1italic"], sizes=["4inch"], resolutions=["8x8"], lightings=["lightoff"])
    names = [s.name for s in expected_sets(catalogue, cfg)]
    # the italic object exists only at 8inch, so it drops out; backgrounds stay (8inch by convention)
    assert names == sorted(["A_4inch_8x8_lightoff", "NOOBJECTMOUNT_8inch_8x8_lightoff", "NOOBJECT_8inch_8x8_lightoff"])


def test_expected_sets_tiny_preset(catalogue, demo_config):
    import yaml

    cfg = copy.deepcopy(demo_config)
    cfg.update(yaml.safe_load((REPO / "config" / "presets" / "tiny.yaml").read_text()))
    sets = expected_sets(catalogue, cfg)
    # 1, A, circle, white 1: 4 objects x 2 sizes x 4 (res, light); italic 1 (8 in only) x 4; 8 backgrounds
    assert len(sets) == 4 * 2 * 4 + 4 + 8
    assert {s.object for s in sets} == {"1", "A", "circle", "generalization1white", "generalization1italic", *BACKGROUNDS}


# --- select_objects, background_of ---------------------------------------------------------


def test_select_objects(catalogue):
    assert select_objects(catalogue, "all") == list(catalogue.values())
    picked = select_objects(catalogue, ["circle", "A"])
    assert [s.name for s in picked] == ["circle", "A"]


def test_select_objects_rejects_unknown(catalogue):
    with pytest.raises(ValueError) as e:
        select_objects(catalogue, ["A", "Q", "dodecahedron"])
    msg = str(e.value)
    assert "Q" in msg and "dodecahedron" in msg
    assert "'A'" not in msg  # only the unknown names are listed


def test_expected_sets_rejects_unknown_object(catalogue, demo_config):
    cfg = copy.deepcopy(demo_config)
    cfg["objects"] = ["A", "zeppelin"]
    with pytest.raises(ValueError, match="zeppelin"):
        expected_sets(catalogue, cfg)


@pytest.mark.parametrize("res", ["3x3", "8x8"])
@pytest.mark.parametrize("light", LIGHTINGS)
def test_background_of(res, light):
    for obj, size in [("A", "4inch"), ("generalization1italic", "8inch"), ("NOOBJECTMOUNT", "8inch")]:
        bg = background_of(CaptureSet(obj, size, res, light))
        assert bg == CaptureSet("NOOBJECT", "8inch", res, light)
        assert bg.is_background
        assert bg.name == f"NOOBJECT_8inch_{res}_{light}"


def test_every_object_set_has_its_background(catalogue, demo_config):
    sets = set(expected_sets(catalogue, demo_config))
    for s in sets:
        assert background_of(s) in sets


# --- select_sets ---------------------------------------------------------------------


def test_select_sets_all_keeps_every_set(catalogue, demo_config):
    sets = expected_sets(catalogue, demo_config)
    assert select_sets(sets, "all") == sets


def test_select_sets_keeps_the_named_ones_in_name_order(catalogue, demo_config):
    sets = expected_sets(catalogue, demo_config)
    named = ["NOOBJECT_8inch_3x3_lighton", "A_4inch_3x3_lighton", "1_8inch_3x3_lighton"]
    assert [s.name for s in select_sets(sets, named)] == sorted(named)


def test_select_sets_refuses_a_set_outside_the_grid(catalogue, demo_config):
    cfg = copy.deepcopy(demo_config)
    cfg["resolutions"] = ["3x3"]
    with pytest.raises(ValueError, match=r"config `sets` names \['A_4inch_8x8_lighton', 'NOOBJECT_8inch_8x8_lighton'\], which the grid .* does not ask for"):
        select_sets(expected_sets(catalogue, cfg), ["A_4inch_8x8_lighton", "NOOBJECT_8inch_8x8_lighton"])


def test_select_sets_needs_the_backgrounds(catalogue, demo_config):
    with pytest.raises(ValueError, match=r"without their background sets \['NOOBJECT_8inch_3x3_lighton'\]"):
        select_sets(expected_sets(catalogue, demo_config), ["A_4inch_3x3_lighton"])
