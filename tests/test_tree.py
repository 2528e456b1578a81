"""`io/tree.py`: a capture tree surveyed against the configured sets, on
trees of empty NNN files (the survey reads names only)."""

from __future__ import annotations

import pytest
from release_trees import write_set, write_tree

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, expected_sets
from denali_pipe.core.geometry import N_LOCATIONS
from denali_pipe.io.release import location_span
from denali_pipe.io.tree import misnamed_reason, survey_tree

GRID = {"objects": ["1", "A"], "sizes": ["4inch", "8inch"], "resolutions": ["3x3"], "lightings": ["lighton"]}


@pytest.fixture(scope="module")
def sets(catalogue):
    """1 and A at both sizes and their two backgrounds: six sets."""
    return expected_sets(catalogue, GRID)


@pytest.mark.parametrize(
    "locations, span",
    [([0, 1, 2, 4], "000-002, 004"), (range(100), "000-099"), ([5], "005"), ([], "none"), ([10, 3, 9, 1, 2], "001-003, 009-010")],
)
def test_location_span(locations, span):
    assert location_span(locations) == span


def test_a_whole_tree_is_complete(tmp_path, sets):
    write_tree(tmp_path, sets)
    (tmp_path / "README.txt").touch()
    survey = survey_tree(tmp_path, sets, "release")
    assert survey.complete and survey.refusal(named=False) is None
    assert survey.missing == [] and survey.misnamed == [] and survey.set_problems() == {}
    assert sorted(survey.found) == sorted(s.name for s in sets)
    assert survey.usable() == [s.name for s in sets]
    assert survey.locations == frozenset(range(N_LOCATIONS)) and survey.grid_note() is None
    assert survey.other == ["README.txt"]
    listing = survey.listing()
    assert "complete: every configured set is here, whole" in listing
    assert f"  A_8inch_3x3_lighton{' ' * 21} spad_histogram 100 (000-099)  tracking_rgb 100" in listing


def test_a_missing_set_and_suffixed_folders_get_clear_messages(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"A_4inch_3x3_lighton", "1_8inch_3x3_lighton", "A_8inch_3x3_lighton", "1_4inch_3x3_lighton"})
    write_set(tmp_path, "", folder="A_4inch_3x3_lighton_short_NLOSdata")
    write_set(tmp_path, "", folder="1_8inch_3x3_lighton_long_NLOSdata")
    write_set(tmp_path, "", folder="A_8inch_3x3_lighton")
    write_set(tmp_path, "", folder="1_4inch_3x3_LightOn_NLOSdata")
    survey = survey_tree(tmp_path, sets, "release")
    assert not survey.complete
    assert survey.missing == ["1_4inch_3x3_lighton", "1_8inch_3x3_lighton", "A_4inch_3x3_lighton", "A_8inch_3x3_lighton"]
    reasons = {m.name: m.reason for m in survey.misnamed}
    assert reasons == {
        "1_4inch_3x3_LightOn_NLOSdata": "names are case-sensitive: expected 1_4inch_3x3_lighton_NLOSdata",
        "1_8inch_3x3_lighton_long_NLOSdata": "a long-range capture (the sensor's long-range mode: 260 ps bins, not short range's 100 ps); the benchmark is short-range only",
        "A_4inch_3x3_lighton_short_NLOSdata": "the capture script's `_short` range suffix, which the release's folder names drop; rename it to A_4inch_3x3_lighton_NLOSdata",
        "A_8inch_3x3_lighton": "expected the folder name A_8inch_3x3_lighton_NLOSdata",
    }
    refusal = survey.refusal(named=False)
    assert refusal.startswith(f"source release: the capture tree {tmp_path} does not hold the benchmark the config asks for (2 of 6 capture sets found):")
    assert "  missing (4): 1_4inch_3x3_lighton, 1_8inch_3x3_lighton, A_4inch_3x3_lighton, A_8inch_3x3_lighton" in refusal
    for name, reason in reasons.items():
        assert f"  misnamed, not read: {name}: {reason}" in refusal
    assert "name the sets to use in config `sets`" in refusal
    # the backgrounds are whole, but no object set is: nothing usable to run on but them
    assert survey.usable() == ["NOOBJECTMOUNT_8inch_3x3_lighton", "NOOBJECT_8inch_3x3_lighton"]


def test_an_archive_left_packed_is_named(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"A_4inch_3x3_lighton"})
    (tmp_path / "A_4inch_3x3_lighton_NLOSdata.zip").touch()
    (tmp_path / "denali-code.zip").touch()
    survey = survey_tree(tmp_path, sets, "release")
    assert [(m.name, m.reason) for m in survey.misnamed] == [("A_4inch_3x3_lighton_NLOSdata.zip", f"an archive, not a folder: unpack it in {tmp_path}")]
    assert survey.other == ["denali-code.zip"]


