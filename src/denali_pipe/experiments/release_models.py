"""The DENALI release's 15 trained generalisation networks (the authors' own
1D CNNs, io.release_weights), each scored on its own test part of this run's
3x3 captures: `results/release_models.csv` (docs/release_models.md).

The release's `benchmark/generalization/` ships:
- 10 split networks, `split_checkpoints/splits_<task>_<strategy>.pth`, each
  trained on the base objects under one train/test split; its manifest
  (`preprocessing_manifest.json`) gives each one's input transform and its
  `split_strategy` and `split_params`, the checkpoint's `split_info` the
  held-out locations, objects or sizes;
- 5 held-out variant networks, `checkpoints/<name>.pth`, trained on the base
  objects and tested on the italic (8 in) or non-retroreflective variants;
  each carries its training mean and std.

A network's test part is what the release's evaluation code (its splits.py and
experiments.py) defines, taken from this run's tree (`held_out_part`):
- random_grouped: the repeats of a capture (set, location) kept together,
  int(test_size x groups) groups drawn first after a shuffle with
  RandomState(42), over the tree's capture groups (core.splits'
  `repeats_grouped`, which reproduces the release's draw sample for sample);
- by_location: the captures at the checkpoint's stored test positions. The
  release matches location labels exactly; a tree's labels come from its
  own pose stage, so a location is the stored position nearest its label
  when every label lies within half a gantry step of a stored position,
  one to one (the release's own labels match at 0 mm);
- by_object, by_size: the captures of the checkpoint's test objects or sizes;
- the variant networks: every 3x3 capture of their variant's objects (the
  italic ones at 8 in), both lightings, each object labelled with its base
  class (the objects sheet's `class`).

Where the tree lacks what a split needs, the row's `note` says what was used
instead: a tree whose labels are not the release's positions (the rig's grid
lies 4-6 cm from the real one) has the same share of its own locations (or,
lacking every test object, of its shapes) drawn by core.splits with seed 42;
a tree with part of the release's test part scores that part; nothing
present, nothing is scored (n_samples 0). The run never stops for it.

Inputs follow the manifest and the checkpoint exactly (`network_inputs`): raw
counts (N, 3, 3, 128), log1p(max(x, 0)) where `log_transform` (the variant
networks: always, as the release evaluates them), then (x - mean) /
max(std, 1e-6) with the stored statistics, in float32 as the release's
evaluation code computes it.

Scores (`score_rows`), for both lightings together and each lighting alone:
location per-coordinate RMSE (m, train.metrics, as the release's) beside the
RMSE of predicting the scored samples' own mean position (the best constant),
with the Pearson correlation of predicted and true x and of y; shape and
size Top-1 beside chance (1 / the network's classes). `release_value` is the
split network's own stored score on its test part: on the whole release tree
`value` must equal it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from denali_pipe.core import geometry as geo
from denali_pipe.core.splits import make_split
from denali_pipe.io.release_weights import MANIFEST, WeightsStatus
from denali_pipe.train import metrics as M
from denali_pipe.train.release_nets import release_network
from denali_pipe.train.runs import HEADLINE

# The release's SplitExperiment.random_state (its experiments.py): neither the manifest nor a checkpoint stores it.
RANDOM_STATE = 42
STD_FLOOR = 1e-6  # the release's max(std, 1e-6)
BATCH = 256
BASE = "base"
BOTH = "both"  # the `light` of the rows scored on both lightings together
MEAN, CHANCE = "mean of the scored positions", "chance (1 / classes)"
# A tree's location label is a stored position when within half a gantry step of it.
MATCH_TOLERANCE_M = 0.5 * float(np.linalg.norm(geo.GANTRY_COL_STEP))
COLUMNS = ("network", "task", "split", "light", "metric", "value", "baseline", "baseline_kind", "release_value", "n_samples", "corr_x", "corr_y", "note")


@dataclass(frozen=True)
class Network:
    """One of the release's networks: its task (cells.TASKS) and, for a
    held-out variant network, the variant (objects.VARIANTS) and size it is
    tested on."""

    name: str
    task: str
    variant: str | None = None
    size: str | None = None

    @property
    def file(self) -> str:
        """Its checkpoint's path in the release's benchmark/generalization/ (io.release_weights.RELEASE_FILES)."""
        return f"{'split_checkpoints' if self.variant is None else 'checkpoints'}/{self.name}.pth"

    @property
    def dataset(self) -> str:
        """The dataset its test part comes from: the base objects' or its variant's."""
        return self.variant or BASE


# In the order of the release's tables (its scripts/eval.py).
NETWORKS = (
    Network("splits_loc_random_grouped", "location"),
    Network("splits_loc_by_location", "location"),
    Network("splits_loc_by_object", "location"),
    Network("splits_loc_by_size", "location"),
    Network("splits_obj_random_grouped", "shape"),
    Network("splits_obj_by_location", "shape"),
    Network("splits_obj_by_size", "shape"),
    Network("splits_size_random_grouped", "size"),
    Network("splits_size_by_location", "size"),
    Network("splits_size_by_object", "size"),
    Network("italics_loc", "location", "italic", "8inch"),
    Network("italics_obj", "shape", "italic", "8inch"),
    Network("nonrr_loc", "location", "nonrr"),
    Network("nonrr_obj", "shape", "nonrr"),
    Network("nonrr_size", "size", "nonrr"),
)


@dataclass(frozen=True)
class Part:
    """Sorted row indices (int64) of a dataset, and what was used instead of
    the release's definition ('' when it is the release's own test part)."""

    rows: np.ndarray
    note: str = ""


@dataclass(frozen=True)
class Scored:
    """One network on one dataset: its test part, its outputs there ((n, 2)
    metres or (n, C) logits over `classes`), its stored score on the release."""

    network: Network
    part: Part
    outputs: np.ndarray
    classes: list[str] | None
    release_value: float


def _location_labels(samples: pd.DataFrame) -> pd.DataFrame:
    return samples.groupby("location")[["x", "y"]].first()


def match_locations(labels: pd.DataFrame, stored: np.ndarray) -> tuple[dict[int, int] | None, float]:
    """{tree location: index of its stored position} where every label (x, y
    per location) lies within MATCH_TOLERANCE_M of a stored position (S, 2),
    each of a different one; else None. Also the largest distance (m)."""
    xy = labels.to_numpy(np.float64)
    d = np.linalg.norm(xy[:, None, :] - stored[None, :, :], axis=-1)
    nearest, dist = d.argmin(axis=1), d.min(axis=1)
    worst = float(dist.max())
    if worst > MATCH_TOLERANCE_M or len(set(nearest)) < len(nearest):
        return None, worst
    return dict(zip(labels.index.astype(int), nearest.astype(int))), worst


def _drawn(samples: pd.DataFrame, split: str, share: float, what: str) -> Part:
    rows = make_split(samples, split, RANDOM_STATE, test_fraction=share).test
    return Part(
        rows,
        f"{what}: {share:.0%} of this tree's {'locations' if split == 'location_held_out' else 'shapes'} drawn instead (core.splits {split}, seed {RANDOM_STATE})",
    )


def _by_location(samples: pd.DataFrame, info: dict) -> Part:
    train, test = np.asarray(info["train_locations"], np.float64), np.asarray(info["test_locations"], np.float64)
    labels = _location_labels(samples)
    match, worst = match_locations(labels, np.concatenate([train, test]))
    if match is None:
        what = (
            f"this tree's location labels are not the release's positions (the farthest lies {1000 * worst:.0f} mm from its nearest stored one;"
            f" a match is within {1000 * MATCH_TOLERANCE_M:.0f} mm, one location a position)"
        )
        return _drawn(samples, "location_held_out", len(test) / (len(train) + len(test)), what)
    held = sorted(k for k, i in match.items() if i >= len(train))
    rows = np.flatnonzero(samples["location"].isin(held).to_numpy())
    notes = []
    if len(labels) < len(train) + len(test):
        notes.append(f"{len(held)} of the {len(test)} stored test positions are among this tree's {len(labels)} locations")
    if worst > 0:
        notes.append(f"labels matched to the stored positions within {1000 * worst:.1f} mm")
    return Part(rows, "; ".join(notes))


def _by_object(samples: pd.DataFrame, info: dict) -> Part:
    test = list(info["test_objects"])
    present = sorted(set(test) & set(samples["object"]))
    if not present:
        share = len(test) / (len(test) + len(info["train_objects"]))
        return _drawn(samples, "shape_held_out", share, f"this tree holds none of the {len(test)} test objects")
    note = "" if len(present) == len(test) else f"{len(present)} of the {len(test)} test objects are in this tree ({', '.join(present)})"
    return Part(np.flatnonzero(samples["object"].isin(test).to_numpy()), note)


def _random_grouped(samples: pd.DataFrame, params: dict, n_release: int) -> Part:
    rows = make_split(samples, "repeats_grouped", RANDOM_STATE, test_fraction=float(params["test_size"])).test
    note = "" if len(samples) == n_release else f"drawn over this tree's {len(samples)} samples (the release drew over its {n_release}): its own test captures"
    return Part(rows, note)


def held_out_part(network: Network, samples: pd.DataFrame, entry: dict | None, info: dict | None) -> Part:
    """`network`'s test part of a dataset (`samples`, in the release's row
    order). Split networks: their manifest entry and checkpoint `split_info`;
    variant networks: neither. ValueError naming the network when the
    manifest and the checkpoint disagree on the split."""
    if network.variant is not None:
        keep = np.ones(len(samples), bool) if network.size is None else (samples["size"] == network.size).to_numpy()
        note = "" if keep.any() else f"this tree holds no {network.variant} captures at {network.size}: nothing scored"
        return Part(np.flatnonzero(keep), note)
    strategy, params = entry["split_strategy"], entry["split_params"]
    counts = {"n_train_locations": "train_locations", "n_train_objects": "train_objects"}
    for key, listed in counts.items():
        if key in params and params[key] != len(info[listed]):
            raise ValueError(f"{network.name}: the manifest's {key} {params[key]} but its checkpoint lists {len(info[listed])} {listed}")
    if strategy == "random_grouped":
        return _random_grouped(samples, params, round(entry["num_train_samples"] / (1 - float(params["test_size"]))))
    if strategy == "by_location":
        return _by_location(samples, info)
    if strategy == "by_object":
        return _by_object(samples, info)
    if strategy == "by_size":
        rows = np.flatnonzero(samples["size"].isin(info["test_sizes"]).to_numpy())
        return Part(rows, "" if len(rows) else f"this tree holds no {', '.join(info['test_sizes'])} captures: nothing scored")
    raise ValueError(f"{network.name}: unknown split_strategy {strategy!r} in the manifest")


def network_inputs(x: np.ndarray, log: bool, mean: float | None, std: float | None) -> np.ndarray:
    """Raw counts x (N, 3, 3, T) as a network saw its training inputs,
    float32: log1p(max(x, 0)) if `log`, then (x - mean) / max(std, 1e-6)
    unless mean is None. The release's `_preprocess`, bit for bit."""
    x = np.asarray(x, dtype=np.float32)
    if log:
        x = np.log1p(np.clip(x, 0.0, None))
    if mean is not None:
        x = (x - float(mean)) / max(float(std), STD_FLOOR)  # Python floats: the arithmetic stays float32
    return x.astype(np.float32, copy=False)


