"""Where a diverged training epoch first went non-finite, found by replaying it.

`fit` checks its losses and weights once an epoch (a check per step would
cost every healthy step a synchronisation). When an epoch ends non-finite,
`replay` runs that epoch again from a snapshot taken at its start, the same
batches and random state, checking every module's output, the loss, every
gradient and every updated weight as it goes, and names the first tensor
that is not finite. A kernel that gives a different answer on the same
inputs can stay finite in the replay; `replay` then says so.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class Snapshot:
    """An epoch's starting point: the model's and the optimiser's state and the
    random state of the model's device (dropout's masks: the CPU's, and the
    GPU's where the model is on one); the batches' order is the caller's."""

    model: dict
    optimiser: dict
    rng: torch.Tensor
    cuda_rng: torch.Tensor | None

    @classmethod
    def take(cls, model: nn.Module, opt: torch.optim.Optimizer) -> Snapshot:
        device = next(model.parameters()).device
        cuda_rng = torch.cuda.get_rng_state(device) if device.type == "cuda" else None
        return cls(copy.deepcopy(model.state_dict()), copy.deepcopy(opt.state_dict()), torch.get_rng_state(), cuda_rng)

    def restore(self, model: nn.Module, opt: torch.optim.Optimizer) -> None:
        model.load_state_dict(self.model)
        opt.load_state_dict(self.optimiser)
        torch.set_rng_state(self.rng)
        if self.cuda_rng is not None:
            torch.cuda.set_rng_state(self.cuda_rng, next(model.parameters()).device)


def all_finite(tensors) -> bool:
    return all(bool(torch.isfinite(t).all()) for t in tensors if torch.is_floating_point(t))


def state_finite(model: nn.Module, opt: torch.optim.Optimizer) -> bool:
    """Whether the model's parameters and the optimiser's moments are all finite."""
    return all_finite(model.parameters()) and all_finite(v for s in opt.state.values() for v in s.values())


def replay(
    model: nn.Module,
    opt: torch.optim.Optimizer,
    snapshot: Snapshot,
    batches: list[torch.Tensor],
    x: torch.Tensor,
    y: torch.Tensor,
    loss: nn.Module,
    head: Callable[[torch.Tensor], torch.Tensor] | None,
    precision: torch.dtype,
) -> tuple[int, str] | None:
    """(step, what) of the first non-finite tensor in the epoch that began at
    `snapshot` and ran `batches` (row indices of x and y), steps counted from
    1; None if the replay stays finite. The model and optimiser end in the
    replay's state."""
    snapshot.restore(model, opt)
    if not all_finite(model.parameters()):
        return 0, "a weight at the epoch's start"
    first: list[str] = []

    def watch(name: str):
        def hook(module, inputs, output):
            outs = output if isinstance(output, tuple) else (output,)
            if not first and not all_finite(o for o in outs if isinstance(o, torch.Tensor)):
                first.append(f"the output of {name} ({type(module).__name__}) in the forward pass")

        return hook

    handles = [m.register_forward_hook(watch(n)) for n, m in model.named_modules() if n and not list(m.children())]
    model.train()
    try:
        for step, idx in enumerate(batches, start=1):
            if not all_finite([x[idx]]):
                return step, "the batch's inputs"
            opt.zero_grad(set_to_none=True)
            with torch.autocast(x.device.type, dtype=precision, enabled=precision != torch.float32):
                out = model(x[idx])
            if first:
                return step, first[0]
            batch_loss = loss(out.float() if head is None else head(out.float()), y[idx])
            if not all_finite([batch_loss]):
                return step, "the loss"
            batch_loss.backward()
            for name, p in model.named_parameters():
                if p.grad is not None and not all_finite([p.grad]):
                    return step, f"the gradient of {name} in the backward pass"
            opt.step()
            for name, p in model.named_parameters():
                if not all_finite([p]):
                    return step, f"{name} after the optimiser's update"
    finally:
        for h in handles:
            h.remove()
    return None


@dataclass
class Losses:
    """The batch losses of a run's finished epochs, as far as a divergence
    needs them: the first step's and the largest."""

    first: float | None = None
    largest: float = 0.0

    def add(self, losses: torch.Tensor) -> None:
        """Take an epoch's (n_steps,) batch losses; the finite ones count."""
        finite = losses[torch.isfinite(losses)]
        if len(finite) == 0:
            return
        if self.first is None:
            self.first = float(finite[0])
        self.largest = max(self.largest, float(finite.max()))


# The loss has grown when it passed this multiple of the run's first batch loss.
GROWTH = 2.0


def diverged(name: str, epoch: int, losses: torch.Tensor, history: Losses, lr: float, precision: torch.dtype, found: tuple[int, str] | None) -> str:
    """The message of a run whose epoch `epoch` ended non-finite: its (n_steps,)
    batch losses `losses`, the finished epochs' `history`, and what `replay`
    found. It suggests float32 where the run trained in bfloat16, and a lower
    learning rate only where the loss had grown first."""
    bad = (~torch.isfinite(losses)).nonzero()
    k = int(bad[0]) if len(bad) else len(losses)
    before = Losses(history.first, history.largest)
    before.add(losses[:k])
    parts = [f"{name}: training diverged in epoch {epoch}"]
    if len(bad):
        parts.append(f"the loss was {float(losses[k])} at step {k + 1}")
    if found is None:
        parts.append("its replay from the epoch's start stayed finite, so a kernel gave different results on the same inputs")
    else:
        step, what = found
        parts.append(f"the first non-finite tensor is {what}" + (f" at step {step}" if step else ""))
    grown = before.first is not None and before.largest > GROWTH * before.first
    if precision != torch.float32:
        parts.append(f"it trained in {str(precision).removeprefix('torch.')}: train it in float32 (config train.precision: float32)")
    if grown:
        parts.append(f"the loss had grown from {before.first:.4g} to {before.largest:.4g} first: lower the learning rate (lr {lr:g})")
    elif precision == torch.float32:
        parts.append("the loss had not grown first, so the learning rate is not the likely cause")
    return "; ".join(parts)
