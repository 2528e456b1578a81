"""End to end: the real DAG on the tiny preset."""

import json
import re
import shutil

import numpy as np
import pandas as pd
import pytest

from denali_pipe.capture_sets import expected_sets
from denali_pipe.geometry import select_locations
from denali_pipe.io.store import open_set
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


def test_stores_index_and_table4(tiny_run):
    cfg = tiny_config(tiny_run)
    sets = expected_sets(load_catalogue(tiny_run / "config/objects.tsv"), cfg)
    n_loc, reps = cfg["rig"]["n_locations"], cfg["rig"]["repeats"]
    captures = pd.read_parquet(tiny_run / "results/index/captures.parquet")
    assert len(captures) == len(sets) * n_loc * reps
    assert sorted(captures.set.unique()) == sorted(s.name for s in sets)
    store = open_set(tiny_run / "results/store/circle_8inch_3x3_lighton.zarr")
    raw = tiny_run / "data/raw/circle_8inch_3x3_lighton_NLOSdata/spad_histogram"
    assert np.array_equal(store.histogram(0), np.load(raw / "000.npy"))
    t4 = pd.read_csv(tiny_run / "results/table4.csv").set_index("modality")
    assert list(t4.index) == ["lidar_histograms", "tracking_rgb", "tracking_depth", "colocated_rgb", "colocated_depth", "metadata", "total"]
    assert t4.loc["total", "total_bytes"] == t4.drop("total").total_bytes.sum()
    assert t4.loc["tracking_rgb", "size_3x3_bytes"] > t4.loc["lidar_histograms", "size_3x3_bytes"] > 0
    assert t4.loc["total", "paper_total_gb"] == pytest.approx(96.5, abs=0.02)


def test_new_object_reruns_only_its_own_jobs(tiny_run, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(tiny_run, wd, symlinks=True)
    with open(wd / "config/objects.tsv", "a") as f:
        f.write("newplus\tplus\tshape\t4inch,8inch\tbase\tretroreflective\t\n")
    preset = wd / "config/presets/tiny.yaml"
    preset.write_text(preset.read_text().replace("generalization1white]", "generalization1white, newplus]"))
    out = snakemake(wd, "-n", *TINY).stdout
    jobs = {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, re.M)}
    assert jobs == {"rig": 2, "ingest": 8, "poses": 8, "index": 1, "table4": 1, "calibrate": 1, "all": 1, "total": 22}
    assert sorted(re.findall(r"wildcards: object=(\w+), size=(\w+)", out)) == [("newplus", "4inch"), ("newplus", "8inch")]
    assert {m for m in re.findall(r"wildcards: set=(\w+)", out)} == {
        f"newplus_{size}_{res}_{light}" for size in ("4inch", "8inch") for res in ("3x3", "8x8") for light in ("lighton", "lightoff")
    }


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


def test_bad_set_fails_alone_with_keep_going(tiny_run, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(tiny_run, wd, symlinks=True)
    bad, good = "A_4inch_3x3_lighton", "A_8inch_3x3_lighton"
    npy = wd / f"data/raw/{bad}_NLOSdata/spad_histogram/000.npy"
    npy.write_bytes(npy.read_bytes()[:100])  # truncated
    for s in (bad, good):
        shutil.rmtree(wd / f"results/store/{s}.zarr")
    (wd / "results/table4.csv").unlink()  # Snakemake leaves deleted intermediates alone otherwise
    # targets first: --configfile takes every word that follows it
    proc = snakemake(wd, "results/table4.csv", "--cores", "2", "--keep-going", *TINY, check=False)
    assert proc.returncode != 0
    assert (wd / f"results/store/{good}.zarr").is_dir()  # the other set still ingests
    assert not (wd / f"results/store/{bad}.zarr").exists()
    assert not any(p.name.startswith(".") for p in (wd / "results/store").iterdir())  # nothing half-written
    log = (wd / f"logs/ingest/{bad}.log").read_text()
    assert str(npy.relative_to(wd)) in log and bad in log


def test_poses_match_the_rig_truth(tiny_run):
    truth = json.loads((tiny_run / "data/raw/circle_8inch_3x3_lighton_NLOSdata/rig_truth.json").read_text())
    t6 = pd.read_csv(tiny_run / "results/table6.csv").set_index("tag_id")
    for tag, pose in truth["static_tags"].items():
        est = t6.loc[int(tag), ["x_mean_cm", "y_mean_cm", "z_mean_cm"]].to_numpy(float) / 100
        assert np.linalg.norm(est - np.array(pose["t"])) < 0.002, f"tag {tag}"
    pos = pd.read_parquet(tiny_run / "results/calibration/tag1_positions.parquet").set_index("location")
    for k, rec in truth["locations"].items():
        err = pos.loc[int(k), ["x", "y", "z"]].to_numpy(float) - np.array(rec["tag1"]["t"])
        assert np.linalg.norm(err) < 0.003, f"location {k}: {err}"
    scene = json.loads((tiny_run / "results/calibration/scene.json").read_text())
    assert set(map(int, scene["locations"])) == set(map(int, truth["locations"]))
    det = pd.read_csv(tiny_run / "results/calibration/detections.csv")
    assert set(det.light) == {"lighton", "lightoff"}
    assert (tiny_run / "results/fig12.png").stat().st_size > 10_000
