"""model.pt as a versioned record: what it holds, and what it refuses."""

import numpy as np
import pytest
import torch
from test_train import HP, _cell, data, factory  # noqa: F401 (the fixture)

from denali_pipe.train.saved_cell import FORMAT, MODEL_FILE, VERSION, SavedCell
from denali_pipe.train.training import run_cell, to_metres


@pytest.fixture(scope="module")
def record(data):  # noqa: F811
    x, samples = data
    return run_cell(x, samples, _cell(task="shape"), HP, validation_fraction=0.2, factory=factory()).state


def test_the_record_names_its_format_factory_and_shapes(record, data, tmp_path):  # noqa: F811
    x, _ = data
    assert record["format"] == FORMAT and record["version"] == VERSION
    assert record["factory"] == "denali_pipe.train.models:cnn1d" and record["input_shape"] == list(x.shape[1:])
    assert record["classes"] == ["A", "B", "circle"] and record["cell"]["task"] == "shape"
    torch.save(record, tmp_path / MODEL_FILE)
    saved = SavedCell.load(tmp_path)
    assert saved.input_shape == x.shape[1:] and saved.to_record().keys() == record.keys()
    assert all(torch.equal(saved.model[k], v) for k, v in record["model"].items())


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda r: r.pop("format"), "must be retrained"),
        (lambda r: r.update(version=VERSION + 1), f"reads version {VERSION}"),
        (lambda r: r.pop("factory"), "without a valid 'factory'"),
    ],
    ids=["unversioned", "newer", "incomplete"],
)
def test_a_record_of_another_format_or_version_is_refused_naming_the_file(record, tmp_path, change, message):
    bad = dict(record)
    change(bad)
    torch.save(bad, tmp_path / MODEL_FILE)
    with pytest.raises(ValueError, match=message) as e:
        SavedCell.load(tmp_path)
    assert str(tmp_path / MODEL_FILE) in str(e.value)


def test_a_version_1_record_reads_as_metre_outputs(record, tmp_path):
    """Version 1 had no target_stats: its location cells regressed metres."""
    old = {k: v for k, v in record.items() if k != "target_stats"} | {"version": 1}
    torch.save(old, tmp_path / MODEL_FILE)
    saved = SavedCell.load(tmp_path)
    assert saved.target_stats is None and saved.to_record()["version"] == VERSION


def test_a_version_2_record_reads_as_unbounded_standardised_outputs(record, tmp_path):
    """Version 2 held a clean location cell's mean and std, not its box: it maps back without the bounded head."""
    old = record | {"version": 2, "target_stats": [[1.0, 0.3], [0.1, 0.05]]}
    torch.save(old, tmp_path / MODEL_FILE)
    saved = SavedCell.load(tmp_path)
    assert saved.target_stats == ((1.0, 0.3), (0.1, 0.05))
    assert to_metres(np.array([[50.0, -50.0]], np.float32), saved.target_stats)[0].tolist() == pytest.approx([6.0, -2.2])
