"""The release's trained 1D CNNs (io.release_weights) as this project's
`models.CNN1d`, to run them or to start a model's training from them.

The release's `MediumConv1DNet` (shape, size) and `MediumConv1DNetReg`
(location) of its `benchmark/main_table/models.py` are `CNN1d`'s layers under
other names (`RELEASE_NAMES`): three bias-free Conv1d-BN-GELU blocks over the 9
zones as channels, a global average over time, Linear(64, 32)-GELU-Dropout,
and the output Linear (the classifier's `head.2` and `head.5`; the
regressor's `mlp.0` and `out_linear`, beside its unused `out_tanh`). A
network maps (B, 3, 3, T) float32 inputs, transformed as it was trained
(`experiments.release_models`), to (B, 2) positions in metres or (B, C)
logits over its checkpoint's `classes`.

Checkpoints are read with torch's weights-only unpickler, which admits
tensors, containers and, here, the numpy scalars and arrays the release's
checkpoints hold (their stored means, metrics and label encoders): nothing
in a checkpoint runs code.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from numpy._core.multiarray import _reconstruct, scalar
from torch import nn

from denali_pipe.io.release_weights import WeightsStatus, release_checkpoint
from denali_pipe.train.models import CNN1d

# The numpy objects a checkpoint may hold: the release's name them as numpy 1
# did, a checkpoint written under numpy 2 by their own names.
NUMPY_GLOBALS = [
    _reconstruct,
    scalar,
    (_reconstruct, "numpy.core.multiarray._reconstruct"),
    (scalar, "numpy.core.multiarray.scalar"),
    np.ndarray,
    np.dtype,
    np.dtypes.Int64DType,
    np.dtypes.Float32DType,
    np.dtypes.Float64DType,
    np.dtypes.StrDType,
]
# The release's layer names -> CNN1d's (prefixes of the state dict's keys).
RELEASE_NAMES = {
    "conv1.": "features.0.",
    "bn1.": "features.1.",
    "conv2.": "features.3.",
    "bn2.": "features.4.",
    "conv3.": "features.6.",
    "bn3.": "features.7.",
    "head.2.": "mlp.0.",  # the classifier's Linear(64, 32)
    "head.5.": "out_linear.",  # the classifier's output layer
    "mlp.0.": "mlp.0.",
    "out_linear.": "out_linear.",
    "out_tanh.": "out_tanh.",  # the regressor's unused layer (models.CNN1d says why it is kept)
}
# The layers a model may start without: the output layer (its width is the
# run's class count) and the regressor's unused one.
HEAD = ("out_linear.", "out_tanh.")


def read_checkpoint(path: Path) -> dict:
    """A release checkpoint's dict (`model_state_dict`, its stored statistics,
    metrics and `classes`). ValueError naming the file when it is not one."""
    try:
        with torch.serialization.safe_globals(NUMPY_GLOBALS):
            payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises UnpicklingError, RuntimeError or OSError by what is wrong
        lines = str(e).splitlines()
        why = next((line for line in lines if "GLOBAL" in line or "got <" in line), lines[0] if lines else "")
        raise ValueError(f"{path}: not a checkpoint the weights-only reader accepts ({type(e).__name__}: {why.strip()})") from None
    if not isinstance(payload, dict) or "model_state_dict" not in payload:
        raise ValueError(f"{path}: a release checkpoint is a dict with a model_state_dict")
    return payload


def cnn1d_state(release_state: dict, where: Path | str) -> dict[str, torch.Tensor]:
    """The release's state dict under CNN1d's names; ValueError naming
    `where` for a key of no known layer."""
    out = {}
    for key, value in release_state.items():
        prefix = next((p for p in RELEASE_NAMES if key.startswith(p)), None)
        if prefix is None:
            raise ValueError(f"{where}: layer {key!r} is not one of the release's 1D CNN ({', '.join(RELEASE_NAMES)})")
        out[RELEASE_NAMES[prefix] + key.removeprefix(prefix)] = value
    return out


def release_network(path: Path, task: str) -> tuple[CNN1d, dict]:
    """(the network, its checkpoint dict) of release checkpoint `path` for
    `task` ('location': 2 outputs, else its output layer's width), in eval
    mode on the CPU, every weight loaded (strict)."""
    payload = read_checkpoint(path)
    state = cnn1d_state(payload["model_state_dict"], path)
    n_out = state["out_linear.weight"].shape[0]
    zones = state["features.0.weight"].shape[1]
    net = CNN1d(int(np.sqrt(zones)), n_out, with_out_tanh=task == "location")
    try:
        net.load_state_dict(state, strict=True)
    except RuntimeError as e:
        raise ValueError(f"{path}: its layers are not the 1D CNN's for {task} ({str(e).splitlines()[0]})") from None
    return net.eval(), payload


def init_path(init: str, weights: Path | None) -> Path:
    """The checkpoint file that a model's `init: release:<file>` names, in the
    weights folder `weights` (rule release_weights). ValueError saying what
    is wrong: not a release checkpoint, no folder, or a folder without the files."""
    name = release_checkpoint(init)
    if weights is None:
        raise ValueError(f"init {init!r}: no folder of the release's weights given")
    status = WeightsStatus.read(weights)
    if not status.available:
        raise ValueError(f"init {init!r}: {weights} holds none of the release's weights: {status.missing}")
    return Path(weights) / name


def init_from_release(model: nn.Module, path: Path) -> list[str]:
    """Load release checkpoint `path`'s weights into `model` (a CNN1d for
    the same zones) before training: every layer but the output layer must
    fit, which loads where its width does (the release's 30 shapes, 2 sizes
    or x, y). Returns the layers left at their initialisation. ValueError
    naming the file and the layers when the model is no such network."""
    state = cnn1d_state(read_checkpoint(path)["model_state_dict"], path)
    own = model.state_dict()
    misfits = [k for k, v in state.items() if not k.startswith(HEAD) and (k not in own or own[k].shape != v.shape)]
    if misfits:
        raise ValueError(f"{path}: the model is not the release's 1D CNN for its zones: {', '.join(misfits)} do not fit")
    loaded = {k: v for k, v in state.items() if k in own and own[k].shape == v.shape}
    model.load_state_dict(loaded, strict=False)
    return sorted(k for k in own if k not in loaded)
