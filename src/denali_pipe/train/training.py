"""One training cell: a model trained for one task on one split, one seed;
and `fit`, the one training loop that the cells and every experiment that
trains a network (Fig 9, the jitter sweep) go through.

Two protocols:
- `paper`: as the reference does it: raw counts of every zone and bin
  (paper_inputs.py; the DAG hands its cells those samples), its transform
  with statistics over all samples, every epoch evaluated on the test split
  and the best test epoch kept. Kept for comparability with the paper's
  numbers; it leaks.
- `clean` (default): a validation part is carved out of the training split
  (the same kind of hold-out as the split itself), normalisation statistics
  come from the remaining training part only, the best validation epoch is
  kept and the test split is evaluated once, with that model. Location
  networks regress positions standardised on the training part (each
  coordinate's mean and std), through a bounded head (a tanh into the
  training positions' box and half a gantry step), mapped back to metres for
  every metric and prediction: a network's outputs start near zero, that is
  at the training mean, an input unlike the training ones (a held-out size,
  several times brighter) moves them in units of the training spread, not of
  metres, and no input moves them out of the box.

Training follows the reference (docs/deviations.md): Adam (betas 0.9/0.999, no weight decay,
no schedule), cross-entropy for classification, summed MSE on the position
targets for regression (metres; clean: standardised, see above); the best
epoch is chosen on Top-1 (classification) or MAE (regression). Batches are drawn by indexing one in-memory tensor (no
DataLoader: its per-batch overhead halves throughput for models this small).
"""

from __future__ import annotations

import copy
import logging
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from torch import nn
from tqdm import tqdm

from denali_pipe.core.geometry import WORKSPACE_MARGIN
from denali_pipe.core.splits import Split, make_split, validation_split
from denali_pipe.preprocess.histograms import normalise
from denali_pipe.train import metrics as M
from denali_pipe.train import paper_inputs
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import PROTOCOLS, TASKS, Cell
from denali_pipe.train.divergence import Losses, Snapshot, diverged, replay, state_finite
from denali_pipe.train.models import forward_flops, n_params
from denali_pipe.train.precision import check_bfloat16, training_precision
from denali_pipe.train.registry import build
from denali_pipe.train.release_nets import init_from_release, init_path
from denali_pipe.train.saved_cell import SavedCell

log = logging.getLogger(__name__)

SIZE_CLASSES = ("4inch", "8inch")
# Inference batch: small enough that a 1D CNN batch's activations (128
# channels x 77 bins each) stay within a core's cache. On one core of an AMD
# EPYC, 128 samples infer 2x faster than 1,024 in bfloat16 and 3x in float32.
EVAL_BATCH = 128
MIN_TARGET_STD = 1e-3  # m: a training part at one position still standardises


@dataclass(frozen=True)
class Hyper:
    """Training settings of one (model, task): learning rate, epochs, batch
    size, input normalisation ("raw" or "log_z"), and the release checkpoint
    a cell's network starts from instead of its initialisation
    ('release:<file>', release_nets.init_from_release; None: from scratch)."""

    lr: float
    epochs: int
    batch_size: int
    norm: str
    init: str | None = None


@dataclass
class Result:
    metrics: CellMetrics
    curves: pd.DataFrame  # long: epoch, part, metric, value
    state: dict  # what model.pt holds: a network's `SavedCell` record (saved_cell), the linear model's own dict


@dataclass
class Fitted:
    """What `fit` did. state: the model's state_dict at the selected epoch
    (loaded back into the model); train_seconds: time spent in training
    batches only (no evaluation)."""

    state: dict
    best_epoch: int
    epochs_run: int
    samples_seen: int
    train_seconds: float
    stopped_by_budget: bool


def targets(samples: pd.DataFrame, task: str) -> tuple[np.ndarray, list[str] | None]:
    """Labels of every sample: (N, 2) float32 metres for location; (N,) int64
    class indices and the class names (ASCII order, like sklearn's
    LabelEncoder) for shape and size."""
    if task == "location":
        return samples[["x", "y"]].to_numpy(np.float32), None
    if task == "shape":
        classes = sorted(samples["class"].unique())
        lookup = {c: i for i, c in enumerate(classes)}
        return samples["class"].map(lookup).to_numpy(np.int64), classes
    if task == "size":
        bad = sorted(set(samples["size"]) - set(SIZE_CLASSES))
        if bad:
            raise ValueError(f"unknown sizes {bad}; expected {SIZE_CLASSES}")
        return samples["size"].map({s: i for i, s in enumerate(SIZE_CLASSES)}).to_numpy(np.int64), list(SIZE_CLASSES)
    raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")