def predict(net: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    """The network's outputs (N, C) float32 for inputs x (N, 3, 3, T), in eval mode on the CPU."""
    net.eval()
    with torch.inference_mode():
        outs = [net(torch.from_numpy(x[i : i + BATCH])).numpy() for i in range(0, len(x), BATCH)]
    return np.concatenate(outs) if outs else np.zeros((0, net.out_linear.out_features), np.float32)


def read_manifest(weights: Path) -> dict:
    return json.loads((Path(weights) / MANIFEST).read_text())


def evaluate_network(network: Network, weights: Path, manifest: dict, x: np.ndarray, samples: pd.DataFrame) -> Scored:
    """Run `network` (its checkpoint in the weights folder `weights`) on its
    test part of raw counts x (N, 3, 3, T) with sample table `samples`."""
    path = Path(weights) / network.file
    net, payload = release_network(path, network.task)
    if network.variant is None:
        entry = manifest.get(Path(network.file).name)
        if entry is None:
            raise ValueError(f"{Path(weights) / MANIFEST}: no entry for {Path(network.file).name}")
        if entry["split_strategy"] != payload.get("split_strategy"):
            raise ValueError(f"{path}: split_strategy {payload.get('split_strategy')!r}, but the manifest says {entry['split_strategy']!r}")
        stats = entry["normalization"] if entry["normalize"] else {"mean": None, "std": None}
        log, info = bool(entry["log_transform"]), payload["split_info"]
        stored = payload["test_rmse"] if network.task == "location" else payload["test_metrics"]["top1_acc"]
    else:
        entry, info, log, stored = None, None, True, np.nan
        stats = {"mean": payload["train_mean"], "std": payload["train_std"]}
    part = held_out_part(network, samples, entry, info)
    outputs = predict(net, network_inputs(x[part.rows], log, stats["mean"], stats["std"]))
    classes = None if network.task == "location" else [str(c) for c in payload["classes"]]
    return Scored(network, part, outputs, classes, float(stored))


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Pearson's r of two (n,) series; NaN where either is constant (or n < 2)."""
    if len(a) < 2 or np.std(a) == 0 or np.std(b) == 0:
        return float("nan")
    return float(np.corrcoef(a, b)[0, 1])


def _labels(scored: Scored, samples: pd.DataFrame) -> np.ndarray:
    column = "class" if scored.network.task == "shape" else "size"
    lookup = {c: i for i, c in enumerate(scored.classes)}
    unknown = sorted(set(samples[column]) - set(lookup))
    if unknown:
        raise ValueError(f"{scored.network.name}: captures of {column} {unknown}, which the network does not know ({', '.join(scored.classes)})")
    return samples[column].map(lookup).to_numpy(np.int64)


def score_rows(scored: Scored, samples: pd.DataFrame) -> list[dict]:
    """The table's rows of one scored network: both lightings, then each
    lighting of its test part; `samples` is the dataset's whole table."""
    net, part = scored.network, scored.part
    metric, _ = HEADLINE[net.task]
    tested = samples.iloc[part.rows]
    base = {"network": net.name, "task": net.task, "metric": metric, "note": part.note}
    if not len(part.rows):
        return [{**base, "light": BOTH, "n_samples": 0}]
    rows = []
    for light in (BOTH, *sorted(tested["light"].unique())):
        keep = np.ones(len(tested), bool) if light == BOTH else (tested["light"] == light).to_numpy()
        out, sub = scored.outputs[keep], tested[keep]
        row = {**base, "light": light, "n_samples": int(keep.sum()), "release_value": scored.release_value if light == BOTH else np.nan}
        if net.task == "location":
            y = sub[["x", "y"]].to_numpy(np.float64)
            constant = np.broadcast_to(y.mean(axis=0), y.shape)
            row.update(value=M.regression_metrics(out, y)[metric], baseline=M.regression_metrics(constant, y)[metric], baseline_kind=MEAN,
                       corr_x=_correlation(out[:, 0], y[:, 0]), corr_y=_correlation(out[:, 1], y[:, 1]))  # fmt: skip
        else:
            row.update(value=M.classification_metrics(out, _labels(scored, sub))[metric], baseline=1.0 / len(scored.classes), baseline_kind=CHANCE)
        rows.append(row)
    return rows


def _split_name(network: Network, manifest: dict) -> str:
    return manifest[Path(network.file).name]["split_strategy"] if network.variant is None else f"{network.variant} variants"


def release_models(weights: Path, datasets: dict[str, tuple[np.ndarray, pd.DataFrame] | None]) -> pd.DataFrame:
    """The table (COLUMNS) of every network of NETWORKS: the weights folder
    `weights` (io.release_weights), and per dataset (`BASE`, each variant)
    raw counts (N, 3, 3, T) and their sample table, or None where the run
    has no such 3x3 captures. Where the weights are unavailable each
    network's row says why, and nothing is scored."""
    status = WeightsStatus.read(weights)
    if not status.available:
        rows = [{"network": n.name, "task": n.task, "light": BOTH, "metric": HEADLINE[n.task][0], "n_samples": 0,
                 "note": f"the release's weights are unavailable: {status.missing}"} for n in NETWORKS]  # fmt: skip
        return pd.DataFrame(rows).reindex(columns=list(COLUMNS))
    manifest = read_manifest(weights)
    rows = []
    for network in NETWORKS:
        data = datasets.get(network.dataset)
        if data is None:
            what = "base-object" if network.dataset == BASE else network.dataset
            rows.append({"network": network.name, "task": network.task, "split": _split_name(network, manifest), "light": BOTH,
                         "metric": HEADLINE[network.task][0], "n_samples": 0, "note": f"this run has no {what} 3x3 captures: nothing scored"})  # fmt: skip
            continue
        x, samples = data
        scored = evaluate_network(network, weights, manifest, x, samples)
        rows += [{**r, "split": _split_name(network, manifest)} for r in score_rows(scored, samples)]
    return pd.DataFrame(rows).reindex(columns=list(COLUMNS))
