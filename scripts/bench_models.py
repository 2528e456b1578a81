#!/usr/bin/env python
"""Benchmark training throughput of the four models; prints a table, asserts nothing.

    python scripts/bench_models.py               # 2 CPU threads, 3x3 zones
    python scripts/bench_models.py --threads 1 --precision bfloat16   # as a cell under train.precision auto on AMX or AVX-512 BF16
    python scripts/bench_models.py --device cuda --precision bfloat16  # on the first GPU
    OMP_WAIT_POLICY=PASSIVE python scripts/bench_models.py   # on a busy machine

Samples per second of a full training step (forward, loss, backward, Adam step)
in train mode, with the plain loop a trainer would use without a DataLoader:
index a random batch out of an in-memory tensor. Inputs are random normal
(log+z-scored histograms look like that); the loss is the reference's:
MSELoss(reduction="sum") for location, cross-entropy for shape; forward
passes in `--precision` as `train.fit` runs them (bfloat16: torch.autocast,
the loss in float32). Rows are the
location models plus the shallow shape 3D CNN, which is a different network
(the Transformer classifier costs the same as the regressor).

Each cell times whole steps for about STEP_BUDGET_S after one warm-up step.
The deep 3D CNN and the Transformer need seconds per step on a CPU: where the
warm-up step takes longer than SLOW_STEP_S it is the measurement ("1 cold step",
first-call set-up included, a small share of such a step), and cells whose step
would take longer than MAX_STEP_S are skipped, with the rate extrapolated from
the smaller batch in brackets. Anything else running on the machine slows every
figure down, and more than its share: OpenMP threads spin while they wait for
each other, so with other jobs on the cores a 2-thread step can take 5-10x
longer than a 1-thread one. OMP_WAIT_POLICY=PASSIVE (read when torch loads)
avoids that; the header line says which policy the figures were taken with.
"""

from __future__ import annotations

import argparse
import os
import time

import torch
from torch import nn

from denali_pipe.train.models import PAPER_MODELS, n_params
from denali_pipe.train.registry import n_outputs

N = 3  # zones per side
BINS = (128, 56)  # full histograms; cropped after the first bounce
BATCHES = (64, 256)
ROWS = (("mlp", "location"), ("cnn1d", "location"), ("cnn3d", "location"), ("cnn3d", "shape"),
        ("transformer", "location"))  # fmt: skip
N_CLASSES = 30  # the benchmark's shape classes
STEP_BUDGET_S = 1.5  # timed seconds per cell
SLOW_STEP_S = 2.0  # a warm-up step longer than this is the measurement itself
MAX_STEP_S = 20.0  # skip cells whose single step would take longer


def build(name: str, task: str, bins: int) -> nn.Module:
    return PAPER_MODELS[name](task, n_outputs(task, N_CLASSES), (N, N, bins))


def step_fn(model: nn.Module, task: str, x: torch.Tensor, y: torch.Tensor, batch: int, precision: torch.dtype):
    """One training step on a random batch of (x, y), as a closure; on CUDA
    it waits for the GPU to finish, so that wall-clock times are the step's."""
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    loss_fn = nn.MSELoss(reduction="sum") if task == "location" else nn.CrossEntropyLoss()

    def step() -> None:
        idx = torch.randint(len(x), (batch,), device=x.device)
        opt.zero_grad(set_to_none=True)
        with torch.autocast(x.device.type, dtype=precision, enabled=precision != torch.float32):
            out = model(x[idx])
        loss_fn(out.float(), y[idx]).backward()
        opt.step()
        if x.device.type == "cuda":
            torch.cuda.synchronize()

    return step


def throughput(name: str, task: str, bins: int, batch: int, est_step_s: float | None, precision: torch.dtype, device: str) -> tuple[float, str]:
    """(samples/s, note) for one cell; `est_step_s` is the step time expected from a smaller batch."""
    if est_step_s is not None and est_step_s > MAX_STEP_S:
        return batch / est_step_s, "skipped"
    torch.manual_seed(0)
    model = build(name, task, bins).train().to(device)
    n_samples = 4 * batch
    x = torch.randn(n_samples, N, N, bins, device=device)
    y = torch.rand(n_samples, 2, device=device) if task == "location" else torch.randint(n_outputs(task, N_CLASSES), (n_samples,), device=device)
    step = step_fn(model, task, x, y, batch, precision)
    t0 = time.perf_counter()
    step()  # warm-up: allocations, oneDNN primitives or cuDNN kernels for these shapes
    first = time.perf_counter() - t0
    if first > SLOW_STEP_S:
        return batch / first, "1 cold step"
    steps, t0 = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - t0) < STEP_BUDGET_S:
        step()
        steps += 1
    return steps * batch / elapsed, f"{steps} step" + "s" * (steps > 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    parser.add_argument("--device", default="cpu", help="torch device: cpu, or cuda for the first GPU")
    parser.add_argument("--precision", choices=("float32", "bfloat16"), default="float32", help="the training passes' dtype (train.precision)")
    args = parser.parse_args()
    precision = getattr(torch, args.precision)
    torch.set_num_threads(args.threads)
    policy = os.environ.get("OMP_WAIT_POLICY", "default")
    where = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else f"{args.threads} CPU threads"
    print(f"training samples/s, {N}x{N} zones, {where}, {args.precision}, OMP_WAIT_POLICY {policy}, torch {torch.__version__}")
    columns = "".join(f"{f'bins {bins} batch {batch}':>24}" for bins in BINS for batch in BATCHES)
    print(f"{'model':<12}{'task':<10}{'params':>11}{columns}")
    t_start = time.perf_counter()
    for name, task in ROWS:
        cells = []
        for bins in BINS:
            est = None
            for batch in BATCHES:
                rate, note = throughput(name, task, bins, batch, est, precision, args.device)
                est = BATCHES[-1] / rate  # step time at the larger batch, if time grows linearly with it
                cells.append(f"[{rate:.1f}] {note}" if note == "skipped" else f"{rate:.1f} ({note})")
        params = n_params(build(name, task, BINS[0]))
        print(f"{name:<12}{task:<10}{params:>11,}" + "".join(f"{c:>24}" for c in cells), flush=True)
    print(f"total {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
