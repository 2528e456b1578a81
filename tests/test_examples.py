"""The example model of examples/ (outside the package), through the registry
and a training cell, as the workflow runs it."""

import pytest
import torch
import yaml
from conftest import REPO
from test_train import _cell, data  # noqa: F401 (the fixture)

from denali_pipe.train.registry import build, check_models
from denali_pipe.train.training import Hyper, run_cell

EXAMPLE = yaml.safe_load((REPO / "examples" / "tof.yaml").read_text())["train"]


@pytest.fixture()
def in_workflow_folder(monkeypatch):
    monkeypatch.chdir(REPO)  # where the workflow runs, and finds examples/


def test_the_example_config_registers_the_matched_filter_model(in_workflow_folder):
    models = check_models(EXAMPLE["models"], EXAMPLE["benchmark_model"])
    net = build("tof", models["tof"]["factory"], "shape", (3, 3, 40), n_classes=5)
    assert net(torch.randn(2, 3, 3, 40)).shape == (2, 5)
    assert not [n for n, _ in net.named_parameters() if "bank" in n]  # the filters are fixed
    # the jitter sweep's centre zone, in an epoch's last batch of one sample, trains
    centre = build("tof", models["tof"]["factory"], "size", (1, 1, 40), n_classes=2).train()
    centre(torch.randn(1, 1, 1, 40)).sum().backward()


@pytest.mark.parametrize(("task", "beats"), [("location", 0.75), ("size", 1.5), ("shape", 2.0)])
def test_the_matched_filter_model_learns_the_bumps_time_height_and_width(in_workflow_folder, data, task, beats):  # noqa: F811
    """The synthetic bump's time encodes the location, its height the size
    and its width the class: what the filters' peak time, height and energy read.
    RMSE below `beats` x the mean predictor's; Top-1 above `beats` x the majority's."""
    x, samples = data
    torch.manual_seed(0)
    hp = Hyper(lr=3e-3, epochs=40, batch_size=32, norm="raw")
    m = run_cell(x, samples, _cell(task=task, model="tof"), hp, 0.2, EXAMPLE["models"]["tof"]["factory"]).metrics
    if task == "location":
        assert m.test["rmse"] < beats * m.baseline["rmse"]
    else:
        assert m.test["top1"] > beats * m.baseline["top1"]
    assert m.params < 20_000 and m.flops > 0
