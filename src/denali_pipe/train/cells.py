"""The vocabulary of training cells (model x task x split x resolution x
protocol x seed; the splits are core.splits'), light enough for the
Snakefile to import: no torch, no sklearn."""

from __future__ import annotations

from dataclasses import dataclass

# The networks are the registry's (config `train.models`, registry.py); this one is not a network.
LINEAR = "linear"  # the classical reference model (classical.py)
TASKS = ("location", "shape", "size")
PROTOCOLS = ("clean", "paper")
# Where a protocol's cells find their datasets, under results/: `clean` trains on the
# preprocessed features' (dataset.py), `paper` on the stores' raw counts (paper_inputs.py).
DATASET_DIRS = {"clean": "datasets", "paper": "datasets/paper"}
# The dtypes a network can train in (config train.precision; precision.training_precision).
PRECISIONS = ("auto", "float32", "bfloat16")
# The condition of a cell that trains and tests on every sample (conditions.py has the others).
ALL = "all"

# A classifier cannot name shapes (sizes) it never saw in training.
ILL_POSED = {("shape_held_out", "shape"), ("size_held_out", "size")}


def uses_gpu(model: str) -> bool:
    """Whether a model's cells can use a GPU: every network, not the linear
    model, which fits in closed form on the CPU."""
    return model != LINEAR


def is_ill_posed(split: str, task: str) -> bool:
    """True for evaluations whose test labels never occur in training."""
    return (split, task) in ILL_POSED


@dataclass(frozen=True)
class Cell:
    """One training cell: `model` learns `task` on the `split` of the
    benchmark's samples at `resolution` that meet `condition`
    (conditions.py), under `protocol`, with `seed`."""

    model: str
    task: str
    split: str
    resolution: str
    protocol: str
    seed: int
    condition: str = ALL
