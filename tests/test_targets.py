"""`targets.py`: the artefact table is what `rule all` builds, and what
`denali targets` lists."""

from __future__ import annotations

import re

from workflow import copy_workflow, merged_config, snakemake

from denali_pipe.cli import main
from denali_pipe.core.objects import load_catalogue
from denali_pipe.twin.selection import twin_pairs
from denali_pipe.workflow.targets import TARGETS, target_files

TINY = "config/presets/tiny.yaml"


def test_target_files_expand_the_twins_per_pair():
    files = target_files([("A", "4inch"), ("1", "8inch")])
    per_pair = ("results/twin/", "results/twin_calibrated/")
    for folder in per_pair:
        assert [f for f in files if f.startswith(folder)] == [f"{folder}A_4inch.zarr", f"{folder}1_8inch.zarr"]
    assert [f for f in files if not f.startswith(per_pair)] == [t.path for t in TARGETS if "{object}" not in t.path]


def test_every_artefact_has_one_file():
    assert len({t.artefact for t in TARGETS}) == len(TARGETS)
    assert len({t.path for t in TARGETS}) == len(TARGETS)


def test_rule_all_builds_exactly_the_table(tmp_path):
    # a dry run prints the rule's input files: no other list of them can drift from the table
    wd = copy_workflow(tmp_path)
    out = snakemake(wd, "-n", "--configfile", TINY).stdout
    built = re.search(r"^rule all:\n    input: (.*)$", out, re.M)[1].split(", ")
    cfg = merged_config(wd, TINY)
    assert sorted(built) == sorted(target_files(twin_pairs(load_catalogue(wd / cfg["objects_sheet"]), cfg)))


def test_denali_targets_lists_each_artefact_and_file(capsys):
    assert main(["targets"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(TARGETS)
    for line, t in zip(lines, TARGETS):
        assert line.split()[: len(t.artefact.split()) + 1] == [*t.artefact.split(), t.path]
        assert line.endswith(t.what)
