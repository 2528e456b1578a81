"""Training cells on small synthetic features: protocols, determinism,
outputs; the training loop every network goes through."""

import logging

import numpy as np
import pandas as pd
import pytest
import torch

from denali_pipe.core.geometry import WORKSPACE_MARGIN
from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train.cells import Cell
from denali_pipe.train.classical import run_linear
from denali_pipe.train.models import PAPER_MODELS, cnn1d
from denali_pipe.train.training import Hyper, fit, infer, loss_for, partition, run_cell, targets, to_metres, training_device

CLASSES = ("A", "B", "circle")
N_LOC, REPEATS, BINS = 8, 3, 24


@pytest.fixture(scope="module")
def data():
    """Features whose bump position encodes the location's y, whose bump
    height encodes size and whose width encodes the class."""
    rng = np.random.default_rng(0)
    rows, xs = [], []
    t = np.arange(BINS)
    for ci, cls in enumerate(CLASSES):
        for size in ("4inch", "8inch"):
            for light in ("lightoff", "lighton"):
                for k in range(N_LOC):
                    for r in range(REPEATS):
                        x, y = 1.0 + 0.0365 * (k % 4), 0.2 + 0.0365 * (k // 4)
                        centre = 4 + 12 * (y - 0.2) / 0.0365 + 2 * (k % 4)
                        bump = (50 if size == "8inch" else 20) * np.exp(-0.5 * ((t - centre) / (1 + ci)) ** 2)
                        xs.append(bump[None, None, :] * np.ones((3, 3, 1)) + rng.normal(0, 3, (3, 3, BINS)))
                        rows.append(
                            {
                                "set": f"{cls}_{size}_3x3_{light}",
                                "object": cls,
                                "class": cls,
                                "type": "letter",
                                "size": size,
                                "light": light,
                                "location": k,
                                "repeat": r,
                                "x": x,
                                "y": y,
                            }
                        )
    return np.stack(xs).astype(np.float32), pd.DataFrame(rows)


def _cell(task="location", split="random", protocol="clean", model="cnn1d", seed=42):
    return Cell(model=model, task=task, split=split, resolution="3x3", protocol=protocol, seed=seed)


HP = Hyper(lr=3e-3, epochs=4, batch_size=32, norm="raw")


def factory(model="cnn1d"):
    """The registry entry of one of the paper's models, as config.yaml names it."""
    return f"denali_pipe.train.models:{model}"


def test_targets(data):
    _, samples = data
    y, classes = targets(samples, "shape")
    assert classes == sorted(CLASSES) and y.dtype == np.int64
    y, classes = targets(samples, "size")
    assert classes == ["4inch", "8inch"] and set(y) == {0, 1}
    y, classes = targets(samples, "location")
    assert classes is None and y.shape == (len(samples), 2) and y.dtype == np.float32
    with pytest.raises(ValueError, match="unknown task"):
        targets(samples, "colour")


def test_clean_protocol_selects_on_validation_and_tests_once(data):
    x, samples = data
    res = run_cell(x, samples, _cell(), HP, validation_fraction=0.2, factory=factory())
    m, c = res.metrics, res.curves
    assert m.selected_on == "validation" and m.n_validation > 0
    assert m.n_train + m.n_validation + m.n_test == len(samples)
    assert set(c["part"]) == {"train", "validation", "test"}
    assert c[c["part"] == "test"]["epoch"].unique().tolist() == [m.best_epoch]
    assert c[c["part"] == "validation"]["epoch"].nunique() == HP.epochs
    assert {"rmse", "mae"} <= set(m.test) and m.params == 82340
    assert m.train_samples_per_second > 0 and m.inference_seconds > 0


def test_paper_protocol_selects_on_test(data):
    x, samples = data
    res = run_cell(x, samples, _cell(task="shape", protocol="paper"), HP, validation_fraction=0.2, factory=factory())
    m, c = res.metrics, res.curves
    assert m.selected_on == "test" and m.n_validation == 0
    best = c[(c["part"] == "test") & (c["metric"] == "top1")].set_index("epoch")["value"]
    assert m.test["top1"] == pytest.approx(best.max()) and m.best_epoch == best.idxmax()


def test_clean_normalisation_statistics_come_from_the_training_part_only(data):
    x, samples = data
    hp = Hyper(lr=1e-3, epochs=1, batch_size=64, norm="log_z")
    cell = _cell(task="size", split="location_held_out")
    res = run_cell(x, samples, cell, hp, validation_fraction=0.2, factory=factory())
    y, _ = targets(samples, "size")
    split, val = partition(samples, y, cell, 0.2)
    assert tuple(res.state["norm_stats"]) == normalise(x[split.train], "log_z")[1]
    assert tuple(res.state["norm_stats"]) != normalise(x, "log_z")[1]


@pytest.mark.parametrize(("task", "protocol", "standardised"), [("location", "clean", True), ("location", "paper", False), ("size", "clean", False)])
def test_clean_location_networks_regress_positions_standardised_on_the_training_part(data, task, protocol, standardised):
    x, samples = data
    cell = _cell(task=task, protocol=protocol, split="location_held_out")
    res = run_cell(x, samples, cell, Hyper(lr=1e-3, epochs=1, batch_size=64, norm="raw"), validation_fraction=0.2, factory=factory())
    if not standardised:
        assert res.state["target_stats"] is None
        return
    y, _ = targets(samples, task)
    split, _ = partition(samples, y, cell, 0.2)
    mean, std, lo, hi = np.asarray(res.state["target_stats"])
    assert np.allclose(mean, y[split.train].mean(axis=0)) and np.allclose(std, y[split.train].std(axis=0))
    assert np.allclose(lo, y[split.train].min(axis=0) - WORKSPACE_MARGIN) and np.allclose(hi, y[split.train].max(axis=0) + WORKSPACE_MARGIN)
    # the network's own outputs are standardised, through the bounded head; the cell's metrics are in metres (errors of cm, not of std units)
    model = cnn1d("location", 2, x.shape[1:])
    model.load_state_dict(res.state["model"])
    raw = infer(model, torch.from_numpy(x[split.test]))
    lo_z, hi_z = (lo - mean) / std, (hi - mean) / std
    metres = mean + std * ((hi_z + lo_z) / 2 + (hi_z - lo_z) / 2 * np.tanh((raw - (hi_z + lo_z) / 2) / ((hi_z - lo_z) / 2)))
    assert res.metrics.test["rmse"] == pytest.approx(float(np.sqrt(np.mean((metres - y[split.test]) ** 2))), rel=1e-4)
    assert res.metrics.test["rmse"] != pytest.approx(float(np.sqrt(np.mean((raw - y[split.test]) ** 2))), rel=1e-2)


def test_the_bounded_head_keeps_positions_in_the_box_whatever_the_input(data):
    """Inputs far brighter than any training one (a held-out size) drive the
    network's raw outputs far out; its positions stay inside the training box."""
    x, samples = data
    cell = _cell(task="location", split="size_held_out")
    res = run_cell(x, samples, cell, Hyper(lr=1e-3, epochs=2, batch_size=64, norm="raw"), validation_fraction=0.2, factory=factory())
    stats = res.state["target_stats"]
    model = cnn1d("location", 2, x.shape[1:])
    model.load_state_dict(res.state["model"])
    raw = infer(model, torch.from_numpy(x * 1000))
    lo, hi = np.asarray(stats[2:])
    unbounded = to_metres(raw, stats[:2])
    assert ((unbounded < lo) | (unbounded > hi)).any()  # the input does leave the box without the head
    bounded = to_metres(raw, stats)
    assert ((bounded >= lo - 1e-6) & (bounded <= hi + 1e-6)).all()  # float32 at a wall


def test_cells_are_deterministic_and_learn(data):
    x, samples = data
    a = run_cell(x, samples, _cell(task="size"), HP, validation_fraction=0.2, factory=factory())
    b = run_cell(x, samples, _cell(task="size"), HP, validation_fraction=0.2, factory=factory())
    assert a.metrics.test == b.metrics.test
    assert all(torch.equal(a.state["model"][k], b.state["model"][k]) for k in a.state["model"])
    assert a.metrics.test["top1"] > 0.8 > a.metrics.baseline["top1"]


def test_training_device_is_the_gpu_whenever_torch_sees_one():
    # `denali train` passes torch.cuda.is_available(): a flag, so both branches run without a GPU
    assert training_device(cuda_available=True) == "cuda"
    assert training_device(cuda_available=False) == "cpu"


def test_a_bfloat16_cell_learns_keeps_float32_weights_and_records_its_precision(data):
    # bfloat16 autocast runs on any CPU (emulated without AMX or AVX-512 BF16): the same cell as in float32 must still learn
    x, samples = data
    res = run_cell(x, samples, _cell(task="size"), HP, validation_fraction=0.2, factory=factory(), precision="bfloat16")
    m = res.metrics
    assert m.precision == "bfloat16" and m.precision_check is None and m.test["top1"] > 0.8 > m.baseline["top1"]
    assert all(v.dtype == torch.float32 for v in res.state["model"].values() if v.is_floating_point())
    f32 = run_cell(x, samples, _cell(task="size"), HP, validation_fraction=0.2, factory=factory())
    assert f32.metrics.precision == "float32"
    assert not all(torch.equal(res.state["model"][k], f32.state["model"][k]) for k in f32.state["model"])


@pytest.mark.parametrize("native", [True, False])
def test_an_auto_cell_records_the_check_that_chose_its_precision_where_one_ran(data, native):
    # `denali train` passes torch's AMX and AVX-512 BF16 probes: a flag, so both branches run on any CPU
    x, samples = data
    m = run_cell(x, samples, _cell(task="size"), HP, validation_fraction=0.2, factory=factory(), precision="auto", native_bf16=native).metrics
    if native:
        assert m.precision_check["bfloat16"] is True and m.precision == "bfloat16"
        assert m.precision_check["finite"] and m.precision_check["repeatable"] and m.precision_check["grad_error"] < 0.5
    else:
        assert m.precision == "float32" and m.precision_check is None


def test_inference_in_bfloat16_returns_float32_close_to_float32_inference():
    """Validation passes run in the training precision: bfloat16 outputs are
    float32 arrays within bfloat16's rounding (3 significant digits) of float32's."""
    torch.manual_seed(0)
    model = cnn1d("location", 2, (3, 3, 40))
    x = torch.randn(300, 3, 3, 40)
    f32, b16 = infer(model, x), infer(model, x, "cpu", torch.bfloat16)
    assert f32.dtype == b16.dtype == np.float32 and f32.shape == b16.shape == (300, 2)
    assert not np.array_equal(f32, b16)
    np.testing.assert_allclose(b16, f32, rtol=0.05, atol=0.05 * np.abs(f32).max())


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("task", ["size", "location"])  # location: the bounded head's box on the device
def test_a_cell_trains_and_is_recorded_on_the_gpu(data, task):
    x, samples = data
    res = run_cell(x, samples, _cell(task=task), HP, validation_fraction=0.2, factory=factory(), device=training_device(True))
    assert res.metrics.device.startswith("cuda")
    if task == "size":
        assert res.metrics.test["top1"] > 0.8 > res.metrics.baseline["top1"]
    else:
        assert np.isfinite(res.metrics.test["rmse"]) and len(res.state["target_stats"]) == 4


def test_linear_cell_beats_the_baseline(data):
    x, samples = data
    res = run_linear(x, samples, _cell(model="linear", task="location"), validation_fraction=0.2)
    m = res.metrics
    assert m.test["rmse"] < 0.5 * m.baseline["rmse"]
    assert m.selected_on == "validation" and m.selected_regularisation in m.hyper["regularisation"]
    res = run_linear(x, samples, _cell(model="linear", task="shape", split="size_held_out"), validation_fraction=0.2)
    assert res.metrics.test["top1"] > 1 / len(CLASSES)


def test_unknown_protocol_is_refused(data):
    x, samples = data
    with pytest.raises(ValueError, match="unknown protocol"):
        run_cell(x, samples, _cell(protocol="sloppy"), HP, validation_fraction=0.2, factory=factory())


@pytest.mark.parametrize("model", ["mlp", "cnn1d", "cnn3d", "transformer"])
def test_fit_trains_every_batch_down_to_a_last_one_of_one_sample(data, model):
    x, samples = data
    hp = Hyper(lr=1e-3, epochs=1, batch_size=8, norm="raw")
    torch.manual_seed(0)
    net = PAPER_MODELS[model]("shape", len(CLASSES), (3, 3, BINS))
    y = torch.from_numpy(np.array(targets(samples, "shape")[0][:9]))  # pandas hands out read-only views
    seen = []
    fitted = fit(net, torch.from_numpy(x[:9]), y, hp, 0, loss_for("shape"), lambda e, rows, out: seen.append(len(rows)) or 0.0)
    assert fitted.samples_seen == 9 and seen == [9]


def test_fit_keeps_the_best_scoring_epoch_or_the_last(data, caplog):
    x, samples = data
    xt, yt = torch.from_numpy(x[:100]), torch.from_numpy(np.array(targets(samples, "location")[0][:100]))
    hp = Hyper(lr=1e-3, epochs=3, batch_size=64, norm="raw")
    states = []

    def score(epoch, rows, out):
        states.append({k: v.clone() for k, v in net.state_dict().items()})
        return {1: 0.0, 2: 5.0, 3: 1.0}[epoch]

    net = cnn1d("location", 2, (3, 3, BINS))
    with caplog.at_level(logging.INFO, logger="denali_pipe.train.training"):
        fitted = fit(net, xt, yt, hp, 0, loss_for("location"), score, name="probe")
    assert fitted.best_epoch == 2 and fitted.epochs_run == 3 and fitted.samples_seen == 3 * len(xt)
    assert all(torch.equal(net.state_dict()[k], states[1][k]) for k in states[1])
    # stderr is no terminal under pytest: one log line per epoch, no bar
    assert [r.getMessage().split(",")[0] for r in caplog.records] == [f"probe: epoch {e}/3" for e in (1, 2, 3)]
    net = cnn1d("location", 2, (3, 3, BINS))
    assert fit(net, xt, yt, hp, 0, loss_for("location")).best_epoch == 3
