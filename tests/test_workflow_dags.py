"""`rule all`'s DAG builds for every preset x source x protocol x renderer
(`snakemake -n`, no job runs): a configuration branch that only some
combination reaches fails here, not hours into a run."""

import functools
import itertools

import pytest
import yaml
from workflow import copy_workflow, dry_runs, merged_config

from denali_pipe.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, CaptureSet, expected_sets
from denali_pipe.objects import load_catalogue

PRESETS = {"tiny": ("config/presets/tiny.yaml",), "demo": (), "paper": ("config/presets/paper.yaml",)}
SOURCES = ("synthetic", "release", "pickle")
PROTOCOLS = ("clean", "paper")
RENDERERS = ("analytic", "mitransient")
COMBOS = list(itertools.product(PRESETS, SOURCES, PROTOCOLS, RENDERERS))
PLACEHOLDERS = "placeholders"
# a release source whose raw tree holds nothing: a DAG that must not build
EMPTY = "empty"


def configfiles(wd, preset: str, source: str, protocol: str, renderer: str) -> tuple[str, ...]:
    """The preset's file, then one (written into `wd`) setting the rest."""
    combo = {"source": source, "train": {"protocol": protocol}, "twin": {"renderer": renderer}}
    if source != "synthetic":
        combo["raw_dir"] = PLACEHOLDERS
    name = f"{preset}-{source}-{protocol}-{renderer}.yaml"
    (wd / name).write_text(yaml.safe_dump(combo))
    return (*PRESETS[preset], name)


@functools.cache
def preset_sets(scratch, preset: str) -> list[CaptureSet]:
    """The capture sets a preset asks for (the other settings change none)."""
    cfg = merged_config(scratch, *PRESETS[preset])
    return expected_sets(load_catalogue(scratch / cfg["objects_sheet"]), cfg)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """One scratch copy of the workflow, and a placeholder raw tree: an empty
    folder and an empty stream for every set of every object (set discovery
    only asks whether they exist)."""
    wd = copy_workflow(tmp_path_factory.mktemp("dags"))
    cfg = merged_config(wd)
    (wd / PLACEHOLDERS).mkdir()
    (wd / EMPTY).mkdir()
    for s in expected_sets(load_catalogue(wd / cfg["objects_sheet"]), {**cfg, "objects": "all"}):
        (wd / PLACEHOLDERS / f"{s.name}{FOLDER_SUFFIX}").mkdir()
        (wd / PLACEHOLDERS / f"{s.name}{PICKLE_SUFFIX}").touch()
    return wd


@pytest.fixture(scope="module")
def dags(scratch):
    """{combination (or EMPTY): job counts, or Snakemake's failure}."""
    argsets = {combo: ("--configfile", *configfiles(scratch, *combo)) for combo in COMBOS}
    argsets[EMPTY] = ("--configfile", "config/presets/tiny.yaml", "--config", "source=release", f"raw_dir={EMPTY}")
    return dict(zip(argsets, dry_runs(scratch, list(argsets.values()))))


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(c) for c in COMBOS])
def test_rule_all_dag_builds(scratch, dags, combo):
    preset, source, _, _ = combo
    jobs = dags[combo]
    assert isinstance(jobs, dict), jobs
    sets = preset_sets(scratch, preset)
    assert jobs["all"] == 1
    assert jobs["total"] <= 2000  # the scale target; scripts/bench_dag.py prints the build time
    assert jobs["ingest"] == len(sets)
    # the rig writes the raw tree only when it is the source, one job per object and size
    assert jobs.get("rig", 0) == (len({(s.object, s.size) for s in sets}) if source == "synthetic" else 0)


def test_a_dag_that_does_not_build_fails_with_the_reason(dags):
    assert f"source release: no configured capture set found in {EMPTY}" in dags[EMPTY]
