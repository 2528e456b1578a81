"""A trained cell as one TorchScript file for use outside the pipeline
(`denali export`; docs/models.md).

The archive holds the network behind the cell's input normalisation, so it
takes what the pipeline's features are: (B, n, n, T) float32
background-subtracted, aligned, cropped counts (predict.capture_features),
and gives what the cell gives: (B, 2) x, y in metres for location, (B, C)
logits for shape and size. Beside the code, the archive's extra file
`denali.json` (EXTRA_FILE) names the task, the classes in output order,
the input shape, the normalisation, the cell and its factory, and the crop
window when given: read it with
`torch.jit.load(path, _extra_files={"denali.json": ""})`.
"""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import torch
from torch import nn

from denali_pipe.core.atomic import atomic_file
from denali_pipe.preprocess.histograms import CropWindow
from denali_pipe.train.evaluate import TrainedCell
from denali_pipe.train.saved_cell import SavedCell

FORMAT = "denali-pipe export"
VERSION = 1
EXTRA_FILE = "denali.json"
# preprocess.normalise's floor on sigma, kept so that the archive computes what the cell does
MIN_SIGMA = 1e-6


class NormalisedModel(nn.Module):
    """`preprocess.normalise` (raw: identity; log_z: signed log1p, then the
    cell's (x - mu) / sigma) followed by the cell's network."""

    def __init__(self, model: nn.Module, norm: str, stats: tuple[float, float] | None):
        super().__init__()
        self.model = model
        self.log_z = norm == "log_z"
        mu, sigma = stats if stats is not None else (0.0, 1.0)
        self.register_buffer("mu", torch.tensor(float(mu)))
        self.register_buffer("sigma", torch.tensor(max(float(sigma), MIN_SIGMA)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.log_z:
            x = (torch.sign(x) * torch.log1p(x.abs()) - self.mu) / self.sigma
        return self.model(x)


def metadata(trained: TrainedCell, factory: str, window: CropWindow | None) -> dict:
    """What `denali.json` holds (module docstring)."""
    task = trained.cell.task
    return {
        "format": FORMAT,
        "version": VERSION,
        "task": task,
        "input": "float32 (B, n, n, T): background-subtracted, aligned, cropped counts",
        "input_shape": list(trained.input_shape),
        "outputs": ["x_m", "y_m"] if task == "location" else "logits over classes",
        "classes": trained.classes,
        "normalisation": {"kind": trained.hyper.norm, "stats": None if trained.norm_stats is None else list(trained.norm_stats), "applied": "inside"},
        "crop": None if window is None else window.to_dict(),
        "cell": asdict(trained.cell),
        "factory": factory,
    }


def export_cell(trained: TrainedCell, run_dir: Path, out: Path, window: CropWindow | None = None) -> dict:
    """Trace the cell in `run_dir` (loaded as `trained`) behind its
    normalisation and save it to `out` with its metadata; returns the metadata."""
    meta = metadata(trained, SavedCell.load(run_dir).factory, window)
    wrapper = NormalisedModel(trained.model, trained.hyper.norm, trained.norm_stats).eval()
    example = torch.zeros(2, *trained.input_shape)
    with torch.no_grad():
        traced = torch.jit.trace(wrapper, example)
    with atomic_file(Path(out)) as tmp:
        torch.jit.save(traced, str(tmp), _extra_files={EXTRA_FILE: json.dumps(meta, indent=1)})
    return meta


def load_export(path: Path) -> tuple[torch.jit.ScriptModule, dict]:
    """(the archive's module in eval mode, its metadata). ValueError naming the file when it is not an export."""
    extra = {EXTRA_FILE: ""}
    try:
        module = torch.jit.load(str(path), map_location="cpu", _extra_files=extra)
    except (RuntimeError, ValueError) as e:
        raise ValueError(f"{path}: not a denali-pipe export ({e})") from None
    try:
        meta = json.loads(extra[EXTRA_FILE])
    except ValueError:
        meta = None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"{path}: a TorchScript file without denali-pipe's {EXTRA_FILE}")
    return module.eval(), meta
