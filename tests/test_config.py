"""The configuration: config.yaml, the presets, and schema.yaml (one source of truth)."""

from __future__ import annotations

import copy
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from conftest import REPO
from snakemake.utils import update_config, validate

from denali_pipe.core.capture_sets import expected_sets
from denali_pipe.core.geometry import PAPER_TIME_AXIS, TimeAxis
from denali_pipe.core.objects import BACKGROUNDS, load_catalogue

SCHEMA = str(REPO / "config" / "schema.yaml")
HYPER = {"lr": 1e-3, "epochs": 1, "batch_size": 8, "norm": "raw"}
PRESETS = sorted((REPO / "config" / "presets").glob("*.yaml"))


def load(path: Path) -> dict:
    with open(path) as f:
        return yaml.safe_load(f) or {}


def merged(overrides: dict) -> dict:
    """config.yaml with `overrides` merged in recursively, as Snakemake does for
    `--configfile` / `--config`."""
    cfg = load(REPO / "config" / "config.yaml")
    update_config(cfg, copy.deepcopy(overrides))
    return cfg


# --- valid configs ----------------------------------------------------------------------


def test_presets_found():
    assert {p.stem for p in PRESETS} >= {"tiny", "paper"}


def test_default_config_validates():
    cfg = load(REPO / "config" / "config.yaml")
    before = copy.deepcopy(cfg)
    validate(cfg, SCHEMA)
    assert cfg == before  # complete already: no default had to be filled in


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.stem)
def test_preset_validates(preset):
    cfg = merged(load(preset))
    validate(cfg, SCHEMA)
    # and the merge kept every key the preset does not override
    assert set(cfg["rig"]) == set(load(REPO / "config" / "config.yaml")["rig"])
    assert expected_sets(load_catalogue(REPO / cfg["objects_sheet"]), cfg)


def test_release_preset_is_the_whole_release_at_the_paper_schedules(catalogue):
    cfg = merged(load(REPO / "config" / "presets" / "release.yaml"))
    validate(cfg, SCHEMA)
    assert (cfg["preset"], cfg["source"], cfg["sets"]) == ("release", "release", "all")
    assert cfg["train"]["max_epochs"] is None and cfg["train"]["budget_seconds"] is None
    # every object of the sheet at each of its sizes and both backgrounds, at 2 resolutions x 2 lightings
    n_sets = sum(len(spec.sizes) for spec in catalogue.values()) + len(BACKGROUNDS)
    assert len(expected_sets(catalogue, cfg)) == n_sets * 2 * 2


def test_the_paper_preset_keeps_the_reference_twins_time_axis():
    """The paper's bins, to the last bit, whatever config.yaml's default axis."""
    cfg = merged(load(REPO / "config" / "presets" / "paper.yaml"))
    assert TimeAxis.from_config(cfg["sensor"]["time_axis"]) == PAPER_TIME_AXIS


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.stem)
def test_preset_alone_plus_defaults_equals_merge(preset):
    """Schema defaults filled into a bare preset give the same config as the
    preset merged over config.yaml."""
    alone = load(preset)
    validate(alone, SCHEMA)
    assert alone == merged(load(preset))


def test_schema_defaults_are_config_yaml():
    """One source of truth: the schema's defaults, applied to {}, are exactly config.yaml."""
    cfg: dict = {}
    validate(cfg, SCHEMA)
    assert cfg == load(REPO / "config" / "config.yaml")


def test_defaults_fill_nested_keys():
    cfg = {"rig": {"n_locations": 4, "photometry": {"dark_counts": 10}}}
    validate(cfg, SCHEMA)
    demo = load(REPO / "config" / "config.yaml")
    assert cfg["rig"]["n_locations"] == 4
    assert cfg["rig"]["repeats"] == demo["rig"]["repeats"]
    assert cfg["rig"]["frames"] == demo["rig"]["frames"]
    assert cfg["rig"]["photometry"] == {**demo["rig"]["photometry"], "dark_counts": 10}


def test_defaults_are_not_shared_between_validations():
    a: dict = {}
    validate(a, SCHEMA)
    a["rig"]["frames"]["tracking_scale"] = 0.9
    b: dict = {}
    validate(b, SCHEMA)
    assert b["rig"]["frames"]["tracking_scale"] == 0.5


