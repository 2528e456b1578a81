"""End to end: the real DAG on the tiny preset."""

import json
import re
import shutil
import time

import browser
import numpy as np
import pandas as pd
import pytest
import torch
from workflow import copy_workflow, job_counts, snakemake

from denali_pipe.cli.warm_start import worker_usage
from denali_pipe.core.capture_sets import expected_sets
from denali_pipe.core.geometry import select_locations
from denali_pipe.core.objects import load_catalogue
from denali_pipe.experiments.fig9 import CAPPED, CONTROL, MEAN_BASELINE
from denali_pipe.experiments.generalisation import MODEL
from denali_pipe.io.store import open_set
from denali_pipe.train.conditions import TABLES as CONDITION_TABLES
from denali_pipe.train.conditions import table_conditions
from denali_pipe.transforms.sim_to_real import FIDELITIES
from denali_pipe.twin.calibrate import EMISSION
from denali_pipe.twin.render import read_twin

pytestmark = pytest.mark.e2e
TINY = ("--configfile", "config/presets/tiny.yaml")
TARGETS = ("results/render_benchmark.png", "results/fig18.png")


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
    assert (tiny_run / "logs/rig/circle_8inch_3x3.log").exists() and (tiny_run / "logs/rig/circle_8inch_8x8.log").exists()


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


# Outputs of one set or one object (and the calibration, which reads the
# background sets only): adding an object must leave every one of them alone.
PER_SET_OUTPUTS = ("data/raw", "results/store", "results/index", "results/poses", "results/features", "results/twin", "results/calibration")
AGGREGATES_AMONG_THEM = {"results/index/captures.parquet", "results/calibration/detections.csv"}


def file_states(wd):
    """{relative path: (sha256, mtime_ns)} of every per-set, per-object and calibration file."""
    import hashlib

    states = {}
    for root in PER_SET_OUTPUTS:
        for path in sorted((wd / root).rglob("*")):
            if path.is_file() and str(path.relative_to(wd)) not in AGGREGATES_AMONG_THEM:
                states[str(path.relative_to(wd))] = (hashlib.sha256(path.read_bytes()).hexdigest(), path.stat().st_mtime_ns)
    return states


