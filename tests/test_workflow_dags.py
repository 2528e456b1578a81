"""`rule all`'s DAG builds over preset x source x protocol x renderer
(`snakemake -n`, no job runs): every pair of settings of any two of them
meets in some build, so a configuration branch that a pair of settings
reaches fails here, not hours into a run."""

import functools
import itertools

import pytest
import yaml
from release_trees import write_set, write_tree
from workflow import copy_workflow, dry_runs, merged_config

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, CaptureSet, expected_sets
from denali_pipe.core.geometry import N_LOCATIONS
from denali_pipe.core.objects import load_catalogue
from denali_pipe.train.cells import TASKS

PRESETS = {"tiny": ("config/presets/tiny.yaml",), "demo": (), "paper": ("config/presets/paper.yaml",), "release": ("config/presets/release.yaml",)}
SOURCES = ("synthetic", "release", "pickle")
PROTOCOLS = ("clean", "paper")
RENDERERS = ("analytic", "mitransient")
ILLUMINATION = {"analytic": "flood", "mitransient": "spot"}  # mitransient traces the spot only
# mitransient asked to render the flood: a config refused before any DAG
FLOOD_TRACED = "flood_traced"
# Pairwise, not the full 48-build product (a demo or paper DAG costs ~5 CPU-s):
# per preset, one (protocol, renderer) per source, chosen so that every value
# of every factor meets every value of every other. The demo and the paper
# preset share theirs, so that their builds differ by the preset alone.
PAIRS = {
    "tiny": (("clean", "analytic"), ("paper", "mitransient"), ("clean", "mitransient")),
    "demo": (("clean", "mitransient"), ("paper", "analytic"), ("paper", "mitransient")),
    "paper": (("clean", "mitransient"), ("paper", "analytic"), ("paper", "mitransient")),
    "release": (("paper", "mitransient"), ("clean", "analytic"), ("paper", "analytic")),
}
COMBOS = [(preset, source, *PAIRS[preset][i]) for preset in PRESETS for i, source in enumerate(SOURCES)]
PLACEHOLDERS = "placeholders"
# a release source whose raw tree holds nothing: a DAG that must not build
EMPTY = "empty"
# the tiny preset's release tree without one set and with another under the
# capture script's name: a DAG that must not build, unless the config names
# the sets to use (NAMED)
SHORT, NAMED = "short", "named"
ABSENT, SUFFIXED = "A_4inch_8x8_lightoff", "circle_8inch_3x3_lighton"


def configfiles(wd, preset: str, source: str, protocol: str, renderer: str) -> tuple[str, ...]:
    """The preset's file, then one (written into `wd`) setting the rest."""
    combo = {"source": source, "train": {"protocol": protocol}, "twin": {"renderer": renderer, "illumination": ILLUMINATION[renderer]}}
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
    """One scratch copy of the workflow, and a placeholder raw tree: for every
    set of every object, a folder of empty spad_histogram/NNN.npy files at
    every location and an empty stream (the DAG reads only their names).
    Beside it, SHORT: the tiny preset's sets, ABSENT missing and SUFFIXED
    under its `_short` name."""
    wd = copy_workflow(tmp_path_factory.mktemp("dags"))
    cfg = merged_config(wd)
    (wd / EMPTY).mkdir()
    for s in expected_sets(load_catalogue(wd / cfg["objects_sheet"]), {**cfg, "objects": "all"}):
        hist = wd / PLACEHOLDERS / f"{s.name}{FOLDER_SUFFIX}" / "spad_histogram"
        hist.mkdir(parents=True)
        for k in range(N_LOCATIONS):
            (hist / f"{k:03d}.npy").touch()
        (wd / PLACEHOLDERS / f"{s.name}{PICKLE_SUFFIX}").touch()
    tiny = preset_sets(wd, "tiny")
    write_tree(wd / SHORT, tiny, skip={ABSENT, SUFFIXED})
    write_set(wd / SHORT, SUFFIXED, folder=f"{SUFFIXED}_short{FOLDER_SUFFIX}")
    usable = [s.name for s in tiny if s.name not in {ABSENT, SUFFIXED}]
    (wd / f"{NAMED}.yaml").write_text(yaml.safe_dump({"source": "release", "raw_dir": SHORT, "sets": usable}))
    (wd / f"{FLOOD_TRACED}.yaml").write_text(yaml.safe_dump({"twin": {"renderer": "mitransient", "illumination": "flood"}}))
    return wd


