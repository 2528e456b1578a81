"""The model registry: the networks a benchmark trains, each named in config
(`train.models.<name>`) by the import path of its factory.

The factory contract (docs/models.md):

    factory(task: str, n_outputs: int, input_shape: tuple[int, int, int]) -> torch.nn.Module

`task` is one of cells.TASKS; `input_shape` (n, n, T): n zones per side (3
or 8; 1 for the centre-zone experiments) and T time bins (128 less the crop).
The module maps a float32 batch (B, n, n, T), normalised as the task's
`norm` setting says, to (B, n_outputs): for location x, y in metres
(n_outputs = 2), for shape and size logits over the classes (n_outputs =
their count; size: 4inch, 8inch). The paper's four are registered the same
way (their factories are in `denali_pipe.train.models`).

This module imports no torch at load, so that the workflow can check the
registry when it builds the DAG; `build` imports what it needs.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import re
import sys
from collections.abc import Callable

from denali_pipe.io.release_weights import release_checkpoint
from denali_pipe.train.cells import LINEAR, TASKS

N_LOCATION_OUTPUTS = 2  # x, y in metres
N_SIZE_CLASSES = 2  # 4inch, 8inch
# A model's name is a path part (`<model>_<task>` run folders) and a Snakemake
# wildcard value: letters, digits and '-' keep both unambiguous.
NAME_PATTERN = r"[A-Za-z][A-Za-z0-9-]*"
FACTORY_PATTERN = r"[A-Za-z_][\w.]*:[A-Za-z_]\w*"
KEY = "train.models"


def n_outputs(task: str, n_classes: int) -> int:
    """The head's width for `task`: 2 (x, y) for location, `n_classes` for shape, 2 for size."""
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; expected one of {TASKS}")
    return {"location": N_LOCATION_OUTPUTS, "shape": n_classes, "size": N_SIZE_CLASSES}[task]


def _workflow_dir_on_path() -> None:
    # A user's model lives beside the workflow (e.g. examples/), which is the
    # working directory of the workflow and of its jobs; `python -m` puts it on
    # sys.path, the `snakemake` script does not. Both resolve the same way.
    cwd = os.getcwd()
    if cwd not in sys.path:
        sys.path.append(cwd)


def _split(name: str, path: object) -> tuple[str, str]:
    key = f"{KEY}.{name}.factory"
    if not isinstance(path, str) or not re.fullmatch(FACTORY_PATTERN, path):
        raise ValueError(f"{key}: {path!r} is not an import path 'package.module:factory'")
    module, attr = path.split(":")
    return module, attr


def check_models(models: dict, benchmark_model: str) -> dict[str, dict]:
    """The registered models of a config's `train.models` (entries set to
    null are dropped: that is how a config leaves out a default model), in
    config order, after checking each name, that each factory's module
    can be found (without importing it) and that each `init` names a
    release checkpoint. ValueError naming the config key otherwise, or when
    `benchmark_model` (train.benchmark_model) is not one of them."""
    registered = {name: entry for name, entry in models.items() if entry is not None}
    if not registered:
        raise ValueError(f"{KEY}: no model registered")
    _workflow_dir_on_path()
    for name, entry in registered.items():
        if not re.fullmatch(NAME_PATTERN, name) or name == LINEAR:
            raise ValueError(f"{KEY}.{name}: a model name is letters, digits and '-' ({LINEAR!r} is the classical reference model's)")
        module, _ = _split(name, entry.get("factory"))
        try:
            found = importlib.util.find_spec(module) is not None
        except ImportError as e:  # a parent package that does not import
            raise ValueError(f"{KEY}.{name}.factory: module {module!r} cannot be imported ({e})") from None
        if not found:
            raise ValueError(f"{KEY}.{name}.factory: no module {module!r} on the Python path or in the workflow folder {os.getcwd()}")
        for task in TASKS:
            init = (entry.get(task) or {}).get("init")
            if init is not None:
                try:
                    release_checkpoint(init)
                except ValueError as e:
                    raise ValueError(f"{KEY}.{name}.{task}.{e}") from None
    if benchmark_model not in registered:
        raise ValueError(f"train.benchmark_model: {benchmark_model!r} is not a registered model of {KEY} ({', '.join(registered)})")
    return registered


def check_left_out(left_out: list[dict], models: dict, benchmark_model: str) -> dict[str, str]:
    """`train.left_out` as {model: reason}, in config order: the registered
    models a preset does not train for Tables 2 and 10 and the
    speed-vs-accuracy chart, which print each one's row as absent with its
    reason. `models` is the config's `train.models`: an entry naming a model
    set to null there is dropped (the model is gone from every table).
    ValueError naming the key when an entry names no model of it, names one
    twice, or names `benchmark_model` (Table 5 and the one-model experiments
    train it)."""
    reasons: dict[str, str] = {}
    for entry in left_out:
        name = entry["model"]
        if name not in models:
            raise ValueError(f"train.left_out: {name!r} is not a model of {KEY} ({', '.join(models)})")
        if models[name] is None:
            continue
        if name in reasons:
            raise ValueError(f"train.left_out: {name!r} is named twice")
        if name == benchmark_model:
            raise ValueError(f"train.left_out: {name!r} is train.benchmark_model, which Table 5 and the one-model experiments train")
        reasons[name] = entry["reason"]
    return reasons


def load_factory(name: str, path: str) -> Callable:
    """The factory callable of model `name` at import path `path`
    ('package.module:factory'). ValueError naming `train.models.<name>.factory`
    when it does not resolve."""
    module, attr = _split(name, path)
    _workflow_dir_on_path()
    try:
        factory = getattr(importlib.import_module(module), attr)
    except ImportError as e:
        raise ValueError(f"{KEY}.{name}.factory {path!r}: module {module!r} cannot be imported ({e})") from None
    except AttributeError:
        raise ValueError(f"{KEY}.{name}.factory {path!r}: module {module!r} has no {attr!r}") from None
    if not callable(factory):
        raise ValueError(f"{KEY}.{name}.factory {path!r}: {attr!r} is not callable")
    return factory


def build(name: str, path: str, task: str, input_shape: tuple[int, int, int], n_classes: int):
    """Model `name` for `task` from its factory at `path`: an nn.Module taking
    (B, *input_shape) and giving (B, n_outputs(task, n_classes)).
    ValueError naming the config key when the factory gives no module."""
    from torch import nn

    module = load_factory(name, path)(task, n_outputs(task, n_classes), tuple(int(d) for d in input_shape))
    if not isinstance(module, nn.Module):
        raise ValueError(f"{KEY}.{name}.factory {path!r} returned {type(module).__name__}, not a torch.nn.Module")
    return module