def test_new_object_reruns_only_its_own_jobs(tiny_run, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(tiny_run, wd, symlinks=True)
    before = file_states(wd)
    with open(wd / "config/objects.tsv", "a") as f:
        f.write("newplus\tplus\tshape\t4inch\tbase\tretroreflective\t\n")
    preset = wd / "config/presets/tiny.yaml"
    objects = preset.read_text().replace("generalization1italic]", "generalization1italic, newplus]")
    assert "newplus" in objects
    preset.write_text(objects)
    out = snakemake(wd, "-n", *TINY).stdout
    jobs = job_counts(out)
    # the new object, one size (its second would only double these): 2 resolutions x 2 lightings (preprocessed at both: Fig 14
    # trains at 8x8); a twin per object x size
    own = {"rig": 2, "ingest": 4, "poses": 4, "preprocess": 4, "twin": 1}
    # (the variant datasets read the objects sheet like the benchmark's: rebuilt, with the same content)
    aggregates = {"index": 1, "table4": 1, "table6": 1, "detections": 1, "dataset": 2, "variant_dataset": 2, "render_benchmark": 1, "fig18": 1}
    # the twin's calibration reads every training capture, so every calibrated twin follows it (9 + the new 1)
    aggregates |= {"twin_calibration": 1, "twin_calibrated": 10, "transforms": 1, "fig9": 1, "all": 1}
    # every training cell reads its dataset; tiny: 1 seed, 13 Table 5 cells + 9 more Table 2 cells + 3 linear + Fig 14's 8x8 shape cell,
    # 10 conditioned cells of Tables 7-9 (their baselines are Table 5's) and 3 of the jitter sweep
    training = {"train": 39, "table5": 1, "table2": 1, "table10": 1, "training_curves": 2, "speed_vs_accuracy": 1, "condition_table": 3, "jitter": 1}
    # ... and the stability report reads them all, with the transforms and the twin's calibration
    training["stability"] = 1
    # the retrained cells are scored on the variant datasets again (5 evaluations)
    experiments = {"evaluate": 5, "fig10": 1, "fig11": 1, "tsne": 2}
    # the release's networks score the raw-count datasets of the base and variant sets again, and rig_vs_real shows them
    experiments |= {"paper_dataset": 3, "release_models": 1, "rig_vs_real": 1}
    expected = {**own, **aggregates, **training, **experiments}
    assert jobs == {**expected, "total": sum(expected.values())}
    rig_jobs = re.findall(r"rule rig:\n    output: data/raw/(\w+?)_(4inch|8inch)_(3x3|8x8)_", out)
    assert sorted(rig_jobs) == [("newplus", "4inch", res) for res in ("3x3", "8x8")]
    assert sorted(re.findall(r"output: results/twin/(\w+)\.zarr", out)) == ["newplus_4inch"]
    new_sets = {f"newplus_4inch_{res}_{light}" for res in ("3x3", "8x8") for light in ("lighton", "lightoff")}
    assert {m for m in re.findall(r"wildcards: set=(\w+)", out)} == new_sets
    # Built up to the per-set and per-object outputs only (named as targets:
    # `--until <rules>` stalls after the rig, snakemake/snakemake#823): the
    # retrained cells and the tables after them are the jobs the tiny run already ran.
    targets = [f"results/{kind}/{name}.{ext}" for name in sorted(new_sets) for kind, ext in (("features", "zarr"), ("poses", "parquet"))]
    targets += ["results/twin/newplus_4inch.zarr", "results/calibration/detections.csv"]
    snakemake(wd, *targets, "--cores", "2", *TINY)
    after = file_states(wd)
    # every old per-set and per-object output is byte-identical and untouched (same mtime)
    assert {k: after.get(k) for k in before} == before
    added = {k.split("/")[2].split(".")[0] for k in set(after) - set(before) if k.count("/") >= 2}
    assert added and all(name.startswith("newplus_") for name in added), sorted(added)
    left = {rule: n for rule, n in expected.items() if rule not in own and rule != "detections"}
    assert job_counts(snakemake(wd, "-n", *TINY).stdout) == {**left, "total": sum(left.values())}


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


def test_rig_vs_real_measures_the_centre_zone(tiny_run):
    df = pd.read_csv(tiny_run / "results/rig_vs_real.csv")
    rig = df[df.source == "capture source"]
    # tiny: circle (the first base shape) at both sizes, both lightings, beside three real figures
    assert sorted(rig.set) == sorted(f"circle_{size}_3x3_{light}" for size in ("4inch", "8inch") for light in ("lighton", "lightoff"))
    assert df.source.str.startswith("real (").sum() == 3
    # every zone's mean counts beside REFERENCE Part 5's
    zones = df[df.source == "capture source, every zone"]
    assert len(zones) == 9 and zones.mean_counts.gt(0).all() and zones.real_mean_counts.notna().all()
    off = rig.set_index("set")
    big, small = off.loc["circle_8inch_3x3_lightoff"], off.loc["circle_4inch_3x3_lightoff"]
    assert 0.01 < big.floor_fraction < 0.1 and big.late_over_floor < 1
    assert big.bump_excess > small.bump_excess > 0
    assert (tiny_run / "results/rig_vs_real.png").stat().st_size > 10_000


def test_the_sensor_fit_says_where_no_real_captures_were_found(tiny_run):
    # the scratch copy has no ../shared beside it: the target completes and says why nothing was fitted
    body = json.loads((tiny_run / "results/sensor_fit.json").read_text())
    assert body["status"].startswith("no real captures") and "real-tmf8820" in body["source"]
    assert (tiny_run / "results/sensor_fit.png").stat().st_size > 1_000
    # and the test on real scenes, which needs the fit, says so in its table and figure
    scenes = pd.read_csv(tiny_run / "results/sensor_vs_real.csv")
    assert list(scenes.columns) == ["status"] and scenes.status.iloc[0].startswith("no fitted sensor")
    assert (tiny_run / "results/sensor_vs_real.png").stat().st_size > 1_000


def test_the_release_networks_say_why_they_were_not_scored(tiny_run):
    # the scratch copy has no ../shared beside it and the tiny preset downloads nothing: each network's row says so
    df = pd.read_csv(tiny_run / "results/release_models.csv")
    assert len(df) == 15 and (df.n_samples == 0).all()
    assert df.note.str.contains("no local copy at ../shared/denali-release, and downloads are off").all()


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


def test_training_tables_and_figures(tiny_run):
    t5 = pd.read_csv(tiny_run / "results/table5.csv", keep_default_na=False).set_index("split")
    assert list(t5.index) == ["random", "repeats_grouped", "location_held_out", "shape_held_out", "size_held_out"]
    assert t5.loc["shape_held_out", "shape_top1"] == "n/a" and t5.loc["size_held_out", "size_accuracy"] == "n/a"
    # tiny trains 3 epochs: a check of the path, not of the numbers. The labels
    # sit ~1 m from the origin where an untrained localiser starts, so a
    # finite RMSE under the table's 2 m span is all it can promise.
    assert 0 < float(t5.loc["random", "loc_rmse"]) < 2.0 and 0 <= float(t5.loc["random", "size_accuracy"]) <= 1
    assert set(t5["protocol"]) == {"clean"}
    t2 = pd.read_csv(tiny_run / "results/table2.csv").set_index("model")
    assert list(t2.index) == ["mlp", "cnn1d", "cnn3d", "transformer"]
    t10 = pd.read_csv(tiny_run / "results/table10.csv").set_index(["model", "task"])
    assert t10.loc[("cnn1d", "location"), "params"] == 82340  # the paper's count: the 1D CNN does not depend on the bins
    assert len(t10) == 12 and (t10["train_hours"] > 0).all()
    for fig in ("fig16", "fig17", "speed_vs_accuracy"):
        assert (tiny_run / f"results/{fig}.png").stat().st_size > 10_000 and (tiny_run / f"results/{fig}.csv").exists()
    run = tiny_run / "results/runs/clean/3x3/all/random/cnn1d_location/seed42"
    assert {p.name for p in run.iterdir()} == {"metrics.json", "curves.csv", "model.pt"}
    m = json.loads((run / "metrics.json").read_text())
    assert m["cell"]["protocol"] == "clean" and m["cell"]["condition"] == "all"
    assert m["selected_on"] == "validation" and m["train_samples_per_second"] > 0
    crop = json.loads((tiny_run / "results/features/crop_3x3.json").read_text())["crop_start"]
    assert m["input_shape"] == [3, 3, 128 - crop]


def test_condition_tables(tiny_run):
    t5 = pd.read_csv(tiny_run / "results/table5.csv").set_index("split")
    for name in CONDITION_TABLES:
        task, conditions = table_conditions(name, ["object_type", "location"])
        t = pd.read_csv(tiny_run / f"results/{name}.csv", keep_default_na=False)
        # tiny: 3x3 only, one seed, two groups; every condition has two classes of each task (1, A, circle at both sizes)
        assert list(t.condition) == conditions and set(t.resolution) == {"3x3"} and (t.n_seeds == 1).all()
        assert (t.condition_group.iloc[1:] != "baseline").all() and set(t.protocol) == {"clean"}
        assert (t.filter(like="paper_") == "").all().all()  # the paper published 8x8 only
        base = t.set_index("condition").loc["all"]
        assert (t.n_train.iloc[1:] < base.n_train).all()  # a condition keeps part of the samples
        headline = {"shape": "shape_top1", "size": "size_accuracy", "location": "loc_rmse"}[task]
        assert float(base[headline]) == pytest.approx(float(t5.loc["random", headline]), abs=1e-4)  # Table 5's cells
    cell = json.loads((tiny_run / "results/runs/clean/3x3/front_quadrant/random/cnn1d_shape/seed42/metrics.json").read_text())
    # tiny's 12 locations put 3 in each quadrant: 3 objects x 2 sizes x 2 lightings x 3 repeats each
    assert cell["cell"]["condition"] == "front_quadrant" and cell["n_train"] + cell["n_validation"] + cell["n_test"] == 3 * 3 * 2 * 2 * 3


def test_jitter_sweep(tiny_run):
    curve = pd.read_csv(tiny_run / "results/jitter.csv")
    assert set(curve.fwhm_ps) == {100} and set(curve.task) == {"location", "shape", "size"} and len(curve) == 8
    assert (curve.n_seeds == 1).all() and curve.trivial.notna().all()
    assert (tiny_run / "results/jitter.png").stat().st_size > 10_000
    crop = json.loads((tiny_run / "results/features/crop_3x3.json").read_text())["crop_start"]
    cell = json.loads((tiny_run / "results/runs/clean/3x3/jitter100ps/random/cnn1d_size/seed42/metrics.json").read_text())
    # the light-on half of the samples, the centre zone only
    assert cell["input_shape"] == [1, 1, 128 - crop] and cell["n_train"] + cell["n_validation"] + cell["n_test"] == 3 * 2 * 12 * 3


def test_stability_report_reads_every_cell_the_fit_and_the_twin(tiny_run):
    """results/stability.csv: every failure mode over all the run's cells
    (every metrics.json under results/runs/), the transforms and the twin's
    calibration, counted as their own files say; Tables 5 and 9 show the
    share of predictions outside the workspace that the cells recorded."""
    from denali_pipe.report.stability import cell_id
    from denali_pipe.train.cell_metrics import CellMetrics

    cells = [CellMetrics.read(p) for p in sorted((tiny_run / "results/runs").rglob("metrics.json"))]
    assert len(cells) == 39
    table = pd.read_csv(tiny_run / "results/stability.csv", keep_default_na=False).set_index("failure")
    assert len(table) == 8 and (tiny_run / "results/stability.png").stat().st_size > 10_000
    located = [m for m in cells if m.cell.task == "location"]
    assert table.loc["diverged training", "count"] == 0 and table.loc["diverged training", "of"] == len(cells)
    assert table.loc["location outside the workspace", "of"] == table.loc["location worse than the mean", "of"] == len(located)
    outside = sorted(cell_id(m.cell) for m in located if m.test["outside_workspace"] > 0)
    assert sorted(w.split(" (")[0] for w in table.loc["location outside the workspace", "which"].split("; ") if w) == outside
    stopped = sorted(cell_id(m.cell) for m in cells if m.stopped_by_budget)
    assert sorted(w.split(" (")[0] for w in table.loc["training stopped by its budget", "which"].split("; ") if w) == stopped
    c = json.loads((tiny_run / "results/twin_calibration.json").read_text())
    assert table.loc["twin coordinate at its bound", "count"] == len(c["at_bound"])
    assert table.loc["twin coordinate at its bound", "of"] == sum(np.size(v) for v in c["parameters"].values())
    assert table.loc["twin calibration stopped by its budget", "count"] == (0 if c["fit"]["converged"] else 1)
    t = json.loads((tiny_run / "results/transforms.json").read_text())
    assert table.loc["sim-to-real transforms unidentified", "of"] == (1 if t["mode"] == "shared" else 9)
    t5 = pd.read_csv(tiny_run / "results/table5.csv").set_index("split")
    random_cell = json.loads((tiny_run / "results/runs/clean/3x3/all/random/cnn1d_location/seed42/metrics.json").read_text())
    assert t5.loc["random", "loc_outside_workspace"] == pytest.approx(random_cell["test"]["outside_workspace"], abs=1e-4)
    assert pd.read_csv(tiny_run / "results/table9.csv")["loc_outside_workspace"].between(0, 1).all()


def test_changing_one_models_hyperparameters_reruns_only_its_cells_and_tables(tiny_run, tmp_path):
    cfg = tmp_path / "lr.yaml"
    cfg.write_text("train:\n  models:\n    mlp:\n      location: {lr: 0.002}\n")
    out = snakemake(tiny_run, "-n", "--configfile", "config/presets/tiny.yaml", str(cfg)).stdout
    jobs = job_counts(out)
    assert jobs == {"train": 1, "table2": 1, "table10": 1, "speed_vs_accuracy": 1, "stability": 1, "all": 1, "total": 6}
    assert "mlp_location" in out


def test_the_example_model_runs_through_table5_and_joins_the_benchmark(tiny_run, tmp_path):
    """examples/tof.yaml registers a model outside the package and makes it
    the benchmark model: Table 5 trains its cells from the tiny run's
    datasets; Tables 2 and 10 add its random-split cells beside the
    paper's four; the explorer offers it."""
    from denali_pipe.explore.outputs import scan

    wd = tmp_path / "wd"
    shutil.copytree(tiny_run, wd, symlinks=True)
    example = (*TINY, "examples/tof.yaml")
    jobs = job_counts(snakemake(wd, "-n", "results/table5.csv", *example).stdout)
    assert jobs == {"train": 13, "table5": 1, "total": 14}  # 5 splits x 3 tasks less the 2 ill-posed; nothing upstream
    snakemake(wd, "--cores", "2", "results/table5.csv", *example)
    t5 = pd.read_csv(wd / "results/table5.csv", keep_default_na=False).set_index("split")
    assert set(t5["model"]) == {"tof"} and list(t5.index) == ["random", "repeats_grouped", "location_held_out", "shape_held_out", "size_held_out"]
    assert 0 < float(t5.loc["random", "loc_rmse"]) < 2.0 and 0 <= float(t5.loc["random", "shape_top1"]) <= 1
    m = json.loads((wd / "results/runs/clean/3x3/all/random/tof_shape/seed42/metrics.json").read_text())
    assert m["params"] < 20_000 and m["flops"] > 0
    # its random-split cells are Table 5's: Tables 2 and 10 only add them to the paper's four
    assert job_counts(snakemake(wd, "-n", "results/table2.csv", "results/table10.csv", *example).stdout) == {"table2": 1, "table10": 1, "total": 2}
    assert "tof" in {c.model for c in scan(wd / "results").choices("3x3")}


def test_predict_and_export_a_tiny_capture_as_training_saw_it(tiny_run, tmp_path, capsys):
    """`denali predict` on a release file of the tiny run answers what the
    cells answer for the dataset's rows of that capture (the same
    preprocessing, averaged over the repeats); `denali export` of the shape
    cell gives its logits."""
    from denali_pipe.cli import main
    from denali_pipe.train.dataset import read_dataset
    from denali_pipe.train.evaluate import load_cell, predict
    from denali_pipe.train.export import load_export
    from denali_pipe.train.predict import softmax

    results = tiny_run / "results"
    x, samples, _ = read_dataset(results / "datasets/3x3.zarr", results / "datasets/3x3.parquet")
    set_name = "circle_8inch_3x3_lighton"
    location = int(samples[samples.set == set_name].location.iloc[len(samples[samples.set == set_name]) // 2])
    rows = samples.index[(samples.set == set_name) & (samples.location == location)]
    runs = [results / f"runs/clean/3x3/all/random/cnn1d_{task}/seed42" for task in ("location", "shape", "size")]
    capture = tiny_run / f"data/raw/{set_name}_NLOSdata/spad_histogram/{location:03d}.npy"
    background = tiny_run / "data/raw/NOOBJECT_8inch_3x3_lighton_NLOSdata"
    args = [*map(str, runs), str(capture), "--background", str(background), "--crop", str(results / "features/crop_3x3.json")]
    assert main(["predict", *args]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["gantry_location"] == location and out["repeats"] == list(range(len(rows)))
    xy = predict(load_cell(runs[0]), x[rows]).mean(axis=0)
    assert (out["location"]["x_m"], out["location"]["y_m"]) == pytest.approx(tuple(xy), abs=1e-5)
    shape = load_cell(runs[1])
    p = softmax(predict(shape, x[rows])).mean(axis=0)
    assert [(c["class"], c["probability"]) for c in out["shape"]["top5"]] == [
        (shape.classes[i], pytest.approx(float(p[i]), abs=1e-5)) for i in np.argsort(-p)[:5]
    ]
    assert out["size"]["class"] in ("4inch", "8inch")
    assert main(["export", str(runs[1]), str(tmp_path / "shape.pt2")]) == 0
    module, meta = load_export(tmp_path / "shape.pt2")
    with torch.no_grad():
        logits = module(torch.from_numpy(x[rows])).numpy()
    np.testing.assert_allclose(logits, predict(shape, x[rows]), rtol=1e-4, atol=1e-4)
    assert meta["classes"] == shape.classes


def test_training_cells_request_the_configured_gpus_at_their_speedup(tiny_run, tmp_path):
    """A cell on a GPU asks for its CPU runtime over its network's
    `cluster.gpu_speedup` (here 0.1, so ten times the CPU request)."""
    cell = "results/runs/clean/3x3/all/random/cnn1d_location/seed42/metrics.json"
    (tmp_path / "cpu.yaml").write_text("cluster:\n  min_runtime_min: 1\n")
    (tmp_path / "gpu.yaml").write_text("train:\n  gpus: 1\ncluster:\n  gpu_speedup: {default: 10, cnn1d: 0.1}\n")
    runtime = {}
    for extra, gpus in (((), 0), (("gpu.yaml",), 1)):
        configs = [str(tmp_path / f) for f in ("cpu.yaml", *extra)]
        out = snakemake(tiny_run, "-n", "--force", cell, "--configfile", "config/presets/tiny.yaml", *configs).stdout
        train = re.search(r"rule train:\n(?:\s+.*\n)*?\s+resources: (.*)", out)[1]
        assert re.search(rf"\bgpu={gpus}\b", train), out[-2000:]
        runtime[gpus] = int(re.search(r"\bruntime=(\d+)", train)[1])
    assert 10 * (runtime[0] - 1) < runtime[1] <= 10 * runtime[0]
    linear = cell.replace("cnn1d_", "linear_")  # fits in closed form on the CPU
    out = snakemake(tiny_run, "-n", "--force", linear, "--configfile", "config/presets/tiny.yaml", str(tmp_path / "gpu.yaml")).stdout
    assert re.search(r"rule train:\n(?:\s+.*\n)*?\s+resources: .*\bgpu=0\b", out), out[-2000:]


# --- digital twins ---------------------------------------------------------------


def test_benchmark_table_and_figure(tiny_run):
    df = pd.read_csv(tiny_run / "results/render_benchmark.csv").set_index("configuration")
    assert list(df.index) == ["paper", "paper, footprint pixels", "footprint 100", "footprint 1k", "footprint 5k", "analytic"]
    assert (df.n_scenes == 4).all() and df.loc["paper", "spp"] == 500
    assert df.loc["analytic", "error_nl2"] < 0.03
    assert df.loc["analytic", "time_per_scene_s"] < df.loc["paper", "time_per_scene_s"]
    assert (tiny_run / "results/render_benchmark.png").stat().st_size > 10_000


def test_fig18_and_the_twins_it_uses(tiny_run):
    data = pd.read_csv(tiny_run / "results/fig18.csv")
    assert data.groupby(["set", "location"]).size().tolist() == [9 * 128, 9 * 128]  # every zone of each capture
    assert data.twin_counts.max() > 0
    assert (tiny_run / "results/fig18.png").stat().st_size > 50_000
    twins = sorted((tiny_run / "results/twin").glob("*.zarr"))
    assert twins
    for path in twins:
        t = read_twin(path)
        # the grid every reader of a twin reads, and no other
        assert set(t.histograms) == {"3x3"} and t.histograms["3x3"].shape == (12, 3, 3, 128)
        assert (t.histograms["3x3"].sum(axis=-1) > 0).any(axis=(1, 2)).all()
        name = path.name.removesuffix(".zarr")
        # a warm job's benchmark sampled its client: its worker logged its own peak
        usage = worker_usage((tiny_run / f"logs/twin/{name}.log").read_text())
        peak = usage["max_rss_mb"] if usage else pd.read_csv(tiny_run / f"benchmarks/twin/{name}.tsv", sep="\t").max_rss.max()
        assert 100 < peak < 2000  # MB per job


def test_renderer_settings_rerun_only_what_uses_them(tiny_run, tmp_path):
    wd = tmp_path / "wd"
    shutil.copytree(tiny_run, wd, symlinks=True)
    preset = wd / "config/presets/tiny.yaml"
    text = preset.read_text()
    # the analytic twins do not use mitransient's spp; the benchmark does
    preset.write_text(text.replace("twin:\n", "twin:\n  mitransient:\n    spp: 1234\n"))
    out = snakemake(wd, "-n", *TARGETS, *TINY).stdout
    jobs = job_counts(out)
    assert jobs == {"render_benchmark": 1, "total": 1}
    # the object albedo changes every twin and the calibration, so Fig 18 too (it draws calibrated twins)
    preset.write_text(text.replace("twin:\n", "twin:\n  object_albedo: 0.6\n"))
    out = snakemake(wd, "-n", *TARGETS, *TINY).stdout
    jobs = job_counts(out)
    assert jobs["twin_calibration"] == 1 and jobs["twin_calibrated"] == 2 and jobs["fig18"] == 1 and jobs["render_benchmark"] == 1


def test_twin_calibration(tiny_run):
    c = json.loads((tiny_run / "results/twin_calibration.json").read_text())
    assert np.shape(c["parameters"]["scale"]) == (3, 3) and set(c["se"]) == set(c["parameters"])
    for k, v in c["parameters"].items():  # every interval holds its estimate; the rest is flagged, not hidden
        lo, hi = np.moveaxis(np.asarray(c["interval"][k]), -1, 0)
        assert (lo <= np.asarray(v) + 1e-12).all() and (np.asarray(v) <= hi + 1e-12).all(), k
    names = {f"{k}[{r}, {q}]" for k in ("offset_u", "offset_v", "scale") for r in range(3) for q in range(3)} | set(c["parameters"])
    assert set(c["not_identified"]) <= names and set(c["at_bound"]) <= names
    # the tiny preset's object is retroreflective, lit by the flood: no lobe width (its narrow limit), the emission's flood and core
    assert {"time_offset", "diffuse_share", *EMISSION} <= set(c["parameters"]) and "lobe_width_deg" not in c["parameters"]
    assert c["illumination"] == "flood"
    before, after = np.array(c["residual"]["before"]["nl2"]), np.array(c["residual"]["after"]["nl2"])
    assert before.shape == after.shape == (3, 3) and after.mean() < before.mean()
    noise = np.array(c["residual"]["after"]["nl2_noise"])  # what the noise alone leaves: no twin scores far below it
    assert noise.shape == (3, 3) and (noise > 0).all() and (after > 0.8 * noise).all()
    net, interval = np.array(c["residual"]["after"]["nl2_net"], float), np.array(c["residual"]["after"]["nl2_net_interval"], float)
    finite = np.isfinite(net)  # nan where a zone's noise holds all of its captures
    below = finite & (after <= 1)  # there taking the noise's share out of both norms lowers the ratio
    assert finite.any() and (net[below] <= after[below] + 1e-12).all()
    assert (interval[finite, 0] <= net[finite]).all() and (net[finite] <= interval[finite, 1]).all()
    assert c["n_test_excluded"] > 0 and (tiny_run / "results/twin_calibration.png").stat().st_size > 10_000
    assert 0 < c["fit"]["evaluations"] <= 20  # the tiny preset's budget
    twins = sorted((tiny_run / "results/twin_calibrated").glob("*.zarr"))
    assert len(twins) == 9 and all(read_twin(p).attrs["calibration"]["sha256"] for p in twins)
    p = c["parameters"]
    emission = {"hwhm_deg": [p["beam_hwhm_h_deg"], p["beam_hwhm_v_deg"]], "core_share": p["core_share"], "core_hwhm_deg": p["core_hwhm_deg"]}
    assert all(read_twin(t).attrs["emission"] == emission for t in twins)


def test_transforms_and_fig9(tiny_run):
    t = json.loads((tiny_run / "results/transforms.json").read_text())
    assert t["mode"] in ("shared", "per_zone") and len(t["zones"]) == 9 and set(t["mode_residual"]) | set(t["mode_rejected"]) == {"shared", "per_zone"}
    for z in t["zones"]:
        assert z["a"] > 0 and z["a_noise"] >= 1 and z["b_noise"] >= 0 and z["offset_sd"] >= 0 and np.isfinite(z["offset_mean"])
        assert len(z["kernel"]) == t["kernel_bins"] == 11 and abs(sum(z["kernel"]) - 1) < 1e-6
    fig9 = pd.read_csv(tiny_run / "results/fig9.csv")
    assert set(fig9["fidelity"]) == {*FIDELITIES, CONTROL, MEAN_BASELINE} and len(FIDELITIES) == 4
    assert set(fig9["panel"]) == {"centre", "all_zones"} and fig9.loc[fig9["fidelity"].isin(FIDELITIES), "real_samples_saved"].notna().all()
    assert CAPPED in fig9.columns  # the real-sample counts each row stands in for, where capped
    assert (tiny_run / "results/fig9.png").stat().st_size > 10_000


# --- experiments: Figs 10, 11 (variant sets), 13, 14 (t-SNE) ------------------------


def test_variant_datasets_and_the_cells_scored_on_them(tiny_run):
    for variant, objects in (("nonrr", {"generalization1white"}), ("italic", {"generalization1italic"})):
        samples = pd.read_parquet(tiny_run / f"results/datasets/{variant}_3x3.parquet")
        assert set(samples["object"]) == objects and set(samples["class"]) == {"1"}
        for task in ("location", "shape", "size") if variant == "nonrr" else ("location", "shape"):
            e = json.loads((tiny_run / f"results/evaluations/{variant}_3x3/clean/3x3/all/random/cnn1d_{task}/seed42.json").read_text())
            assert e["n_samples"] == len(samples) and e["cell"]["task"] == task and e["metrics"] and e["baseline"]


def test_fig10_and_fig11(tiny_run):
    fig10 = pd.read_csv(tiny_run / "results/fig10.csv")
    scores = fig10[fig10["panel"] == "score"].set_index(["task", "data", "predictor"])
    assert set(scores.index.get_level_values("task")) == {"location", "shape", "size"}
    assert scores.loc[("shape", "any", "chance"), "value"] == pytest.approx(1 / 3)  # tiny's three base classes
    # 3 epochs: the path, not the numbers; every score a finite value in its metric's range
    assert 0 < scores.loc[("location", "non-RR sets", MODEL), "value"] < 2.0
    assert 0 <= scores.loc[("size", "non-RR sets", MODEL), "value"] <= 1 and (scores["n_seeds"].dropna() <= 1).all()
    hist = fig10[fig10["panel"] == "histogram"]
    assert set(hist["object"]) == {"generalization1white", "1"} and set(hist["size"]) == {"8inch"} and set(hist["light"]) == {"lightoff"}
    fig11 = pd.read_csv(tiny_run / "results/fig11.csv")
    assert set(fig11["task"]) == {"location", "shape"} and set(fig11["data"].dropna()) >= {"base test split", "italic sets"}
    for fig in ("fig10", "fig11"):
        assert (tiny_run / f"results/{fig}.png").stat().st_size > 10_000


def test_tsne_figures_at_both_resolutions(tiny_run):
    for fig, res in (("fig13", "3x3"), ("fig14", "8x8")):
        table = pd.read_csv(tiny_run / f"results/{fig}.csv")
        mean = table[table["row"] == "mean"].iloc[0]
        assert set(table["resolution"]) == {res} and mean["classes"] == "1 A circle" and mean["n_seeds"] == 1
        assert 0 <= mean["knn_accuracy"] <= 1 and -1 <= mean["silhouette"] <= 1
        assert (table["row"] == "point").sum() == table.loc[table["row"] == "seed", "n_samples"].sum() > 0
        assert (tiny_run / f"results/{fig}.png").stat().st_size > 10_000
    m = json.loads((tiny_run / "results/runs/clean/8x8/all/random/cnn1d_shape/seed42/metrics.json").read_text())
    assert m["input_shape"][:2] == [8, 8]


# --- the HTML report -------------------------------------------------------------


REPORTED = (
    "sensor_fit.png", "sensor_vs_real.png", "rig_examples.png", "rig_vs_real.png", "table4.csv", "table6.csv", "fig12.png", "detections.csv", "table5.csv", "table2.csv", "table10.csv",
    "fig16.png", "fig17.png", "speed_vs_accuracy.png", "render_benchmark.png", "twin_calibration.png", "fig18.png", "transforms.json", "fig9.png",
    "fig10.png", "fig11.png", "fig13.png", "fig14.png", "table7.csv", "table8.csv", "table9.csv", "jitter.png", "stability.png",
)  # fmt: skip


def test_report_has_every_table_and_figure_with_its_caption(tiny_run):
    proc = snakemake(tiny_run, "--report", "results/report.html", *TINY)
    added = re.findall(r"^Adding (\S+) \(", proc.stderr + proc.stdout, re.M)
    assert sorted(added) == sorted(REPORTED)
    # captions are reStructuredText rendered by docutils: a markup slip shows up as ERROR/WARNING
    assert not re.search(r"\((ERROR|WARNING)/\d\)", proc.stderr + proc.stdout)
    html = (tiny_run / "results/report.html").read_text()
    # every caption names the preset; the training ones name the protocol
    assert html.count('Preset <tt class=\\"docutils literal\\">tiny</tt>') == len(REPORTED)
    assert html.count('protocol <tt class=\\"docutils literal\\">clean</tt>') + html.count('Protocol <tt class=\\"docutils literal\\">clean</tt>') >= 10
    titles = ("Table 5: the 1D CNN under five train/test splits", "Figure 16: 1D CNN localisation", "Figure 17: 1D CNN shape", "Figure 9: localisation RMSE")
    experiments = ("Figure 10: non-retroreflective objects", "Figure 11: the italic", "Figure 13: 3x3", "Figure 14: 8x8")
    tables = (
        "Table 7: shape classification",
        "Table 8: size classification",
        "Table 9: localisation RMSE",
        "Timing-jitter sweep",
        "Where the run's methods fail",
    )
    for title in (*titles, *experiments, *tables):
        assert title in html


# --- the capture explorer ---------------------------------------------------------


def tree_state(root):
    """{relative path: (size, mtime_ns)} of everything under root."""
    return {str(p.relative_to(root)): (p.stat().st_size, p.stat().st_mtime_ns) for p in root.rglob("*")}


def _changed(driver, element_id, old, timeout=browser.WAIT_S):
    """Wait until an element's text differs from `old` and no callback is pending; its new text."""
    return browser.wait_for(
        driver,
        f"const e = document.getElementById(arguments[0]); return e.innerText !== arguments[1] && ({browser.IDLE}) && e.innerText;",
        element_id,
        old,
        timeout=timeout,
    )


def _timed(driver, action, element_id):
    """(seconds from the control change until the last panel is redrawn, as
    the browser's clock and Plotly's afterplot events tell; the element's new text)."""
    old = browser.text(driver, element_id)
    driver.execute_script(browser.ARM_REDRAWN_JS, list(browser.PANELS))
    action()
    new = _changed(driver, element_id, old)
    return browser.wait_for(driver, browser.REDRAWN_JS, list(browser.PANELS)) / 1000, new


def test_explorer_in_a_browser(tiny_run, tmp_path):
    """`denali explore` on the tiny run's outputs, driven in headless
    Chromium: changing object and location redraws the panels with the
    calibration's labels and the cells' own predictions; nothing under
    results/ is written."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.action_builder import ActionBuilder
    from selenium.webdriver.common.by import By

    from denali_pipe.poses.pnp import project
    from denali_pipe.train.dataset import read_dataset
    from denali_pipe.train.evaluate import load_cell, predict

    browser.ensure_chromium()
    results = tiny_run / "results"
    before = tree_state(results)
    x, samples, _ = read_dataset(results / "datasets/3x3.zarr", results / "datasets/3x3.parquet")
    labels = pd.read_parquet(results / "calibration/tag1_positions.parquet").set_index("location")
    camera = json.loads((results / "calibration/scene.json").read_text())["tracking_camera"]
    intr = camera["intrinsics"]
    K = np.array([[intr["fx"], 0, intr["cx"]], [0, intr["fy"], intr["cy"]], [0, 0, 1]])
    cells = {task: load_cell(results / f"runs/clean/3x3/all/random/cnn1d_{task}/seed42") for task in ("location", "shape", "size")}

    def expected(set_name, location):
        """What the cells predict for the set's capture (repeat 0, the page's default) and its label."""
        row = samples.index[(samples.set == set_name) & (samples.location == location) & (samples.repeat == 0)]
        assert len(row) == 1
        xi = x[row]
        shape, size = (c.classes[int(predict(c, xi)[0].argmax())] for c in (cells["shape"], cells["size"]))
        return predict(cells["location"], xi)[0], shape, size, labels.loc[location, ["x", "y", "z"]].to_numpy(float)

    def check_panels(set_name, location):
        xy, shape, size, truth = expected(set_name, location)
        assert browser.text(driver, "truth-location") == f"x {truth[0]:.4f} m, y {truth[1]:.4f} m"
        assert browser.text(driver, "pred-shape") == shape and browser.text(driver, "pred-size") == size
        grid = browser.figure(driver, "grid")["traces"]
        assert np.allclose([grid[f"ground truth (location {location})"][a][0] for a in "xy"], truth[:2], atol=1e-9)
        assert np.allclose([grid["prediction"][a][0] for a in "xy"], xy, atol=1e-6)
        frame = browser.figure(driver, "frame")
        assert f"location {location}" in frame["title"]
        uv = project(K, np.array(camera["R_world_to_camera"]), np.array(camera["t_world_to_camera"]), truth[None])[0]
        assert np.allclose([frame["traces"]["ground truth"][a][0] for a in "xy"], uv, atol=1e-6)
        bars = browser.figure(driver, "shape")
        assert bars["title"].startswith(f"Shape: predicted {shape}")

    shots = tmp_path / "screenshots"
    shots.mkdir()
    with browser.explorer(results, tmp_path / "explore.log") as server, browser.chromium(tmp_path / "profile") as driver:
        t0 = time.perf_counter()
        driver.get(server.url)
        browser.wait_for(driver, f"const e = document.getElementById('pred-shape'); return e && e.innerText !== '' && ({browser.IDLE});")
        first_page = time.perf_counter() - t0
        # the start: the first benchmark object, 8 in, 3x3, lights on, the location nearest 50
        locations = select_locations(tiny_config(tiny_run)["rig"]["n_locations"])
        start = int(locations[np.argmin(np.abs(locations - 50))])
        check_panels("1_8inch_3x3_lighton", start)
        grid = browser.figure(driver, "grid")["traces"]["test error"]
        # the heat map recombines to the cell's own test RMSE (its test split drawn again)
        n, rms = np.array([c[2] for c in grid["customdata"]]), np.array([c[1] for c in grid["customdata"]])
        m = json.loads((results / "runs/clean/3x3/all/random/cnn1d_location/seed42/metrics.json").read_text())
        assert n.sum() == m["n_test"] and np.sqrt((n * rms**2).sum() / n.sum()) / 100 == pytest.approx(m["test"]["rmse_euclidean"], rel=1e-5)
        driver.save_screenshot(str(shots / "1_start.png"))

        # object: A, from the dropdown
        def pick(obj):
            driver.find_element(By.ID, "object").click()
            driver.find_element(By.XPATH, f"//label[contains(@class, 'dash-dropdown-option')][.//input[@value='{obj}']]").click()

        object_s, shape_truth = _timed(driver, lambda: pick("A"), "truth-shape")
        assert shape_truth == "A"
        check_panels("A_8inch_3x3_lighton", start)
        driver.save_screenshot(str(shots / "2_object_A.png"))

        # location: a click on the slider at the next captured location's mark, then the previous-location button back
        after = int(locations[list(locations).index(start) + 1])
        mark = driver.find_element(By.XPATH, f"//div[@id='location']//div[contains(@class, 'dash-slider-mark')][text()='{after}']")
        slider_s, _ = _timed(driver, lambda: ActionChains(driver).click(mark).perform(), "truth-location")
        check_panels("A_8inch_3x3_lighton", after)
        driver.save_screenshot(str(shots / "3_slider.png"))
        _timed(driver, lambda: driver.find_element(By.ID, "previous").click(), "truth-location")
        check_panels("A_8inch_3x3_lighton", start)

        # location: a click on the grid's first location, at its point's place in the viewport
        target = int(locations[0])
        gd = driver.find_element(By.CSS_SELECTOR, "#grid .js-plotly-plot")
        xy = driver.execute_script(
            """const gd = arguments[0], L = gd._fullLayout, loc = arguments[1];
               gd.scrollIntoView({block: 'center'});
               const r = gd.getBoundingClientRect();
               for (const t of gd._fullData) { if (!t.customdata) continue;
                 const i = Array.from(t.customdata, c => Array.isArray(c) || ArrayBuffer.isView(c) ? c[0] : c).indexOf(loc);
                 if (i >= 0) return [r.left + L._size.l + L.xaxis.l2p(t.x[i]), r.top + L._size.t + L.yaxis.l2p(t.y[i])]; }
               return null;""",
            gd, target,
        )  # fmt: skip

        def click():
            actions = ActionBuilder(driver)
            actions.pointer_action.move_to_location(round(xy[0]), round(xy[1])).pause(0.2).click()
            actions.perform()

        click_s, _ = _timed(driver, click, "truth-location")
        check_panels("A_8inch_3x3_lighton", target)
        driver.save_screenshot(str(shots / "4_grid_click.png"))

        # a held-out variant: the base shape's class; rule all builds its 3x3 features (Fig 10 scores the cells on them),
        # so the benchmark's cells predict it like any capture
        variant = "generalization1white"
        assert _timed(driver, lambda: pick(variant), "truth-shape")[1] == "1"
        assert f"results/features/{variant}_8inch_3x3_lighton.zarr" not in browser.text(driver, "messages")
        assert browser.text(driver, "pred-shape") in cells["shape"].classes
        driver.save_screenshot(str(shots / "5_variant.png"))

        # 8x8 in the dark theme: the raw 8x8 histograms; rule all builds the variant's features at 3x3 only (Fig 10),
        # so the page names the target that builds its 8x8 ones
        driver.find_element(By.XPATH, "//div[@id='theme']//input[@value='dark']").click()
        driver.find_element(By.XPATH, "//div[@id='resolution']//input[@value='8x8']").click()
        notes = _changed(driver, "messages", browser.text(driver, "messages"))
        assert f"snakemake --cores all results/features/{variant}_8inch_8x8_lighton.zarr" in notes, notes
        assert browser.figure(driver, "histograms")["n_traces"] == 2 * 64  # the capture and the background's mean in each zone
        page = driver.page_source
        driver.save_screenshot(str(shots / "6_8x8_dark.png"))
        print(
            f"\nexplorer: first page {first_page:.2f} s; control change to redrawn panels: object {object_s:.2f} s, "
            f"slider {slider_s:.2f} s, grid click {click_s:.2f} s; screenshots in {shots}"
        )
    assert "Traceback" not in page and "Traceback" not in server.output()
    assert tree_state(results) == before  # read only
