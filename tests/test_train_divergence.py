"""A diverged run (a NaN or infinite loss or weight) fails its cell, naming
the cell, the epoch and step, the first non-finite tensor and what to try,
and leaves no metric behind (train.training.fit, train.divergence, `denali train`)."""

import json
import logging
from dataclasses import asdict

import numpy as np
import pandas as pd
import pytest
import torch
from torch import nn

from denali_pipe.cli import main
from denali_pipe.train.cells import Cell
from denali_pipe.train.dataset import write_dataset
from denali_pipe.train.training import Hyper, fit, loss_for, run_cell

BINS = 16
FACTORY = "denali_pipe.train.models:cnn1d"
# Adam steps every weight by about lr whatever its gradient: at 1e10 the size classifier's logits overflow float32 by its second epoch.
DIVERGING = Hyper(lr=1e10, epochs=2, batch_size=16, norm="raw")


@pytest.fixture(scope="module")
def data():
    """48 samples of random (3, 3, BINS) counts at 12 locations, 2 sizes, 2 repeats."""
    rng = np.random.default_rng(0)
    rows = [
        {"set": f"A_{size}_3x3_lighton", "object": "A", "class": "A", "type": "letter", "size": size, "light": "lighton", "location": k, "repeat": r,
         "x": 1.0 + 0.0365 * (k % 4), "y": 0.2 + 0.0365 * (k // 4)}
        for size in ("4inch", "8inch") for k in range(12) for r in range(2)
    ]  # fmt: skip
    return rng.poisson(20, (len(rows), 3, 3, BINS)).astype(np.float32), pd.DataFrame(rows)


def cell(seed=7):
    # a classifier: a clean location cell's bounded head keeps its loss finite however large its outputs
    return Cell(model="cnn1d", task="size", split="random", resolution="3x3", protocol="clean", seed=seed)


def test_a_cell_whose_loss_grew_first_fails_naming_the_cell_and_suggesting_a_lower_learning_rate(data):
    x, samples = data
    with pytest.raises(ValueError) as e:
        run_cell(x, samples, cell(), DIVERGING, validation_fraction=0.25, factory=FACTORY)
    message = str(e.value)
    assert message.startswith("cnn1d size random 3x3 all clean seed 7: training diverged in epoch 1; ")
    assert "the first non-finite tensor is " in message and "lower the learning rate (lr 1e+10)" in message
    assert "bfloat16" not in message


class OverflowsFrom(nn.Module):
    """A linear head whose training outputs turn infinite from its `n`-th training pass on."""

    def __init__(self, n: int):
        super().__init__()
        self.head, self.n, self.passes = nn.Linear(3 * 3 * BINS, 2), n, 0

    def forward(self, x):
        out = self.head(x.flatten(1))
        if self.training:
            self.passes += 1
            if self.passes >= self.n:
                out = out * torch.inf
        return out


def test_fit_names_the_first_epoch_whose_loss_is_not_finite(data):
    x, samples = data
    xt, yt = torch.from_numpy(x), torch.from_numpy(np.array(samples[["x", "y"]], np.float32))
    # 3 batches an epoch: the 5th pass is epoch 2's 2nd step (the replay, whose passes count on, overflows from its 1st)
    hp = Hyper(lr=1e-3, epochs=4, batch_size=16, norm="raw")
    with pytest.raises(
        ValueError, match=r"^probe: training diverged in epoch 2; the loss was (nan|inf) at step 2; the first non-finite tensor is the loss at step \d;"
    ):
        fit(OverflowsFrom(5), xt, yt, hp, 0, loss_for("location"), name="probe")
    # the same head, never overflowing, trains every epoch
    assert fit(OverflowsFrom(10**6), xt, yt, hp, 0, loss_for("location"), name="probe").epochs_run == 4


def test_denali_train_writes_no_metric_for_a_diverged_cell(tmp_path, data, caplog):
    x, samples = data
    write_dataset(x, samples, tmp_path / "3x3.zarr", tmp_path / "3x3.parquet", crop_start=0)
    out = tmp_path / "runs" / "seed7"
    args = ["train", str(tmp_path / "3x3.zarr"), "--table", str(tmp_path / "3x3.parquet"), "--cell", json.dumps(asdict(cell())), "--factory", FACTORY]
    args += ["--hyper", json.dumps(asdict(DIVERGING)), "--validation-fraction", "0.25", "--outdir", str(out)]
    with caplog.at_level(logging.ERROR, logger="denali"):
        assert main(args) == 1
    assert "cnn1d size random 3x3 all clean seed 7: training diverged in epoch 1" in caplog.text
    assert not (tmp_path / "runs").exists()


class NanGradientAt(torch.autograd.Function):
    """The identity, whose backward gives NaN on the `n`-th call (the loss and
    the forward pass stay finite until the poisoned weights are used)."""

    calls = 0

    @staticmethod
    def forward(ctx, x, n):
        ctx.n = n
        return x.clone()

    @staticmethod
    def backward(ctx, g):
        NanGradientAt.calls += 1
        return (g * torch.nan if NanGradientAt.calls == ctx.n else g), None


class PoisonedGradient(nn.Module):
    def __init__(self, n: int):
        super().__init__()
        self.linear, self.n = nn.Linear(3 * 3 * BINS, 2), n

    def forward(self, x):
        return NanGradientAt.apply(self.linear(x.flatten(1)), self.n)


@pytest.mark.parametrize("precision", [torch.float32, torch.bfloat16])
def test_a_nan_gradient_is_named_with_its_step_and_the_learning_rate_is_not_blamed(data, precision):
    x, samples = data
    xt, yt = torch.from_numpy(x), torch.from_numpy(np.array(samples[["x", "y"]], np.float32))
    hp = Hyper(lr=1e-3, epochs=4, batch_size=16, norm="raw")  # 3 steps an epoch: the 5th backward is epoch 2's 2nd step
    NanGradientAt.calls = 0
    with pytest.raises(ValueError) as e:
        fit(PoisonedGradient(5), xt, yt, hp, 0, loss_for("location"), name="probe", precision=precision)
    message = str(e.value)
    # the fault does not recur in the replay of epoch 2 (its 5th backward is past), as a kernel's that reads memory it never wrote may not
    assert message.startswith("probe: training diverged in epoch 2; the loss was nan at step 3; its replay from the epoch's start stayed finite")
    assert "learning rate" not in message or "not the likely cause" in message
    assert ("train it in float32" in message) == (precision == torch.bfloat16)


def test_the_replay_names_the_first_non_finite_gradient(data):
    x, samples = data
    xt, yt = torch.from_numpy(x), torch.from_numpy(np.array(samples[["x", "y"]], np.float32))
    hp = Hyper(lr=1e-3, epochs=4, batch_size=16, norm="raw")
    NanGradientAt.calls = 0
    model = PoisonedGradient(5)
    original = NanGradientAt.backward

    def every_fifth(ctx, g):  # a fault that the replay meets again: the 5th backward of the run and the 2nd of the replay
        NanGradientAt.calls += 1
        return (g * torch.nan if NanGradientAt.calls in (5, 8) else g), None

    NanGradientAt.backward = staticmethod(every_fifth)
    try:
        with pytest.raises(ValueError, match=r"the first non-finite tensor is the gradient of linear.weight in the backward pass at step 2;"):
            fit(model, xt, yt, hp, 0, loss_for("location"), name="probe")
    finally:
        NanGradientAt.backward = original


def test_non_finite_inputs_are_refused_before_training(data):
    x, samples = data
    xt, yt = torch.from_numpy(x.copy()), torch.from_numpy(np.array(samples[["x", "y"]], np.float32))
    xt[3, 0, 0, 0] = torch.nan
    with pytest.raises(ValueError, match="^probe: the inputs hold 1 non-finite values$"):
        fit(OverflowsFrom(10**6), xt, yt, Hyper(lr=1e-3, epochs=1, batch_size=16, norm="raw"), 0, loss_for("location"), name="probe")
