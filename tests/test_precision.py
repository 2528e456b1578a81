"""The training precision and the check behind `auto` (train.precision)."""

import pytest
import torch
from torch import nn

from denali_pipe.train.models import PAPER_MODELS
from denali_pipe.train.precision import GRAD_TOLERANCE, PrecisionCheck, check_bfloat16, cpu_has_native_bf16, training_precision
from denali_pipe.train.training import Hyper, fit, loss_for

PASSES = PrecisionCheck(0.01, "w", 0.001, finite=True, repeatable=True)
FAILS = PrecisionCheck(float("inf"), "features.0.weight", 0.003, finite=True, repeatable=False)


def never_called() -> PrecisionCheck:
    raise AssertionError("no check should run here")


def test_auto_is_bfloat16_only_on_a_native_cpu_where_the_check_passes():
    assert training_precision("auto", "cpu", True, lambda: PASSES) == (torch.bfloat16, PASSES)
    assert training_precision("auto", "cpu", True, lambda: FAILS) == (torch.float32, FAILS)
    # no check where bfloat16 is not on offer
    assert training_precision("auto", "cpu", False, never_called) == (torch.float32, None)
    assert training_precision("auto", "cuda", True, never_called) == (torch.float32, None)


def test_an_asked_for_precision_is_taken_unchecked():
    assert training_precision("bfloat16", "cpu", False, never_called) == (torch.bfloat16, None)
    assert training_precision("float32", "cpu", True, never_called) == (torch.float32, None)
    with pytest.raises(ValueError, match="unknown precision 'half'"):
        training_precision("half", "cpu", True, never_called)


class WrongInBfloat16(torch.autograd.Function):
    """The identity, whose backward in bfloat16 passes back a gradient
    `factor` times too large: a kernel's fault, on any CPU."""

    @staticmethod
    def forward(ctx, x, factor):
        ctx.factor = factor
        return x.clone()

    @staticmethod
    def backward(ctx, g):
        return (g * ctx.factor if g.dtype == torch.bfloat16 else g), None


class Probe(nn.Module):
    def __init__(self, factor: float):
        super().__init__()
        self.linear, self.factor = nn.Linear(12, 2), factor

    def forward(self, x):
        return WrongInBfloat16.apply(self.linear(x.flatten(1)), self.factor)


def test_the_check_passes_a_sound_model_and_refuses_a_wrong_gradient():
    torch.manual_seed(0)
    sound = check_bfloat16(Probe(1.0), (2, 2, 3), "size", 2, loss_for("size"))
    assert sound.passed and sound.finite and sound.repeatable and sound.grad_error < 0.05
    wrong = check_bfloat16(Probe(10.0), (2, 2, 3), "size", 2, loss_for("size"))
    assert not wrong.passed and wrong.grad_error > GRAD_TOLERANCE
    nan = check_bfloat16(Probe(float("nan")), (2, 2, 3), "size", 2, loss_for("size"))
    assert not nan.passed and not nan.finite and nan.record()["grad_error"] is None and nan.record()["bfloat16"] is False


def test_a_check_whose_bfloat16_runs_differ_records_its_verdict_alone():
    # a faulty kernel's numbers change from run to run; metrics.json must not
    flaky = PrecisionCheck(3.2e11, "features.0.weight", 0.0096, finite=True, repeatable=False)
    assert flaky.record() == {
        "grad_error": None, "worst_parameter": None, "loss_error": None, "finite": None, "repeatable": False, "bfloat16": False,
    }  # fmt: skip
    assert PASSES.record() == {"grad_error": 0.01, "worst_parameter": "w", "loss_error": 0.001, "finite": True, "repeatable": True, "bfloat16": True}


def test_the_check_leaves_the_model_and_the_random_state_untouched():
    torch.manual_seed(0)
    model = PAPER_MODELS["cnn1d"]("size", 2, (3, 3, 16))
    before = {k: v.clone() for k, v in model.state_dict().items()}
    torch.manual_seed(1)
    check_bfloat16(model, (3, 3, 16), "size", 2, loss_for("size"))
    after_check = torch.rand(3)
    torch.manual_seed(1)
    assert torch.equal(after_check, torch.rand(3))
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())


# The tiny preset's 3x3 histograms, cropped shorter: the kernels' faults depend on the zones, not on the bins.
SHAPE, STEPS, RUNS = (3, 3, 24), 3, 3


@pytest.mark.parametrize("task", ["location", "shape", "size"])
@pytest.mark.parametrize("name", sorted(PAPER_MODELS))
def test_every_paper_model_trains_finite_and_repeatably_in_the_precision_auto_picks_here(name, task):
    """What `auto` gives on the machine running the tests (bfloat16 where it
    multiplies it natively and the check passes), trained a few steps
    several times from the same seed: every run finite, all runs equal.
    Without the check, the 3D CNN's shape model gives NaN or garbage here on
    CPUs with AVX-512 BF16 (precision.py)."""
    n_out = 2 if task != "shape" else 5
    torch.manual_seed(0)
    model = PAPER_MODELS[name](task, n_out, SHAPE)
    dtype, check = training_precision("auto", "cpu", cpu_has_native_bf16(), lambda: check_bfloat16(model, SHAPE, task, n_out, loss_for(task)))
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(8, *SHAPE, generator=gen)
    y = torch.randn(8, 2, generator=gen) if task == "location" else torch.randint(0, n_out, (8,), generator=gen)
    hp = Hyper(lr=1e-3, epochs=1, batch_size=8 // STEPS + 1, norm="raw")
    states = []
    for _ in range(RUNS):
        trained = PAPER_MODELS[name](task, n_out, SHAPE)
        trained.load_state_dict(model.state_dict())
        torch.manual_seed(2)
        states.append(fit(trained, x, y, hp, 0, loss_for(task), name=f"{name} {task}", precision=dtype).state)
    assert all(torch.isfinite(v).all() for v in states[0].values() if v.is_floating_point()), (dtype, check)
    assert all(torch.equal(states[0][k], s[k]) for s in states[1:] for k in s), (dtype, check)
