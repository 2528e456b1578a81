"""A saved cell, loaded back: it scores its own test split as training did,
embeds, and refuses what it cannot score."""

import numpy as np
import pytest
import torch
from test_train import _cell, data, factory  # noqa: F401 (the fixture)

from denali_pipe.cli import main
from denali_pipe.train.dataset import write_dataset
from denali_pipe.train.evaluate import Evaluation, baseline_score, embed, labels, load_cell, predict, score
from denali_pipe.train.training import Hyper, partition, run_cell, targets

HP = Hyper(lr=3e-3, epochs=2, batch_size=32, norm="log_z")


def save(tmp_path, result):
    """As `denali train` writes a run directory."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "metrics.json").write_text(result.metrics.to_json())
    torch.save(result.state, tmp_path / "model.pt")
    return tmp_path


# every model (their weights carry the input shape differently) and both kinds of head
@pytest.mark.parametrize(("model", "task"), [("mlp", "location"), ("cnn1d", "shape"), ("cnn3d", "size"), ("transformer", "location")])
def test_a_loaded_cell_scores_its_test_split_as_training_did(tmp_path, data, model, task):  # noqa: F811
    x, samples = data
    cell = _cell(task=task, model=model)
    result = run_cell(x, samples, cell, HP, validation_fraction=0.2, factory=factory(model))
    trained = load_cell(save(tmp_path, result))
    assert trained.cell == cell and trained.input_shape == x.shape[1:]
    y, _ = targets(samples, task)
    split, _ = partition(samples, y, cell, 0.2)
    test = samples.iloc[split.test]
    assert np.array_equal(labels(trained, test), y[split.test])
    got = score(trained, x[split.test], test)
    assert got == pytest.approx(result.metrics.test, rel=1e-5, abs=1e-6)
    assert baseline_score(trained, test) == pytest.approx(result.metrics.baseline, rel=1e-12)


def test_embed_is_the_heads_input(tmp_path, data):  # noqa: F811
    x, samples = data
    trained = load_cell(save(tmp_path, run_cell(x, samples, _cell(task="shape"), HP, validation_fraction=0.2, factory=factory())))
    e = embed(trained, x[:5])
    assert e.shape == (5, 32)  # the 1D CNN's hidden Linear(64, 32)-GELU
    head = trained.model.out_linear
    with torch.no_grad():
        assert np.allclose(head(torch.from_numpy(e)).numpy(), predict(trained, x[:5]), atol=1e-5)


def test_refuses_what_it_cannot_score(tmp_path, data):  # noqa: F811
    x, samples = data
    trained = load_cell(save(tmp_path, run_cell(x, samples, _cell(task="shape"), HP, validation_fraction=0.2, factory=factory())))
    unseen = samples.assign(**{"class": "hexagon"})
    with pytest.raises(ValueError, match=r"\['hexagon'\] were never learnt"):
        labels(trained, unseen)
    with pytest.raises(ValueError, match="do not fit a 3x3 cell"):
        predict(trained, np.zeros((2, 8, 8, x.shape[-1]), np.float32))
    with pytest.raises(ValueError, match="model.pt: not a training cell's saved model"):
        load_cell(tmp_path / "elsewhere")


def test_denali_evaluate_writes_the_cell_and_its_baseline_on_another_dataset(tmp_path, data):  # noqa: F811
    x, samples = data
    run = save(tmp_path / "run", run_cell(x, samples, _cell(task="location"), HP, validation_fraction=0.2, factory=factory()))
    # "another dataset": the 8 in lights-off samples, shifted 5 cm in x
    other = samples[(samples["size"] == "8inch") & (samples["light"] == "lightoff")]
    moved = other.assign(x=other["x"] + 0.05).reset_index(drop=True)
    write_dataset(x[other.index], moved, tmp_path / "other.zarr", tmp_path / "other.parquet", 70)
    out = tmp_path / "evaluation.json"
    assert main(["evaluate", str(run), str(tmp_path / "other.zarr"), "--table", str(tmp_path / "other.parquet"), "--out", str(out)]) == 0
    e = Evaluation.read(out)
    trained = load_cell(run)
    assert e.cell == trained.cell and e.n_samples == len(moved) and e.n_classes == 2
    assert e.metrics == pytest.approx(score(trained, x[other.index], moved))
    mean = np.array(trained.baseline_output)
    assert e.baseline["rmse"] == pytest.approx(np.sqrt(np.mean((moved[["x", "y"]].to_numpy() - mean) ** 2)))
    with pytest.raises(ValueError, match="not a cell's evaluation"):
        Evaluation.read(run / "metrics.json")
