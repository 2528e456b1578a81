"""The dtype a network trains in, and the check that earns bfloat16 its place.

Under `train.precision: auto` a network trains in bfloat16 (torch.autocast)
only where two things hold: the CPU multiplies bfloat16 natively, and a short
check on this CPU, with this model, task and input shape, shows bfloat16's
passes agree with float32's (`check_bfloat16`). Elsewhere it trains in float32.

Why a check and not only the CPU's flags: oneDNN 3.12 (torch 2.13) computes
the weight gradient of a bfloat16 Conv3d wrongly when the kernel is larger
than the input it slides over (`jit_bf16:avx512_core_bf16`, backward_weights).
The 3D CNN's shape model at 3x3 (kernel 5 x 5 over 3 x 3 zones, padding 2) is
such a layer: the kernel's first three depth taps get values read from
memory the kernel never wrote, 1e11-1e35 times the true gradient or NaN, and
which of the two varies from run to run. Its 8x8 layer, and every other
layer of the paper's four models, agree with float32 (docs/deviations.md,
"Training precision").
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import asdict, dataclass

import torch
from torch import nn

from denali_pipe.train.cells import PRECISIONS

# A check's batch: two samples, two optimiser steps; random inputs of unit
# scale (the kernels' faults depend on the shapes, not on the values).
CHECK_BATCH, CHECK_STEPS, CHECK_SEED, CHECK_LR = 2, 2, 0, 1e-3
# Tolerances, relative. On an AMD EPYC with AVX-512 BF16 the paper's four
# models, every task, at 3x3 and 8x8, give at most 0.11 on a parameter's
# first gradient (a two-class head's bias, from two samples) and 0.021 on a
# step's loss; the faulty Conv3d gives 1e11 and more, or NaN.
GRAD_TOLERANCE = 0.5
LOSS_TOLERANCE = 0.1


@dataclass(frozen=True)
class PrecisionCheck:
    """What `check_bfloat16` measured, as metrics.json records it.

    grad_error: the largest ||g_bf16 - g_f32|| / ||g_f32|| over the model's
    parameters at the first step (the same weights, batch and dropout masks);
    worst_parameter: which. loss_error: the largest |L_bf16 - L_f32| / |L_f32|
    over the steps, each precision stepping its own copy. finite: every loss
    and gradient of the bfloat16 runs finite. repeatable: two bfloat16 runs
    gave bit-identical losses and gradients."""

    grad_error: float
    worst_parameter: str
    loss_error: float
    finite: bool
    repeatable: bool

    @property
    def passed(self) -> bool:
        return self.finite and self.repeatable and self.grad_error <= GRAD_TOLERANCE and self.loss_error <= LOSS_TOLERANCE

    def record(self) -> dict:
        """metrics.json's `precision_check`: the verdict and the fields
        (infinities as None, JSON having none). Where the two bfloat16 runs
        differed, the numbers are a faulty kernel's and change from run to
        run, so only the verdict is kept (the job's log has the numbers)."""
        fields = {k: (None if isinstance(v, float) and v == float("inf") else v) for k, v in asdict(self).items()}
        if not self.repeatable:
            fields = {k: (False if k == "repeatable" else None) for k in fields}
        return {**fields, "bfloat16": self.passed}


def _steps(model: nn.Module, x: torch.Tensor, y: torch.Tensor, loss: nn.Module, dtype: torch.dtype) -> tuple[list[torch.Tensor], dict[str, torch.Tensor]]:
    """CHECK_STEPS Adam steps of `model` (changed in place) on (x, y) in
    `dtype`: each step's loss (0-d float32) and the first step's gradients."""
    torch.manual_seed(CHECK_SEED)  # the same dropout masks in every run
    opt = torch.optim.Adam(model.parameters(), lr=CHECK_LR)
    losses, grads = [], {}
    model.train()
    for step in range(CHECK_STEPS):
        opt.zero_grad(set_to_none=True)
        with torch.autocast(x.device.type, dtype=dtype, enabled=dtype != torch.float32):
            out = model(x)
        batch_loss = loss(out.float(), y)
        batch_loss.backward()
        if step == 0:
            grads = {n: p.grad.detach().float().clone() for n, p in model.named_parameters() if p.grad is not None}
        losses.append(batch_loss.detach().float())
        opt.step()
    return losses, grads


def check_bfloat16(model: nn.Module, input_shape: tuple[int, ...], task: str, n_outputs: int, loss: nn.Module) -> PrecisionCheck:
    """Train copies of `model` (untouched, its device's) for CHECK_STEPS steps
    on a fixed random batch of CHECK_BATCH samples of `input_shape`, once in
    float32 and twice in bfloat16, and compare (`PrecisionCheck`). The global
    RNG is left as it was found, so a cell's own training draws what it would
    without the check. n_outputs: 2 (location, standardised targets) or the classes."""
    param = next(model.parameters())
    with torch.random.fork_rng(devices=[]):
        gen = torch.Generator().manual_seed(CHECK_SEED)
        x = torch.randn(CHECK_BATCH, *input_shape, generator=gen).to(param.device)
        if task == "location":
            y = torch.randn(CHECK_BATCH, n_outputs, generator=gen)
        else:
            y = torch.randint(0, n_outputs, (CHECK_BATCH,), generator=gen)
        y = y.to(param.device)
        ref_losses, ref_grads = _steps(copy.deepcopy(model), x, y, loss, torch.float32)
        runs = [_steps(copy.deepcopy(model), x, y, loss, torch.bfloat16) for _ in range(2)]
    (losses, grads), (losses2, grads2) = runs
    finite = all(bool(torch.isfinite(v).all()) for v in [*losses, *grads.values()])
    repeatable = all(torch.equal(a, b) for a, b in zip(losses, losses2)) and all(torch.equal(grads[n], grads2[n]) for n in grads)
    errors = {n: _relative(grads[n], g) for n, g in ref_grads.items()}
    worst = max(errors, key=errors.get)
    loss_error = max(_relative(a, b) for a, b in zip(losses, ref_losses))
    return PrecisionCheck(errors[worst], worst, loss_error, finite, repeatable)


def _relative(a: torch.Tensor, ref: torch.Tensor) -> float:
    """||a - ref|| / ||ref||: inf where a is not finite, 0 where both are zero."""
    diff, scale = float((a - ref).norm()), float(ref.norm())
    if diff != diff:  # NaN
        return float("inf")
    return diff / scale if scale > 0 else (0.0 if diff == 0 else float("inf"))


def training_precision(setting: str, device: str, cpu_has_native_bf16: bool, check: Callable[[], PrecisionCheck]) -> tuple[torch.dtype, PrecisionCheck | None]:
    """The dtype a network's training passes and its per-epoch validation
    (model selection) compute in (`torch.autocast`; weights, gradients, the
    optimiser and the test split's predictions stay float32), and the check
    that decided it (None where none ran).

    setting: config `train.precision`. `auto` is bfloat16 on a CPU that
    multiplies bfloat16 natively (`cpu_has_native_bf16`: the 1D CNN trains
    2.0-2.7x faster on AMX, 2.0x on AVX-512 BF16, the 3D CNN 4x on AMX;
    docs/performance.md) where `check()` passes, and float32 elsewhere:
    without those instructions bfloat16 is emulated and gains little, and on
    CUDA (an H200, measured) these launch-bound networks train no faster in
    it. `float32` and `bfloat16` are taken as asked, unchecked."""
    if setting not in PRECISIONS:
        raise ValueError(f"unknown precision {setting!r}; expected one of {PRECISIONS}")
    if setting != "auto":
        return getattr(torch, setting), None
    if device != "cpu" or not cpu_has_native_bf16:
        return torch.float32, None
    verdict = check()
    return (torch.bfloat16 if verdict.passed else torch.float32), verdict


def cpu_has_native_bf16() -> bool:
    """Whether this CPU multiplies bfloat16 natively, which oneDNN's kernels
    use under autocast: AMX tiles (Intel Sapphire Rapids and later) or
    AVX-512 BF16's dot products (Intel Cooper Lake and later, AMD Zen 4 and
    later). Private torch functions, so torch's pin (pyproject.toml) keeps them."""
    return torch.cpu._is_amx_tile_supported() or torch.cpu._is_avx512_bf16_supported()
