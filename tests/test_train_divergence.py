"""A diverged loss (NaN or inf) fails its cell, naming the cell and the
epoch, and leaves no metric behind (train.training.fit, `denali train`)."""

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


def test_a_diverged_cell_fails_naming_the_cell_and_the_epoch(data):
    x, samples = data
    with pytest.raises(ValueError, match=r"^cnn1d size random 3x3 all clean seed 7: the loss diverged \((nan|inf)\) in epoch 2;"):
        run_cell(x, samples, cell(), DIVERGING, validation_fraction=0.25, factory=FACTORY)


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
    hp = Hyper(lr=1e-3, epochs=4, batch_size=16, norm="raw")  # 3 batches an epoch: the 5th pass is epoch 2's
    with pytest.raises(ValueError, match=r"^probe: the loss diverged \((nan|inf)\) in epoch 2;"):
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
    assert "cnn1d size random 3x3 all clean seed 7: the loss diverged" in caplog.text and "in epoch 2" in caplog.text
    assert not (tmp_path / "runs").exists()
