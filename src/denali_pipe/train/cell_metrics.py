"""What one training cell measured: the `metrics.json` of its run folder, one
typed record that the writers (`train.run_cell`, `classical.run_linear`) and
the readers (`train.runs`, `evaluate`) share.

Networks fill the epoch fields (best_epoch, epochs_run, samples_seen, the
time budget); the linear reference model fills `selected_regularisation`
instead. Files written before a field existed read with its default.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields
from pathlib import Path

from denali_pipe.train.cells import Cell

METRICS_FILE = "metrics.json"  # in the cell's run folder


@dataclass(frozen=True)
class CellMetrics:
    """One cell's sizes, selection, test metrics and costs.

    hyper: the settings it trained with (`train.Hyper`'s fields for a
    network; the regularisation grid and input normalisation for the linear
    model). test / baseline: `train.task_metrics` of the selected model and of
    the mean / majority predictor of the training labels, on the test split
    (metres for location). Seconds are wall-clock on `device`."""

    cell: Cell
    hyper: dict
    selected_on: str  # the part the epoch (regularisation) was picked on: validation (clean) or test (paper)
    n_train: int
    n_validation: int
    n_test: int
    n_classes: int  # outputs of the head: 2 for location (x, y)
    input_shape: tuple[int, int, int]  # (n, n, T)
    params: int
    test: dict[str, float]
    baseline: dict[str, float]
    train_seconds: float
    inference_seconds: float
    train_samples_per_second: float | None
    inference_samples_per_second: float | None
    device: str
    best_epoch: int | None = None
    epochs_run: int | None = None
    samples_seen: int | None = None
    budget_seconds: float | None = None
    stopped_by_budget: bool = False
    validation_fraction: float | None = None  # None under `paper` (no validation part)
    threads: int | None = None
    selected_regularisation: float | None = None
    flops: int | None = None  # one sample's forward pass (models.forward_flops); None for the linear model
    precision: str = "float32"  # the dtype training computed in (precision.training_precision)
    precision_check: dict | None = None  # what decided it under `auto` (precision.PrecisionCheck.record); None where no check ran

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1) + "\n"

    @classmethod
    def from_dict(cls, record: dict) -> CellMetrics:
        """The record of a parsed metrics.json. ValueError for a missing or
        unknown key."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(record) - known)
        if unknown:
            raise ValueError(f"unknown keys {unknown}")
        try:
            cell = Cell(**record["cell"])
            return cls(**{**record, "cell": cell, "input_shape": tuple(record["input_shape"])})
        except (KeyError, TypeError) as e:
            raise ValueError(f"not a cell's metrics ({e!r})") from None

    @classmethod
    def read(cls, path: Path) -> CellMetrics:
        """The metrics.json at `path`; ValueError naming the file when it is
        unreadable or not a cell's metrics."""
        try:
            return cls.from_dict(json.loads(Path(path).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as e:
            raise ValueError(f"{path}: not a training cell's metrics.json ({e})") from None
