"""The model registry: config entries resolve to factories, and every wrong entry is refused naming its key."""

import sys

import pytest
import yaml
from conftest import REPO
from torch import nn

from denali_pipe.train.models import PAPER_MODELS
from denali_pipe.train.registry import build, check_left_out, check_models, load_factory, n_outputs

CONFIG = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
HP = {"lr": 1e-3, "epochs": 1, "batch_size": 8, "norm": "raw"}


def entry(factory):
    return {"factory": factory, "location": HP, "shape": HP, "size": HP}


def test_the_papers_four_are_registry_entries_of_their_factories():
    models = check_models(CONFIG["train"]["models"], CONFIG["train"]["benchmark_model"])
    assert list(models) == list(PAPER_MODELS)
    for name, e in models.items():
        assert load_factory(name, e["factory"]) is PAPER_MODELS[name]


def test_build_follows_the_contract():
    net = build("cnn1d", "denali_pipe.train.models:cnn1d", "shape", (3, 3, 40), n_classes=7)
    assert isinstance(net, nn.Module) and net.out_linear.out_features == n_outputs("shape", 7) == 7
    assert n_outputs("location", 7) == 2 and n_outputs("size", 7) == 2


def test_a_null_entry_leaves_a_model_out():
    models = check_models({**CONFIG["train"]["models"], "mlp": None}, "cnn1d")
    assert "mlp" not in models and len(models) == 3


def test_left_out_models_keep_their_reasons_in_config_order():
    models = CONFIG["train"]["models"]
    left = check_left_out([{"model": "transformer", "reason": "slow"}, {"model": "mlp", "reason": "also"}], models, "cnn1d")
    assert left == {"transformer": "slow", "mlp": "also"} and list(left) == ["transformer", "mlp"]
    assert check_left_out([], models, "cnn1d") == {}
    # a model set to null is gone from every table, so naming it leaves nothing out
    assert check_left_out([{"model": "mlp", "reason": "r"}], {**models, "mlp": None}, "cnn1d") == {}


@pytest.mark.parametrize(
    ("left_out", "message"),
    [
        ([{"model": "resnet", "reason": "r"}], "train.left_out: 'resnet' is not a model of train.models"),
        ([{"model": "mlp", "reason": "r"}, {"model": "mlp", "reason": "s"}], "train.left_out: 'mlp' is named twice"),
        ([{"model": "cnn1d", "reason": "r"}], "train.left_out: 'cnn1d' is train.benchmark_model"),
    ],
    ids=["unregistered", "twice", "benchmark-model"],
)
def test_a_wrong_left_out_entry_is_refused_naming_the_key(left_out, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        check_left_out(left_out, CONFIG["train"]["models"], "cnn1d")


@pytest.mark.parametrize(
    ("models", "benchmark", "message"),
    [
        ({"cnn1d": entry("denali_pipe.train.models:cnn1d")}, "mlp", "train.benchmark_model: 'mlp' is not a registered model"),
        ({"my_net": entry("denali_pipe.train.models:cnn1d")}, "my_net", "train.models.my_net: a model name"),
        ({"linear": entry("denali_pipe.train.models:cnn1d")}, "linear", "train.models.linear: a model name"),
        ({"net": entry("denali_pipe.train.models.cnn1d")}, "net", "train.models.net.factory: 'denali_pipe.train.models.cnn1d' is not an import path"),
        ({"net": entry("no_such_package.mod:f")}, "net", "train.models.net.factory: module 'no_such_package.mod' cannot be imported"),
        ({"net": entry("denali_pipe.no_such_module:f")}, "net", "train.models.net.factory: no module 'denali_pipe.no_such_module'"),
        ({"mlp": None}, "mlp", "train.models: no model registered"),
    ],
    ids=["benchmark-unregistered", "underscore", "reserved", "not-a-path", "no-package", "no-module", "none-left"],
)
def test_a_wrong_entry_is_refused_naming_its_key(models, benchmark, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.").replace("(", r"\(")):
        check_models(models, benchmark)


def test_a_factory_that_does_not_resolve_or_build_names_its_key():
    with pytest.raises(
        ValueError, match=r"train\.models\.net\.factory 'denali_pipe\.train\.models:resnet': module 'denali_pipe\.train\.models' has no 'resnet'"
    ):
        load_factory("net", "denali_pipe.train.models:resnet")
    with pytest.raises(ValueError, match=r"train\.models\.net\.factory 'denali_pipe\.train\.models:DROPOUT': 'DROPOUT' is not callable"):
        load_factory("net", "denali_pipe.train.models:DROPOUT")


def test_a_module_in_the_workflow_folder_resolves_and_must_build_a_module(tmp_path, monkeypatch):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "nets.py").write_text("def not_a_net(task, n_outputs, input_shape):\n    return n_outputs\n")
    monkeypatch.chdir(tmp_path)  # the workflow's folder, not on sys.path
    monkeypatch.setattr("sys.path", [p for p in sys.path if p not in ("", str(tmp_path))])
    assert list(check_models({"net": entry("mine.nets:not_a_net")}, "net")) == ["net"]
    with pytest.raises(ValueError, match=r"train\.models\.net\.factory 'mine\.nets:not_a_net' returned int, not a torch\.nn\.Module"):
        build("net", "mine.nets:not_a_net", "shape", (3, 3, 8), 2)
