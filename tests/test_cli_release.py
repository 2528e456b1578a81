"""`denali check-release` through `denali_pipe.cli.main` (in-process), from
the repository root as a user runs it."""

from __future__ import annotations

import logging

import pytest
import yaml
from conftest import REPO
from release_trees import write_set, write_tree

from denali_pipe.cli import main
from denali_pipe.core.capture_sets import expected_sets
from denali_pipe.workflow.config import load_config

TINY = "config/presets/tiny.yaml"


@pytest.fixture
def tiny_sets(monkeypatch, catalogue):
    monkeypatch.chdir(REPO)
    return expected_sets(catalogue, load_config([TINY]))


def errors(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "denali" and r.levelno >= logging.ERROR]


def test_a_complete_tree_passes(tmp_path, tiny_sets, capsys, caplog):
    write_tree(tmp_path, tiny_sets)
    assert main(["check-release", str(tmp_path), "--configfile", TINY]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"capture tree {tmp_path} (source release): {len(tiny_sets)} capture sets configured\nfound ({len(tiny_sets)}):")
    assert out.rstrip().endswith("complete: every configured set is here, whole")
    assert errors(caplog) == []


def test_an_incomplete_tree_is_listed_and_fails(tmp_path, tiny_sets, capsys, caplog):
    write_tree(tmp_path, tiny_sets, skip={"A_4inch_3x3_lighton", "circle_8inch_8x8_lightoff"})
    write_set(tmp_path, "", folder="A_4inch_3x3_lighton_short_NLOSdata")
    write_set(tmp_path, "circle_8inch_8x8_lightoff", range(99))
    sets_file = tmp_path.parent / f"{tmp_path.name}-sets.yaml"
    assert main(["check-release", str(tmp_path), "--configfile", TINY, "--write-sets", str(sets_file)]) == 1
    out = capsys.readouterr().out
    assert "missing (1):\n  A_4inch_3x3_lighton\n" in out
    assert "A_4inch_3x3_lighton_short_NLOSdata: the capture script's `_short` range suffix" in out
    assert "circle_8inch_8x8_lightoff" in out and "GAPS: spad_histogram/ lacks location(s) 099" in out
    assert "incomplete: 1 missing, 1 with gaps" in out
    assert errors(caplog) == [f"{tmp_path}: the capture tree does not hold every configured set whole (listed above)"]
    # the sets found whole, as a config file that validates over the preset
    named = yaml.safe_load(sets_file.read_text())["sets"]
    assert set(named) == {s.name for s in tiny_sets} - {"A_4inch_3x3_lighton", "circle_8inch_8x8_lightoff"}
    assert load_config([TINY, sets_file])["sets"] == named


def test_a_missing_configfile_is_named(tmp_path, tiny_sets, caplog):
    assert main(["check-release", str(tmp_path), "--configfile", "config/presets/nosuch.yaml"]) == 1
    assert errors(caplog) == ["config/presets/nosuch.yaml: no such config file (run from the repository root, or pass --defaults)"]
