from pathlib import Path

import pytest
from conftest import REPO

from denali_pipe.workflow import costs

REQUESTS = {"runtime_headroom": 3, "mem_headroom": 2, "min_runtime_min": 10, "min_mem_mb": 1000}


def test_frame_pixels_follow_the_rig_scales():
    assert costs.frame_pixels({"tracking_scale": 1.0, "colocated_scale": 1.0}) == (1280 * 720, 848 * 480)
    assert costs.frame_pixels({"tracking_scale": 0.5, "colocated_scale": 0.25}) == (640 * 360, 212 * 120)


def test_set_work_counts_histogram_values_and_pixels():
    w3 = costs.set_work(25, 3, "3x3", 100, 10)
    w8 = costs.set_work(25, 3, "8x8", 100, 10)
    assert w3 == {"const": 1.0, "hist": 25 * 3 * 9 * 128, "frames": 25 * 110, "tracking": 25 * 100, "frame": 110, "samples": 0.0}
    assert w8["hist"] == 25 * 3 * 64 * 128 and w8["frames"] == w3["frames"]


def test_a_rig_job_adds_its_sets_work_but_pays_its_fixed_cost_once():
    sets = [costs.set_work(10, 3, r, 50, 5) for r in ("3x3", "8x8")]
    job = costs.combine(sets)
    assert job["const"] == 1.0 and job["hist"] == sets[0]["hist"] + sets[1]["hist"] and job["frames"] == 2 * sets[0]["frames"]
    assert job["frame"] == sets[0]["frame"]  # one location's frames in memory at a time


def test_predict_is_the_linear_model():
    work = costs.training_work(1000)
    assert costs.predict({"const": 4.0, "samples": 0.01}, work) == pytest.approx(14.0)


def test_requests_apply_headroom_speedup_and_floors():
    assert costs.runtime_minutes(6000, REQUESTS) == 300  # 6,000 CPU-s x 3 = 300 min
    assert costs.runtime_minutes(6000, REQUESTS, speedup=20) == 15
    assert costs.runtime_minutes(1, REQUESTS) == 10
    assert costs.mem_mb(700.2, REQUESTS) == 1401
    assert costs.mem_mb(100, REQUESTS) == 1000


def test_gpu_speedup_is_the_cells_most_specific_entry_and_only_with_gpus():
    speedups = {"default": 10, "cnn3d": 300, "cnn3d_location": 700}
    assert costs.gpu_speedup(speedups, "train", "cnn3d", "location", gpus=1) == 700
    assert costs.gpu_speedup(speedups, "train", "cnn3d", "shape", gpus=1) == 300
    assert costs.gpu_speedup(speedups, "train", "my_net", "size", gpus=1) == 10
    assert costs.gpu_speedup(speedups, "train", "cnn3d", "location", gpus=0) == 1.0
    assert costs.gpu_speedup(speedups, "rig", gpus=1) == 1.0


def test_the_committed_cost_table_loads_and_has_the_heavy_rules():
    table = costs.load_costs(REPO / "config/costs.yaml")
    assert {"rig", "ingest", "poses", "preprocess", "train"} <= set(table["rules"])
    # a network and task's own model, else the network's, else the default
    cells = table["rules"]["train"]
    assert costs.cost_model(table, "train", "cnn1d", "location") == cells["cnn1d_location"]
    assert costs.cost_model(table, "train", "cnn1d", "no-such-task") == cells["cnn1d"]
    assert costs.cost_model(table, "train", "no-such-net", "location") == cells["default"]


def test_a_malformed_cost_table_names_its_file(tmp_path: Path):
    bad = tmp_path / "costs.yaml"
    bad.write_text("rules:\n  rig:\n    cpu_s: {weight: 1}\n    rss_mb: {const: 1}\n")
    with pytest.raises(ValueError, match=f"{bad}.*rig.*cpu_s"):
        costs.load_costs(bad)
