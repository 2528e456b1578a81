"""A trained cell as one file for use outside the pipeline (`denali export`;
docs/models.md): a `torch.export` program (`.pt2`) or an ONNX model
(`.onnx`), chosen by the output's suffix.

The file holds the network behind the cell's input normalisation, so it
takes what the pipeline's features are: (B, n, n, T) float32
background-subtracted, aligned, cropped counts (predict.capture_features),
any batch size B >= 1, and gives what the cell gives: (B, 2) x, y in metres
for location, (B, C) logits for shape and size. Beside the program,
`denali.json` (METADATA_KEY) names the task, the classes in output order,
the input shape, the normalisation, the position targets' standardisation
and box (a clean location cell's bounded head, applied inside), the cell and its factory, and the crop
window when given: an extra file of the `.pt2` archive, a metadata entry of
the ONNX model. `load_export` reads both.
"""

from __future__ import annotations

import json
import logging
import warnings
from dataclasses import asdict
from pathlib import Path

import torch
from torch import nn

from denali_pipe.core.atomic import atomic_file
from denali_pipe.preprocess.histograms import CropWindow
from denali_pipe.train.evaluate import TrainedCell
from denali_pipe.train.saved_cell import SavedCell
from denali_pipe.train.training import bounded, standardised_box

FORMAT = "denali-pipe export"
VERSION = 2  # 1 was a TorchScript archive, deprecated in torch 2.13
METADATA_KEY = "denali.json"
FORMATS = (".pt2", ".onnx")
# preprocess.normalise's floor on sigma, kept so that the file computes what the cell does
MIN_SIGMA = 1e-6
# ONNX opset: torch 2.13's exporter's own (torch.onnx._internal.exporter._constants.TORCHLIB_OPSET),
# pinned so that an upgrade cannot change the files in silence
ONNX_OPSET = 18


class NormalisedModel(nn.Module):
    """`preprocess.normalise` (raw: identity; log_z: signed log1p, then the
    cell's (x - mu) / sigma) followed by the cell's network and, for a
    network regressing standardised positions, their bounded head (where the
    record has a box) and map back to metres (`train.to_metres`)."""

    def __init__(self, model: nn.Module, norm: str, stats: tuple[float, float] | None, target_stats=None):
        super().__init__()
        self.model = model
        self.log_z = norm == "log_z"
        mu, sigma = stats if stats is not None else (0.0, 1.0)
        self.register_buffer("mu", torch.tensor(float(mu)))
        self.register_buffer("sigma", torch.tensor(max(float(sigma), MIN_SIGMA)))
        self.to_metres = target_stats is not None
        mean, std = target_stats[:2] if target_stats is not None else ((0.0, 0.0), (1.0, 1.0))
        self.register_buffer("target_mean", torch.tensor(mean, dtype=torch.float32))
        self.register_buffer("target_std", torch.tensor(std, dtype=torch.float32))
        box = standardised_box(target_stats)
        self.bounded = box is not None
        lo, hi = box if box is not None else ((-1.0, -1.0), (1.0, 1.0))
        self.register_buffer("box_lo", torch.tensor(lo, dtype=torch.float32))
        self.register_buffer("box_hi", torch.tensor(hi, dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.log_z:
            x = (torch.sign(x) * torch.log1p(x.abs()) - self.mu) / self.sigma
        out = self.model(x)
        if self.bounded:
            out = bounded(out, self.box_lo, self.box_hi, torch.tanh)
        if self.to_metres:
            out = out * self.target_std + self.target_mean
        return out


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
        # a clean location network regresses standardised positions; the export maps them back to metres
        "targets": None
        if trained.target_stats is None
        else {
            "mean_m": list(trained.target_stats[0]),
            "std_m": list(trained.target_stats[1]),
            "box_m": [list(row) for row in trained.target_stats[2:4]] or None,
            "applied": "inside",
        },
        "classes": trained.classes,
        "normalisation": {"kind": trained.hyper.norm, "stats": None if trained.norm_stats is None else list(trained.norm_stats), "applied": "inside"},
        "crop": None if window is None else window.to_dict(),
        "cell": asdict(trained.cell),
        "factory": factory,
    }


def export_cell(trained: TrainedCell, run_dir: Path, out: Path, window: CropWindow | None = None) -> dict:
    """Export the cell in `run_dir` (loaded as `trained`) behind its
    normalisation to `out` (`.pt2` or `.onnx`, FORMATS) with its metadata;
    returns the metadata. ValueError naming `out` for another suffix."""
    out = Path(out)
    if out.suffix not in FORMATS:
        raise ValueError(f"{out}: an export is a torch.export program (.pt2) or an ONNX model (.onnx), not {out.suffix or 'a file without suffix'}")
    meta = metadata(trained, SavedCell.load(run_dir).factory, window)
    wrapper = NormalisedModel(trained.model, trained.hyper.norm, trained.norm_stats, trained.target_stats).eval()
    example = (torch.zeros(2, *trained.input_shape),)
    batch = ({0: torch.export.Dim("batch", min=1)},)
    with atomic_file(out) as tmp, torch.no_grad():
        if out.suffix == ".pt2":
            program = torch.export.export(wrapper, example, dynamic_shapes=batch)
            torch.export.save(program, str(tmp), extra_files={METADATA_KEY: json.dumps(meta, indent=1)})
        else:
            _export_onnx(wrapper, example, batch, tmp, meta)
    return meta


def _export_onnx(wrapper: nn.Module, example: tuple, batch: tuple, path: Path, meta: dict) -> None:
    import onnx

    # torch 2.13's own decomposition pass deep-copies a pytree LeafSpec, which
    # warns of a deprecation in torch itself, not in anything called here; and
    # its registry logs at WARNING each torchvision operator it skips.
    with warnings.catch_warnings(), _quiet("torch.onnx"):
        warnings.filterwarnings("ignore", message=r"`isinstance\(treespec, LeafSpec\)` is deprecated", category=FutureWarning)
        program = torch.onnx.export(wrapper, example, dynamo=True, dynamic_shapes=batch, opset_version=ONNX_OPSET, verbose=False)
    model = program.model_proto
    entry = model.metadata_props.add()
    entry.key, entry.value = METADATA_KEY, json.dumps(meta, indent=1)
    onnx.save_model(model, str(path))


class _quiet:
    """A logger raised to ERROR for the duration of a `with` block."""

    def __init__(self, name: str):
        self.logger = logging.getLogger(name)

    def __enter__(self):
        self.level = self.logger.level
        self.logger.setLevel(logging.ERROR)

    def __exit__(self, *exc):
        self.logger.setLevel(self.level)


def load_export(path: Path) -> tuple[nn.Module | None, dict]:
    """(the `.pt2` program as a module, or None for `.onnx`, which runs in an
    ONNX runtime; its metadata). ValueError naming the file when it is not an export."""
    path = Path(path)
    try:
        if path.suffix == ".onnx":
            import onnx

            props = {p.key: p.value for p in onnx.load_model(str(path), load_external_data=False).metadata_props}
            module, raw = None, props.get(METADATA_KEY, "")
        else:
            extra = {METADATA_KEY: ""}
            module, raw = torch.export.load(str(path), extra_files=extra).module(), extra[METADATA_KEY]
    except Exception as e:  # noqa: BLE001 (each loader raises its own types on a foreign file)
        raise ValueError(f"{path}: not a denali-pipe export ({type(e).__name__}: {e})") from None
    try:
        meta = json.loads(raw)
    except ValueError:
        meta = None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ValueError(f"{path}: a {path.suffix} file without denali-pipe's {METADATA_KEY}")
    return module, meta
