"""A saved cell, loaded back: it scores its own test split as training did,
embeds, and refuses what it cannot score."""

import json

import numpy as np
import pytest
import torch

from denali_pipe.evaluate import embed, labels, load_cell, predict, score
from denali_pipe.train import Hyper, partition, run_cell, targets

from test_train import _cell, data  # noqa: F401 (the fixture)

HP = Hyper(lr=3e-3, epochs=2, batch_size=32, norm="log_z")


def save(tmp_path, result):
    """As `denali train` writes a run directory."""
    (tmp_path / "metrics.json").write_text(json.dumps(result.metrics))
    torch.save(result.state, tmp_path / "model.pt")
    return tmp_path


# every model (their weights carry the input shape differently) and both kinds of head
@pytest.mark.parametrize(("model", "task"), [("mlp", "location"), ("cnn1d", "shape"), ("cnn3d", "size"), ("transformer", "location")])
def test_a_loaded_cell_scores_its_test_split_as_training_did(tmp_path, data, model, task):  # noqa: F811
    x, samples = data
    cell = _cell(task=task, model=model)
    result = run_cell(x, samples, cell, HP, validation_fraction=0.2)
    trained = load_cell(save(tmp_path, result))
    assert trained.cell == cell and trained.input_shape == x.shape[1:]
    y, _ = targets(samples, task)
    split, _ = partition(samples, y, cell, 0.2)
    test = samples.iloc[split.test]
    assert np.array_equal(labels(trained, test), y[split.test])
    got = score(trained, x[split.test], test)
    assert got == pytest.approx(result.metrics["test"], rel=1e-5, abs=1e-6)


def test_embed_is_the_heads_input(tmp_path, data):  # noqa: F811
    x, samples = data
    trained = load_cell(save(tmp_path, run_cell(x, samples, _cell(task="shape"), HP, validation_fraction=0.2)))
    e = embed(trained, x[:5])
    assert e.shape == (5, 32)  # the 1D CNN's hidden Linear(64, 32)-GELU
    head = trained.model.out_linear
    with torch.no_grad():
        assert np.allclose(head(torch.from_numpy(e)).numpy(), predict(trained, x[:5]), atol=1e-5)


def test_refuses_what_it_cannot_score(tmp_path, data):  # noqa: F811
    x, samples = data
    trained = load_cell(save(tmp_path, run_cell(x, samples, _cell(task="shape"), HP, validation_fraction=0.2)))
    unseen = samples.assign(**{"class": "hexagon"})
    with pytest.raises(ValueError, match=r"\['hexagon'\] were never learnt"):
        labels(trained, unseen)
    with pytest.raises(ValueError, match="do not fit a 3x3 cell"):
        predict(trained, np.zeros((2, 8, 8, x.shape[-1]), np.float32))
    with pytest.raises(ValueError, match="model.pt: not a training cell's saved model"):
        load_cell(tmp_path / "elsewhere")