def target_statistics(task: str, protocol: str, y_train: np.ndarray) -> tuple[tuple[float, float], ...] | None:
    """((mean_x, mean_y), (std_x, std_y), (lo_x, lo_y), (hi_x, hi_y)) in m of
    the training positions y_train (N, 2) for a clean location cell, whose
    network regresses standardised positions through a bounded head
    (`position_head`): lo and hi are the training positions' box widened by
    the workspace's margin (geometry.WORKSPACE_MARGIN, half a gantry step).
    None (metre or class targets) otherwise. The first two rows alone
    (records of version 2) map without a bound."""
    if task != "location" or protocol != "clean":
        return None
    y = y_train.astype(np.float64)
    mean, std = y.mean(axis=0), np.maximum(y.std(axis=0), MIN_TARGET_STD)
    lo, hi = y.min(axis=0) - WORKSPACE_MARGIN, y.max(axis=0) + WORKSPACE_MARGIN
    return tuple((float(v[0]), float(v[1])) for v in (mean, std, lo, hi))


def standardise(y: np.ndarray, target_stats) -> np.ndarray:
    """Positions (N, 2) m as the network regresses them (`target_statistics`); y itself without stats."""
    if target_stats is None:
        return y
    mean, std = np.asarray(target_stats[:2], np.float32)
    return ((y - mean) / std).astype(np.float32)


def bounded(z, lo, hi, tanh):
    """z squashed into (lo, hi): the identity's slope at the box's middle, flat towards its walls."""
    mid, half = (hi + lo) / 2, (hi - lo) / 2
    return mid + half * tanh((z - mid) / half)


def standardised_box(target_stats) -> tuple[np.ndarray, np.ndarray] | None:
    """The bounded head's (lo, hi) (2,) each in standardised units; None without a box."""
    if target_stats is None or len(target_stats) < 4:
        return None
    mean, std, lo, hi = np.asarray(target_stats, np.float32)
    return (lo - mean) / std, (hi - mean) / std


def position_head(target_stats) -> Callable[[torch.Tensor], torch.Tensor] | None:
    """The bounded head that a clean location network's outputs (N, 2) pass
    through in training: each standardised coordinate squashed by a tanh into
    its box (`target_statistics`), so that no input, however unlike the
    training ones, moves a prediction out of the training positions' box and
    its margin. None for other cells."""
    box = standardised_box(target_stats)
    if box is None:
        return None
    lo, hi = (torch.from_numpy(b) for b in box)
    return lambda out: bounded(out, lo.to(out.device), hi.to(out.device), torch.tanh)


def to_metres(out: np.ndarray, target_stats) -> np.ndarray:
    """A network's outputs (N, C) as metres or logits: standardised positions
    through the bounded head (where the stats hold a box) mapped back; else unchanged."""
    if target_stats is None:
        return out
    mean, std = np.asarray(target_stats[:2], np.float32)
    box = standardised_box(target_stats)
    if box is not None:
        out = bounded(out, *box, np.tanh)
    return out * std + mean


def partition(samples: pd.DataFrame, y: np.ndarray, cell: Cell, validation_fraction: float) -> tuple[Split, np.ndarray | None]:
    """(train/test split, validation rows or None). Under `clean` the
    returned train rows exclude the validation rows."""
    stratify = None if cell.task == "location" else y
    split = make_split(samples, cell.split, cell.seed, stratify)
    if cell.protocol == "paper":
        return split, None
    inner = validation_split(samples, split.train, cell.split, cell.seed, validation_fraction, stratify)
    return Split(inner.train, split.test), inner.test


def training_device(cuda_available: bool) -> str:
    """The torch device a network trains on: `cuda` (the first GPU, or the
    one SLURM's --gpus gives the job) whenever torch sees one, else `cpu`.
    The cells, their tables and Table 10's timings record which."""
    return "cuda" if cuda_available else "cpu"


