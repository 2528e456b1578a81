"""End to end: the real DAG on the tiny preset."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from denali_pipe.capture_sets import expected_sets
from denali_pipe.geometry import select_locations
from denali_pipe.objects import load_catalogue

from workflow import copy_workflow, snakemake

pytestmark = pytest.mark.e2e
TINY = ("--configfile", "config/presets/tiny.yaml")


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    wd = copy_workflow(tmp_path_factory.mktemp("tiny"))
    snakemake(wd, "--cores", "2", *TINY)
    return wd


def tiny_config(wd):
    import yaml

    cfg = yaml.safe_load((wd / "config/config.yaml").read_text())
    tiny = yaml.safe_load((wd / "config/presets/tiny.yaml").read_text())
    cfg["objects"] = tiny["objects"]
    cfg["rig"]["n_locations"] = tiny["rig"]["n_locations"]
    return cfg


def test_every_capture_set_is_written(tiny_run):
    cfg = tiny_config(tiny_run)
    sets = expected_sets(load_catalogue(tiny_run / "config/objects.tsv"), cfg)
    raw = tiny_run / "data/raw"
    assert sorted(p.name for p in raw.iterdir()) == sorted(f"{s.name}_NLOSdata" for s in sets)
    names = [f"{k:03d}.npy" for k in select_locations(cfg["rig"]["n_locations"])]
    for s in sets:
        d = raw / f"{s.name}_NLOSdata"
        assert sorted(p.name for p in (d / "spad_histogram").iterdir()) == names
        meta = json.loads((d / "metadata.json").read_text())
        assert (meta["object"], meta["size"], meta["spad_res"], meta["light"]) == (s.object, s.size, s.resolution, s.light)
        h = np.load(d / "spad_histogram" / names[0])
        assert h.dtype == np.int32 and h.shape == (3, s.n_zones, s.n_zones, 128)
    assert (tiny_run / "logs/rig/circle_8inch.log").exists()


def test_nothing_left_to_do(tiny_run):
    out = snakemake(tiny_run, "-n", *TINY).stdout
    assert "Nothing to be done" in out


def test_rig_examples_show_the_bump(tiny_run):
    assert (tiny_run / "results/rig_examples.png").stat().st_size > 10_000
    df = pd.read_csv(tiny_run / "results/rig_examples.csv")
    three = df[df.set.str.contains("_3x3_")]
    assert len(three) == 3 * 128
    # the object's return shows up where geometry puts it, and not elsewhere after the wall peak
    inside = three[three.in_predicted_window].difference.mean()
    outside = three[~three.in_predicted_window & (three.bin > 80)].difference.mean()
    assert inside > 10 and inside > outside + 10


def test_paper_preset_dag_builds(tiny_run):
    out = snakemake(tiny_run, "-n", "--quiet", "rules", "--configfile", "config/presets/paper.yaml").stdout
    counts = {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, re.M)}
    # one rig job per object x size (67) plus the two background kinds
    assert counts["rig"] == 30 * 2 + 3 + 2 * 2 + 2
    assert counts["total"] < 2000
