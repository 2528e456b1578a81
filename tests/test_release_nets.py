"""`train/release_nets.py`: a release checkpoint as the project's 1D CNN, read
without running code; and a registered model's cells starting from one
(`init: release:<file>`)."""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd
import pytest
import torch
import yaml
from conftest import REPO

from denali_pipe.io.release_weights import STATUS, WeightsStatus
from denali_pipe.train import release_nets as rn
from denali_pipe.train.cells import TASKS, Cell
from denali_pipe.train.models import CNN1d, cnn1d, mlp
from denali_pipe.train.registry import check_models
from denali_pipe.train.training import Hyper, run_cell

CLASSIFIER = {"mlp.0.": "head.2.", "out_linear.": "head.5."}  # the release's classifier names its head apart
RANDOM_GROUPED = "split_checkpoints/splits_loc_random_grouped.pth"


def release_checkpoint(net: CNN1d, path, classifier: bool) -> None:
    """Save `net` as the release saves its networks: its layers under the
    release's names, numpy statistics and label names beside them."""
    ours = {v: k for k, v in rn.RELEASE_NAMES.items() if not (classifier and k in ("mlp.0.", "out_linear."))} | (CLASSIFIER if classifier else {})
    state = {}
    for key, value in net.state_dict().items():
        prefix = next(p for p in ours if key.startswith(p))
        state[ours[prefix] + key.removeprefix(prefix)] = value
    torch.save({"model_state_dict": state, "train_mean": np.float32(7.1), "train_std": np.float64(0.78), "classes": [np.str_("4inch"), np.str_("8inch")]}, path)


def test_a_release_checkpoint_is_the_1d_cnn_layer_for_layer(tmp_path):
    torch.manual_seed(0)
    for task, classifier in (("size", True), ("location", False)):
        original = cnn1d(task, 2, (3, 3, 128)).eval()
        release_checkpoint(original, tmp_path / f"{task}.pth", classifier)
        net, payload = rn.release_network(tmp_path / f"{task}.pth", task)
        x = torch.randn(5, 3, 3, 128)
        assert torch.equal(net(x), original(x)) and not net.training
        assert payload["classes"] == ["4inch", "8inch"] and float(payload["train_mean"]) == pytest.approx(7.1)


def test_a_checkpoint_that_would_run_code_is_refused(tmp_path):
    torch.save({"model_state_dict": {}, "anything": argparse.Namespace(run="code")}, tmp_path / "bad.pth")
    with pytest.raises(ValueError, match="bad.pth: not a checkpoint the weights-only reader accepts"):
        rn.read_checkpoint(tmp_path / "bad.pth")
    torch.save({"weights": {}}, tmp_path / "bare.pth")
    with pytest.raises(ValueError, match="a dict with a model_state_dict"):
        rn.read_checkpoint(tmp_path / "bare.pth")


def test_init_loads_every_layer_that_fits_and_refuses_another_network(tmp_path):
    torch.manual_seed(1)
    release_checkpoint(cnn1d("shape", 30, (3, 3, 128)), tmp_path / "obj.pth", classifier=True)
    model = cnn1d("shape", 3, (3, 3, 77))  # the run's 3 classes and cropped bins: the output layer stays fresh
    fresh = rn.init_from_release(model, tmp_path / "obj.pth")
    assert fresh == ["out_linear.bias", "out_linear.weight"]
    release = rn.cnn1d_state(rn.read_checkpoint(tmp_path / "obj.pth")["model_state_dict"], "obj.pth")
    assert all(torch.equal(model.state_dict()[k], v) for k, v in release.items() if not k.startswith("out_linear."))
    with pytest.raises(ValueError, match="not the release's 1D CNN for its zones: features.0.weight"):
        rn.init_from_release(cnn1d("shape", 3, (8, 8, 128)), tmp_path / "obj.pth")
    with pytest.raises(ValueError, match="not the release's 1D CNN"):
        rn.init_from_release(mlp("shape", 3, (3, 3, 128)), tmp_path / "obj.pth")


def weights_folder(tmp_path, available=True):
    """A release weights folder (rule release_weights) whose random-grouped location checkpoint is a fresh 1D CNN."""
    folder = tmp_path / "release_weights"
    (folder / RANDOM_GROUPED).parent.mkdir(parents=True)
    torch.manual_seed(2)
    release_checkpoint(cnn1d("location", 2, (3, 3, 128)), folder / RANDOM_GROUPED, classifier=False)
    (folder / STATUS).write_text(WeightsStatus(available, "a test", "" if available else "downloads are off").to_json())
    return folder


def small_dataset():
    rng = np.random.default_rng(3)
    rows = [{"set": f"1_{s}_3x3_lighton", "object": "1", "class": "1", "type": "number", "size": s, "light": "lighton", "location": k, "repeat": r,
             "x": 1.0 + 0.0365 * k, "y": 0.3} for s in ("4inch", "8inch") for k in range(6) for r in range(2)]  # fmt: skip
    return rng.poisson(500, (len(rows), 3, 3, 40)).astype(np.float32), pd.DataFrame(rows)


def test_a_cell_starts_from_the_release_checkpoint_its_settings_name(tmp_path):
    x, samples = small_dataset()
    folder = weights_folder(tmp_path)
    cell = Cell("cnn1d", "location", "random", "3x3", "paper", 42)
    # a step too small to move a weight: the trained network's weights are the checkpoint's (its BN statistics follow the data)
    hp = Hyper(lr=1e-12, epochs=1, batch_size=8, norm="log_z", init=f"release:{RANDOM_GROUPED}")
    result = run_cell(x, samples, cell, hp, 0.2, "denali_pipe.train.models:cnn1d", release_weights=folder)
    start = rn.cnn1d_state(rn.read_checkpoint(folder / RANDOM_GROUPED)["model_state_dict"], "start")
    trained = result.state["model"]
    weights = [k for k in start if not k.endswith(("running_mean", "running_var", "num_batches_tracked"))]
    assert all(torch.allclose(trained[k], start[k], atol=1e-9) for k in weights)
    assert result.metrics.hyper["init"] == f"release:{RANDOM_GROUPED}"
    with pytest.raises(ValueError, match="holds none of the release's weights: downloads are off"):
        run_cell(x, samples, cell, hp, 0.2, "denali_pipe.train.models:cnn1d", release_weights=weights_folder(tmp_path / "off", available=False))


def test_the_registry_refuses_an_init_that_names_no_release_checkpoint():
    entry = {"factory": "denali_pipe.train.models:cnn1d", "location": {"lr": 1e-3, "epochs": 1, "batch_size": 8, "norm": "raw", "init": "release:mine.pth"}}
    with pytest.raises(ValueError, match=r"train.models.cnn1d.location.init 'release:mine.pth': expected 'release:<file>'"):
        check_models({"cnn1d": entry}, "cnn1d")


def test_the_example_compares_a_model_from_the_release_with_the_same_from_scratch():
    models = check_models(yaml.safe_load((REPO / "examples" / "release_init.yaml").read_text())["train"]["models"], "cnn1d-log")
    for task in TASKS:
        real, scratch = dict(models["cnn1d-real"][task]), models["cnn1d-log"][task]
        assert real.pop("init").startswith("release:split_checkpoints/") and real == scratch