def infer(model: nn.Module, x: torch.Tensor, device: torch.device | str = "cpu", precision: torch.dtype = torch.float32) -> np.ndarray:
    """The model's outputs (N, C) float32 for x (N, ...) in eval mode, in
    batches of EVAL_BATCH moved to `device`: positions in metres or logits.
    precision: the forward pass's dtype (torch.autocast, as `fit`'s)."""
    model.eval()
    dev = torch.device(device)
    outs = []
    with torch.no_grad(), torch.autocast(dev.type, dtype=precision, enabled=precision != torch.float32):
        for i in range(0, len(x), EVAL_BATCH):
            outs.append(model(x[i : i + EVAL_BATCH].to(dev)).float().cpu())
    return torch.cat(outs).numpy()


def task_metrics(task: str, out: np.ndarray, y: np.ndarray) -> dict:
    """A cell's metrics of outputs `out` against labels `y`: location's errors
    and how many predictions leave the gantry's workspace; the classifiers'."""
    if task == "location":
        return {**M.regression_metrics(out, y), **M.workspace_metrics(out)}
    return M.classification_metrics(out, y)


def selection_key(task: str) -> tuple[str, int]:
    """(metric, sign): the best epoch maximises sign * metric."""
    return ("mae", -1) if task == "location" else ("top1", 1)


def loss_for(task: str) -> nn.Module:
    """The reference's losses: summed MSE on position targets (location),
    cross-entropy on logits (classification)."""
    return nn.MSELoss(reduction="sum") if task == "location" else nn.CrossEntropyLoss()


def baseline_output(task: str, y_train: np.ndarray, n_classes: int) -> np.ndarray:
    """The one output the mean / majority baseline gives every sample: (2,)
    the mean training position in m (location), or (n_classes,) scores
    ranking the classes by their training count (`metrics`' baselines)."""
    if task == "location":
        return M.predict_mean_baseline(y_train, 1)[0]
    return M.predict_majority_baseline(y_train, 1, n_classes)[0]


def baseline_metrics(task: str, y_train: np.ndarray, y_test: np.ndarray, n_classes: int) -> dict:
    """Predict-the-training-mean (location) or the training majority class, scored on y_test."""
    return task_metrics(task, np.tile(baseline_output(task, y_train, n_classes), (len(y_test), 1)), y_test)