@pytest.fixture(scope="module")
def dags(scratch):
    """{combination (or EMPTY): job counts, or Snakemake's failure}."""
    argsets = {combo: ("--configfile", *configfiles(scratch, *combo)) for combo in COMBOS}
    argsets[EMPTY] = ("--configfile", "config/presets/tiny.yaml", "--config", "source=release", f"raw_dir={EMPTY}")
    argsets[SHORT] = ("--configfile", "config/presets/tiny.yaml", "--config", "source=release", f"raw_dir={SHORT}")
    argsets[NAMED] = ("--configfile", "config/presets/tiny.yaml", f"{NAMED}.yaml")
    argsets[FLOOD_TRACED] = ("--configfile", "config/presets/tiny.yaml", f"{FLOOD_TRACED}.yaml")
    return dict(zip(argsets, dry_runs(scratch, list(argsets.values()))))


def test_the_builds_meet_every_pair_of_settings():
    factors = (PRESETS, SOURCES, PROTOCOLS, RENDERERS)
    for (i, a), (j, b) in itertools.combinations(enumerate(factors), 2):
        assert {(c[i], c[j]) for c in COMBOS} == set(itertools.product(a, b)), (i, j)


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(c) for c in COMBOS])
def test_rule_all_dag_builds(scratch, dags, combo):
    preset, source, _, _ = combo
    jobs = dags[combo]
    assert isinstance(jobs, dict), jobs
    sets = preset_sets(scratch, preset)
    assert jobs["all"] == 1 and jobs["stability"] == 1
    assert jobs["total"] <= 2000  # the scale target; scripts/bench_dag.py prints the build time
    assert jobs["ingest"] == len(sets)
    # the rig writes the raw tree only when it is the source, one job per object, size and resolution
    assert jobs.get("rig", 0) == (len({(s.object, s.size, s.resolution) for s in sets}) if source == "synthetic" else 0)


def test_the_demo_leaves_out_the_cells_of_its_left_out_models(scratch, dags):
    """The demo's train.left_out models train no Table 2 cell; the paper
    preset (same seeds, conditions and jitter sweep) trains them all."""
    demo, paper = merged_config(scratch), merged_config(scratch, *PRESETS["paper"])
    assert demo["train"]["seeds"] == paper["train"]["seeds"] and paper["train"]["left_out"] == []
    left_out = len(demo["train"]["left_out"])
    assert PAIRS["demo"] == PAIRS["paper"]
    for source, (protocol, renderer) in zip(SOURCES, PAIRS["demo"]):
        jobs = {preset: dags[(preset, source, protocol, renderer)]["train"] for preset in ("demo", "paper")}
        assert jobs["paper"] - jobs["demo"] == left_out * len(TASKS) * len(demo["train"]["seeds"])


def test_a_dag_that_does_not_build_fails_with_the_reason(scratch, dags):
    n = len(preset_sets(scratch, "tiny"))
    assert f"source release: the capture tree {EMPTY} does not hold the benchmark the config asks for (0 of {n} capture sets found):" in dags[EMPTY]


def test_mitransient_is_refused_the_flood(dags):
    assert "twin.renderer mitransient traces one laser spot: set twin.illumination: spot" in dags[FLOOD_TRACED]


def test_a_tree_smaller_than_configured_is_refused_with_what_is_missing(scratch, dags):
    n = len(preset_sets(scratch, "tiny"))
    refusal = dags[SHORT]
    assert isinstance(refusal, str), refusal
    assert f"the capture tree {SHORT} does not hold the benchmark the config asks for ({n - 2} of {n} capture sets found):" in refusal
    assert f"  missing (2): {ABSENT}, {SUFFIXED}" in refusal
    assert f"  misnamed, not read: {SUFFIXED}_short{FOLDER_SUFFIX}: the capture script's `_short` range suffix" in refusal
    assert "To proceed: complete the tree; or name the sets to use in config `sets`" in refusal


def test_the_sets_a_config_names_run_on_a_smaller_tree(scratch, dags):
    jobs = dags[NAMED]
    assert isinstance(jobs, dict), jobs
    assert jobs["ingest"] == len(preset_sets(scratch, "tiny")) - 2 and jobs.get("rig", 0) == 0