# --- invalid configs ---------------------------------------------------------------------

BAD = [
    ({"rig": {"n_locations": 0}}, "n_locations"),
    ({"rig": {"n_locations": 101}}, "n_locations"),
    ({"rig": {"repeats": 2.5}}, "repeats"),
    ({"rig": {"frames": {"tracking_scale": 0}}}, "tracking_scale"),
    ({"rig": {"frames": {"colocated_scale": 1.5}}}, "colocated_scale"),
    ({"rig": {"photometry": {"dark_counts": -1}}}, "dark_counts"),
    ({"rig": {"photometry": {"direct_peak_counts": "lots"}}}, "direct_peak_counts"),
    ({"sizes": ["5inch"]}, "sizes"),
    ({"sizes": []}, "sizes"),
    ({"resolutions": ["4x4"]}, "resolutions"),
    ({"lightings": ["lighton", "lighton"]}, "lightings"),
    ({"objects": "ALL"}, "objects"),
    ({"objects": []}, "objects"),
    ({"seed": -1}, "seed"),
    ({"source": "s3"}, "source"),
    ({"raw_dir": ""}, "raw_dir"),
    ({"bogus": 1}, "bogus"),
    ({"rig": {"n_location": 3}}, "n_location"),
    ({"rig": {"frames": {"scale": 0.5}}}, "scale"),
    ({"sensor": {"time_axis": {"bin_width_ps": 0}}}, "bin_width_ps"),
    ({"sensor": {"time_axis": {"zero_bin": "13"}}}, "zero_bin"),
]


@pytest.mark.parametrize("overrides,key", BAD, ids=[k for _, k in BAD])
def test_bad_value_names_its_key(overrides, key):
    with pytest.raises(Exception) as e:
        validate(merged(overrides), SCHEMA)
    assert f"'{key}'" in str(e.value), str(e.value)


# --- the real workflow: snakemake -n ------------------------------------------------------


@pytest.fixture(scope="module")
def workflow_copy(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("workflow")
    shutil.copy(REPO / "Snakefile", root / "Snakefile")
    for d in ("rules", "config", "profiles"):
        shutil.copytree(REPO / d, root / d)
    return root


def dry_run(root: Path, *args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{REPO / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    snakemake = shutil.which("snakemake", path=env["PATH"])
    assert snakemake, "snakemake not on PATH"
    return subprocess.run(
        [snakemake, "-n", *args],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_dry_run_default(workflow_copy):
    r = dry_run(workflow_copy)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "rig" in r.stdout + r.stderr


def test_dry_run_bad_config_argument(workflow_copy):
    r = dry_run(workflow_copy, "--config", "rig={n_locations: 0}")
    out = r.stdout + r.stderr
    assert r.returncode != 0, out
    assert "n_locations" in out, out


def test_dry_run_leaves_out_a_model_set_to_null(workflow_copy, tmp_path):
    path = tmp_path / "no_mlp.yaml"
    path.write_text(yaml.safe_dump({"train": {"models": {"mlp": None}}}))
    r = dry_run(workflow_copy, "results/table2.csv", "--configfile", str(path))
    out = r.stdout + r.stderr
    assert r.returncode == 0, out
    assert "cnn1d_location" in out and "mlp_" not in out


@pytest.mark.parametrize(
    "preset,key",
    [
        ({"rig": {"n_locations": 0}}, "n_locations"),
        ({"objects": ["A", "zeppelin"]}, "zeppelin"),
        ({"train": {"benchmark_model": "resnet"}}, "train.benchmark_model: 'resnet' is not a registered model"),
        (
            {"train": {"models": {"tof": {"factory": "examples.no_such_model:tof", **{t: HYPER for t in ("location", "shape", "size")}}}}},
            "train.models.tof.factory",
        ),
    ],
    ids=["n_locations", "unknown-object", "unknown-benchmark-model", "unresolved-factory"],
)
def test_dry_run_bad_preset(workflow_copy, tmp_path, preset, key):
    # (each run costs ~2 s of Snakemake start-up; the other bad values are covered in-process above)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(preset))
    r = dry_run(workflow_copy, "--configfile", str(path))
    out = r.stdout + r.stderr
    assert r.returncode != 0, out
    assert key in out, out