def fit(
    model: nn.Module,
    x: torch.Tensor,
    y: torch.Tensor,
    hp: Hyper,
    seed: int,
    loss: nn.Module,
    evaluate_epoch: Callable[[int, np.ndarray, np.ndarray], float] | None = None,
    budget_seconds: float | None = None,
    name: str = "training",
    precision: torch.dtype = torch.float32,
    head: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> Fitted:
    """The one training loop: train `model` in place on x (N, ...) and y (N,
    ...), tensors on the model's device.

    Adam at hp.lr (betas 0.9/0.999, no weight decay, no schedule) for
    hp.epochs epochs; each epoch visits every sample once, in an order drawn
    from `seed`, in batches of hp.batch_size, the last one short (as the
    reference's DataLoader, drop_last False). A batch of one sample is fine
    for every model: the BatchNorm layers normalise over time (and zones) as
    well as over the batch, so they never see a single value per channel.

    evaluate_epoch(epoch, rows, outputs): called after each epoch with the
    rows of x trained on in it (batch order) and the model's train-mode
    outputs for them, (n, C) numpy; it returns the epoch's score, higher is
    better, and the best epoch's state is kept (the first on ties). Without
    it the last epoch's state is kept (a fixed number of epochs).

    budget_seconds: stop (mid-epoch if need be; that epoch is still
    evaluated) once this much training time is spent, so that models too
    slow for the machine still give a measured point; None trains every epoch.

    Non-finite inputs, or a NaN or infinite loss or weight at an epoch's end,
    raise ValueError naming `name`, the epoch and the step, and the first
    non-finite tensor (divergence.replay): the cell fails and nothing is
    selected or scored.

    precision: the dtype of the forward and backward passes
    (`precision.training_precision`); the loss is taken in float32.

    head: applied to the model's outputs before the loss (`position_head`);
    evaluate_epoch still gets the model's own outputs.

    Progress goes to a tqdm bar when stderr is a terminal and to one log line
    per epoch otherwise. The model ends in the selected state."""
    if not torch.isfinite(x).all():
        raise ValueError(f"{name}: the inputs hold {int((~torch.isfinite(x)).sum())} non-finite values")
    # fused: one kernel per step for all parameters (the same update rule; a per-tensor loop cost 4 % of a 1D CNN step)
    opt = torch.optim.Adam(model.parameters(), lr=hp.lr, fused=True)
    gen = torch.Generator().manual_seed(seed)
    best_score, best_epoch, best_state = -np.inf, 0, None
    train_seconds, seen, over_budget = 0.0, 0, False
    history = Losses()
    bar = tqdm(range(1, hp.epochs + 1), desc=name, unit="epoch", disable=not sys.stderr.isatty(), leave=False)
    for epoch in bar:
        model.train()
        snapshot = Snapshot.take(model, opt)
        t0 = time.perf_counter()
        order, outs, losses, batches = torch.randperm(len(x), generator=gen), [], [], []
        for i in range(0, len(order), hp.batch_size):
            idx = order[i : i + hp.batch_size].to(x.device)
            opt.zero_grad(set_to_none=True)
            with torch.autocast(x.device.type, dtype=precision, enabled=precision != torch.float32):
                out = model(x[idx])
            pred = out.float() if head is None else head(out.float())
            batch_loss = loss(pred, y[idx])
            batch_loss.backward()
            opt.step()
            losses.append(batch_loss.detach())
            batches.append(idx)
            if evaluate_epoch is not None:
                outs.append((idx.cpu(), out.detach().float().cpu()))
            seen += len(idx)
            over_budget = budget_seconds is not None and train_seconds + time.perf_counter() - t0 > budget_seconds
            if over_budget:
                break
        # A non-finite loss or weight has poisoned the model: no later epoch, and no metric, can be trusted.
        epoch_losses = torch.stack(losses).cpu()
        if not (torch.isfinite(epoch_losses).all() and state_finite(model, opt)):
            raise ValueError(diverged(name, epoch, epoch_losses, history, hp.lr, precision,
                                      replay(model, opt, snapshot, batches, x, y, loss, head, precision)))  # fmt: skip
        history.add(epoch_losses)
        train_seconds += time.perf_counter() - t0
        score = None
        if evaluate_epoch is not None:
            score = evaluate_epoch(epoch, torch.cat([i for i, _ in outs]).numpy(), torch.cat([o for _, o in outs]).numpy())
        if evaluate_epoch is None or score > best_score:
            best_score, best_epoch, best_state = score, epoch, copy.deepcopy(model.state_dict())
        progress = {"loss": f"{epoch_losses.mean().item():.4g}", **({} if score is None else {"score": f"{score:.4g}"})}
        if bar.disable:
            log.info("%s: epoch %d/%d, mean batch loss %s%s, %.1f s training", name, epoch, hp.epochs, progress["loss"],
                     "" if score is None else f", score {progress['score']}", train_seconds)  # fmt: skip
        else:
            bar.set_postfix(progress)
        if over_budget:
            break
    bar.close()
    model.load_state_dict(best_state)
    return Fitted(best_state, best_epoch, epoch, seen, train_seconds, over_budget)


def run_cell(
    x: np.ndarray,
    samples: pd.DataFrame,
    cell: Cell,
    hp: Hyper,
    validation_fraction: float,
    factory: str,
    device: str = "cpu",
    budget_seconds: float | None = None,
    precision: str = "float32",
    native_bf16: bool = False,
    release_weights: Path | None = None,
) -> Result:
    """Train one cell on (N, n, n, T) features `x` with sample table `samples`
    (`fit`, with the selection metric of `selection_key` on the validation
    part or, under `paper`, the test split, scored in the training precision;
    `budget_seconds` as there; the test split is scored once, in float32). The
    network is model `cell.model` built by `factory` ('package.module:factory',
    the registry's contract). precision: config `train.precision`, resolved
    by `precision.training_precision` (native_bf16: whether this CPU
    multiplies bfloat16 natively, `precision.cpu_has_native_bf16`).
    release_weights: the folder of the release's weights (rule
    release_weights) where `hp.init` names a checkpoint to start from."""
    if cell.protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {cell.protocol!r}; expected one of {PROTOCOLS}")
    torch.manual_seed(cell.seed)
    np.random.seed(cell.seed)
    dev = torch.device(device)
    y, classes = targets(samples, cell.task)
    split, val = partition(samples, y, cell, validation_fraction)

    # normalisation statistics: training part only (clean), or everything with the reference's own arithmetic (paper)
    if cell.protocol == "paper":
        xn, stats = paper_inputs.transform(x, hp.norm)
    else:
        _, stats = normalise(x[split.train], hp.norm)
        xn = normalise(x, hp.norm, stats)[0]
    xn = torch.from_numpy(xn)
    target_stats = target_statistics(cell.task, cell.protocol, y[split.train])
    yt = torch.from_numpy(np.array(standardise(y, target_stats)))  # pandas hands out read-only views
    n_classes = 2 if cell.task == "location" else len(classes)

    input_shape = tuple(int(d) for d in x.shape[1:])
    model = build(cell.model, factory, cell.task, input_shape, n_classes)
    if hp.init is not None:
        # the release's weights, then training as from any start (under `clean` a location head regresses standardised positions)
        fresh = init_from_release(model, init_path(hp.init, release_weights))
        log.info("starts from %s%s", hp.init, f" (left at their initialisation: {', '.join(fresh)})" if fresh else "")
    model = model.to(dev)
    flops = forward_flops(model, input_shape)
    dtype, check = training_precision(precision, dev.type, native_bf16, lambda: check_bfloat16(model, input_shape, cell.task, n_classes, loss_for(cell.task)))
    log.info("trains in %s%s", str(dtype).removeprefix("torch."), "" if check is None else f" (bfloat16's check: {check})")
    select_on = ("test", split.test) if val is None else ("validation", val)
    metric, sign = selection_key(cell.task)
    x_sel, y_sel = xn[select_on[1]], y[select_on[1]]
    rows = []

    def evaluate_epoch(epoch: int, seen: np.ndarray, out: np.ndarray) -> float:
        # training metrics from the epoch's own (train-mode) outputs: free, as the paper's curves
        rows.extend(metric_rows(epoch, "train", task_metrics(cell.task, to_metres(out, target_stats), y[split.train][seen])))
        # selection scores in the training precision (half the time of float32 where bfloat16 is native); the test split's in float32
        sel = task_metrics(cell.task, to_metres(infer(model, x_sel, dev, dtype), target_stats), y_sel)
        rows.extend(metric_rows(epoch, select_on[0], sel))
        return sign * sel[metric]

    name = f"{cell.model} {cell.task} {cell.split} {cell.resolution} {cell.condition} {cell.protocol} seed {cell.seed}"
    fitted = fit(model, xn[split.train].to(dev), yt[split.train].to(dev), hp, cell.seed, loss_for(cell.task), evaluate_epoch, budget_seconds, name, dtype,
                 position_head(target_stats))  # fmt: skip

    t0 = time.perf_counter()
    test_out = to_metres(infer(model, xn[split.test], dev), target_stats)
    infer_seconds = time.perf_counter() - t0
    test = task_metrics(cell.task, test_out, y[split.test])
    if val is not None:
        rows += metric_rows(fitted.best_epoch, "test", test)

    result = CellMetrics(
        cell=cell,
        hyper=asdict(hp),
        validation_fraction=validation_fraction if val is not None else None,
        selected_on=select_on[0],
        n_train=int(len(split.train)),
        n_validation=int(0 if val is None else len(val)),
        n_test=int(len(split.test)),
        n_classes=n_classes,
        input_shape=input_shape,
        params=n_params(model),
        flops=flops,
        best_epoch=fitted.best_epoch,
        epochs_run=fitted.epochs_run,
        samples_seen=fitted.samples_seen,
        budget_seconds=budget_seconds,
        stopped_by_budget=fitted.stopped_by_budget,
        test=test,
        baseline=baseline_metrics(cell.task, y[split.train], y[split.test], n_classes),
        train_seconds=fitted.train_seconds,
        inference_seconds=infer_seconds,
        train_samples_per_second=fitted.samples_seen / fitted.train_seconds if fitted.train_seconds > 0 else None,
        inference_samples_per_second=len(split.test) / infer_seconds if infer_seconds > 0 else None,
        device=str(dev),
        precision=str(dtype).removeprefix("torch."),
        precision_check=None if check is None else check.record(),
        threads=torch.get_num_threads(),
    )
    state = SavedCell(
        cell=cell,
        factory=factory,
        input_shape=input_shape,
        classes=classes,
        hyper=asdict(hp),
        norm_stats=stats,
        # what the cell's mean / majority baseline predicts, so that a saved cell scores its baseline on other data
        baseline_output=[float(v) for v in baseline_output(cell.task, y[split.train], n_classes)],
        model=fitted.state,
        target_stats=target_stats,
    )
    return Result(result, pd.DataFrame(rows, columns=["epoch", "part", "metric", "value"]), state.to_record())


def metric_rows(epoch: int, part: str, values: dict) -> list[tuple]:
    return [(epoch, part, k, float(v)) for k, v in values.items()]
