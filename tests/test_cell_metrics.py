"""A cell's metrics.json: one record written and read back, older files
readable, anything else refused with the file's name."""

import json

import pytest

from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import Cell

CELL = Cell(model="cnn1d", task="shape", split="random", resolution="3x3", protocol="clean", seed=42)
SCORES = {"top1": 0.5, "top5": 0.9, "precision": 0.4, "recall": 0.5, "f1": 0.45}
# metrics.json as train.run_cell wrote it before the record (no `threads`, no `selected_regularisation`)
OLDER = {
    "cell": {"model": "cnn1d", "task": "shape", "split": "random", "resolution": "3x3", "protocol": "clean", "seed": 42},
    "hyper": {"lr": 0.001, "epochs": 15, "batch_size": 64, "norm": "raw"}, "validation_fraction": 0.2, "selected_on": "validation",
    "n_train": 700, "n_validation": 140, "n_test": 300, "n_classes": 30, "input_shape": [3, 3, 57], "params": 83198,
    "best_epoch": 12, "epochs_run": 15, "samples_seen": 10500, "budget_seconds": 120, "stopped_by_budget": False,
    "test": SCORES, "baseline": SCORES, "train_seconds": 20.5, "inference_seconds": 0.1,
    "train_samples_per_second": 512.0, "inference_samples_per_second": 3000.0, "device": "cpu",
}  # fmt: skip


def test_round_trip(tmp_path):
    m = CellMetrics(cell=CELL, hyper={"regularisation": [0.1, 1.0], "norm": "log_z"}, selected_on="test", n_train=10, n_validation=0, n_test=5,
                    n_classes=30, input_shape=(3, 3, 57), params=1000, test=SCORES, baseline=SCORES, train_seconds=1.0, inference_seconds=0.1,
                    train_samples_per_second=20.0, inference_samples_per_second=None, device="cpu", selected_regularisation=1.0)  # fmt: skip
    (tmp_path / "metrics.json").write_text(m.to_json())
    assert CellMetrics.read(tmp_path / "metrics.json") == m


def test_an_older_file_reads_with_the_defaults(tmp_path):
    (tmp_path / "metrics.json").write_text(json.dumps(OLDER))
    m = CellMetrics.read(tmp_path / "metrics.json")
    assert m.cell == CELL and m.input_shape == (3, 3, 57) and m.best_epoch == 12
    assert m.threads is None and m.selected_regularisation is None


@pytest.mark.parametrize(("change", "message"), [({"colour": "red"}, r"unknown keys \['colour'\]"), ({"test": None, "n_test": None}, None)])
def test_refuses_what_is_not_a_cells_metrics(tmp_path, change, message):
    record = {k: v for k, v in {**OLDER, **change}.items() if v is not None}
    (tmp_path / "metrics.json").write_text(json.dumps(record))
    with pytest.raises(ValueError, match=message or "n_test"):
        CellMetrics.read(tmp_path / "metrics.json")
    with pytest.raises(ValueError, match="nowhere/metrics.json: not a training cell's metrics.json"):
        CellMetrics.read(tmp_path / "nowhere/metrics.json")
