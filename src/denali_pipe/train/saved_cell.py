"""`model.pt`: a trained network cell as a documented, versioned record
(docs/models.md), written by `train.run_cell` and read by `evaluate.load_cell`.

The file is `torch.save` of a plain dict (loadable with
`torch.load(path, weights_only=True)`):

    format          "denali-pipe cell"
    version         3 (versions 1, without target_stats, and 2, without its box, still read)
    cell            the Cell's fields: model, task, split, resolution, protocol, seed, condition
    factory         the model's factory, 'package.module:factory' (registry)
    input_shape     [n, n, T]: zones per side, time bins after the crop
    classes         class names in output order (shape, size); None for location
    hyper           lr, epochs, batch_size, norm ("raw" or "log_z")
    norm_stats      [mu, sigma] of the log_z normalisation (training part); None for raw
    target_stats    [[mean_x, mean_y], [std_x, std_y], [lo_x, lo_y], [hi_x, hi_y]] in m:
                    a clean location cell's network outputs standardised
                    positions, bounded into the box lo-hi and mapped back by
                    these (training part; `train.training.target_statistics`);
                    None for metre outputs (paper) and classifiers
    baseline_output the mean / majority baseline's output: (2,) m or (C,) class scores
    model           the selected epoch's state_dict

The linear reference model's model.pt is its own (no format key); it is not a
network cell and is not read back.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import torch

from denali_pipe.train.cells import Cell

MODEL_FILE = "model.pt"  # in the cell's run folder
FORMAT = "denali-pipe cell"
VERSION = 3
READS = (1, 2, 3)  # version 1 records are version 3 without target_stats, version 2 ones without its box (unbounded)


@dataclass(frozen=True)
class SavedCell:
    """The fields of the record (see the module docstring); `hyper` a dict of `train.Hyper`'s fields."""

    cell: Cell
    factory: str
    input_shape: tuple[int, int, int]
    classes: list[str] | None
    hyper: dict
    norm_stats: tuple[float, float] | None
    baseline_output: list[float]
    model: dict
    target_stats: tuple[tuple[float, float], ...] | None = None

    def to_record(self) -> dict:
        return {
            "format": FORMAT,
            "version": VERSION,
            "cell": asdict(self.cell),
            "factory": self.factory,
            "input_shape": [int(d) for d in self.input_shape],
            "classes": None if self.classes is None else list(self.classes),
            "hyper": dict(self.hyper),
            "norm_stats": None if self.norm_stats is None else [float(v) for v in self.norm_stats],
            "baseline_output": [float(v) for v in self.baseline_output],
            "model": self.model,
            "target_stats": None if self.target_stats is None else [[float(v) for v in row] for row in self.target_stats],
        }

    @classmethod
    def from_record(cls, record: dict, path: Path) -> SavedCell:
        """ValueError naming `path` when `record` is not a cell record of this VERSION."""
        if not isinstance(record, dict) or record.get("format") != FORMAT:
            raise ValueError(f"{path}: not a training cell's saved model (no {FORMAT!r} record; cells saved before the record was versioned must be retrained)")
        if record.get("version") not in READS:
            raise ValueError(f"{path}: cell record version {record.get('version')!r}; this denali-pipe reads version {VERSION}")
        try:
            stats, target = record["norm_stats"], record.get("target_stats")
            return cls(
                cell=Cell(**record["cell"]),
                factory=str(record["factory"]),
                input_shape=tuple(int(d) for d in record["input_shape"]),
                classes=record["classes"],
                hyper=dict(record["hyper"]),
                norm_stats=None if stats is None else (float(stats[0]), float(stats[1])),
                baseline_output=[float(v) for v in record["baseline_output"]],
                model=record["model"],
                target_stats=None if target is None else tuple((float(row[0]), float(row[1])) for row in target),
            )
        except (KeyError, TypeError, ValueError, IndexError) as e:
            raise ValueError(f"{path}: a cell record without a valid {e}") from None

    @classmethod
    def load(cls, run_dir: Path) -> SavedCell:
        """The record in `run_dir`/model.pt. ValueError naming the file when
        it is missing or not a cell record."""
        path = Path(run_dir) / MODEL_FILE
        try:
            record = torch.load(path, map_location="cpu", weights_only=True)
        except (OSError, RuntimeError) as e:
            raise ValueError(f"{path}: not a training cell's saved model ({e})") from None
        return cls.from_record(record, path)