def test_a_gap_in_a_sets_locations_is_reported(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"A_4inch_3x3_lighton"})
    write_set(tmp_path, "A_4inch_3x3_lighton", [k for k in range(N_LOCATIONS) if k != 57])
    survey = survey_tree(tmp_path, sets, "release")
    assert survey.missing == [] and not survey.complete
    assert survey.set_problems() == {
        "A_4inch_3x3_lighton": ["spad_histogram/ lacks location(s) 057: it holds 99 (000-056, 058-099) of the 100 locations of the tree's other sets"]
    }
    assert "  A_4inch_3x3_lighton: spad_histogram/ lacks location(s) 057" in survey.refusal(named=False)
    assert "A_4inch_3x3_lighton" not in survey.usable() and "A_4inch_3x3_lighton" in survey.found
    assert "GAPS: spad_histogram/ lacks location(s) 057" in survey.listing()


def test_folders_that_disagree_say_what_each_holds(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"1_4inch_3x3_lighton", "A_8inch_3x3_lighton"})
    write_set(tmp_path, "1_4inch_3x3_lighton", range(N_LOCATIONS), frames=range(1, N_LOCATIONS))
    d = write_set(tmp_path, "A_8inch_3x3_lighton")
    (d / "spad_histogram" / "000.npy.part").touch()
    problems = survey_tree(tmp_path, sets, "release").set_problems()
    assert problems == {
        "1_4inch_3x3_lighton": ["tracking_rgb/ lacks location(s) 000 that spad_histogram/ holds"],
        "A_8inch_3x3_lighton": ["files that are not NNN.npy / NNN.png: spad_histogram/000.npy.part"],
    }


def test_a_set_without_its_histogram_folder(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"A_4inch_3x3_lighton"})
    (tmp_path / f"A_4inch_3x3_lighton{FOLDER_SUFFIX}").mkdir()
    problems = survey_tree(tmp_path, sets, "release").set_problems()
    assert problems == {"A_4inch_3x3_lighton": ["no spad_histogram/ folder", "no tracking_rgb/ folder (other sets of the tree have one)"]}


def test_sets_that_all_hold_fewer_locations_are_consistent_and_noted(tmp_path, sets):
    write_tree(tmp_path, sets, locations=[0, 33, 66, 99])
    survey = survey_tree(tmp_path, sets, "release")
    assert survey.complete
    assert survey.grid_note() == f"{tmp_path}: its capture sets hold 4 of the gantry grid's 100 locations (000, 033, 066, 099)"
    assert survey.grid_note() in survey.listing()


def test_unconfigured_sets_are_listed_not_read(tmp_path, sets):
    write_tree(tmp_path, sets)
    write_set(tmp_path, "B_4inch_3x3_lighton")
    survey = survey_tree(tmp_path, sets, "release")
    assert survey.complete and survey.unconfigured == ["B_4inch_3x3_lighton"]
    assert "well-named but not configured, not read (1): B_4inch_3x3_lighton" in survey.listing()


def test_sets_one_level_down_are_pointed_at(tmp_path, sets):
    write_tree(tmp_path / "denali-data" / "data", sets)
    survey = survey_tree(tmp_path, sets, "release")
    assert survey.missing == [s.name for s in sets]
    assert survey.elsewhere == [tmp_path / "denali-data" / "data"]
    assert f"capture sets lie in {tmp_path / 'denali-data' / 'data'}: point raw_dir there" in survey.refusal(named=False)


def test_named_sets_are_told_to_leave_config_sets(tmp_path, sets):
    write_tree(tmp_path, sets, skip={"A_4inch_3x3_lighton"})
    refusal = survey_tree(tmp_path, sets, "release").refusal(named=True)
    assert "does not hold the capture sets named in config `sets`" in refusal
    assert refusal.endswith("To proceed: complete these sets in the tree, or take them out of config `sets`.")


def test_capture_streams(tmp_path, sets):
    for s in sets:
        if s.name != "A_4inch_3x3_lighton":
            (tmp_path / f"{s.name}{PICKLE_SUFFIX}").touch()
    (tmp_path / "A_4inch_3x3_lighton_NLOSdata.pkl").touch()
    write_set(tmp_path, "A_4inch_3x3_lighton")  # a release folder beside the streams: not a stream, not misnamed
    survey = survey_tree(tmp_path, sets, "pickle")
    assert survey.missing == ["A_4inch_3x3_lighton"] and survey.files == {}
    assert [(m.name, m.reason) for m in survey.misnamed] == [
        ("A_4inch_3x3_lighton_NLOSdata.pkl", f"expected the stream name A_4inch_3x3_lighton{PICKLE_SUFFIX}")
    ]
    assert survey.other == [f"A_4inch_3x3_lighton{FOLDER_SUFFIX}"]


def test_no_such_raw_dir(tmp_path, sets):
    with pytest.raises(FileNotFoundError, match="raw_dir .*nowhere: no such folder"):
        survey_tree(tmp_path / "nowhere", sets, "release")


def test_misnamed_reason_of_one_folder(tmp_path):
    long = write_set(tmp_path, "", folder="A_4inch_3x3_lighton_long_NLOSdata")
    assert misnamed_reason(long).startswith("a long-range capture")
    assert misnamed_reason(write_set(tmp_path, "A_4inch_3x3_lighton")) is None
    assert misnamed_reason(write_set(tmp_path, "", folder="unrelated")) is None
