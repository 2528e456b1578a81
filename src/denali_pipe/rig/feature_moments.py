"""The real captures' feature statistics (REFERENCE Part 7), and how far a set
of 3x3 histograms is from them.

The release's 18 1D CNNs (Conv1d 9->128, k 5 -> BN -> GELU -> Conv1d 128->128,
k 3 -> BN -> GELU -> Conv1d 128->64, k 3 -> BN -> GELU; convolutions
bias-free, 'same' padding) were trained on real 3x3 captures. Each BN layer's
running mean and variance are the mean and variance, over the real training
samples and the 128 time positions, of each channel of the convolution's
output: the real data's moments as the network sees them. Run each net's
backbone (its own input transform, then the layers with BN at its running
statistics and PyTorch's exact GELU, as at evaluation, in float32) on other histograms and compare, per net and
layer, the moments of each BN input with the real ones:

    mean term = median over channels of |mean - running_mean| / sqrt(running_var)
    var term  = median over channels of |log(var / running_var)|
    distance  = mean term + var term      (0: the real moments)

The statistics live in a folder holding `release_1dcnn_backbones.npz` (keys
`<net>/conv1.weight`, `<net>/bn1.running_var`, ...) and
`release_1dcnn_backbones.json` (each net's input transform).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

NPZ = "release_1dcnn_backbones.npz"
JSON = "release_1dcnn_backbones.json"
LAYERS = (1, 2, 3)
# Part 7's pooled log transform: z = (log1p(max(x, 0)) - LOG_MEAN) / LOG_STD
# (every log-input net's own mean and std are within 0.002 of these).
LOG_MEAN = 7.108
LOG_STD = 0.785
# Log-input nets whose training captures were the base objects at one size,
# and at both (their JSON's `training_data`). A log-input net's transform
# holds the exact mean and std of log1p(counts) over its training captures'
# zones and bins, so these three give the real captures' log moments per size.
SIZE_NETS = {"4inch": "splits_loc_by_size", "8inch": "italics_loc", "both": "nonrr_loc"}
# Samples per forward chunk: bounds the activations' memory (~20 MB a layer).
CHUNK = 256
COLUMNS = ("net", "input", "layer", "channels", "mean_term", "var_term", "distance", "var_log_ratio")


@dataclass(frozen=True)
class Layer:
    """One conv + BN: weight (out, in, k) bias-free, 'same' padding; BN's
    weight, bias, running_mean, running_var (out,); eps as PyTorch's default."""

    conv: np.ndarray
    bn_weight: np.ndarray
    bn_bias: np.ndarray
    running_mean: np.ndarray
    running_var: np.ndarray
    eps: float = 1e-5


@dataclass(frozen=True)
class Backbone:
    """One release net: its input transform (`raw` counts, or `log_z` with
    its own mean and std of log1p counts) and its three layers."""

    name: str
    input: str
    log_mean: float
    log_std: float
    layers: tuple[Layer, ...]

    def transform(self, hist: np.ndarray) -> np.ndarray:
        """The net's input (N, 9, 128) float64 from raw counts (N, 9, 128)."""
        x = np.array(hist, dtype=float)  # a copy: torch wants writable arrays
        if self.input == "raw":
            return x
        return (log_counts(x) - self.log_mean) / self.log_std


def load_backbones(folder: Path) -> list[Backbone]:
    """The 18 backbones of the statistics folder, in the JSON's order."""
    folder = Path(folder)
    npz_path, json_path = folder / NPZ, folder / JSON
    for p in (npz_path, json_path):
        if not p.is_file():
            raise FileNotFoundError(f"feature statistics: {p} is missing (the folder must hold {NPZ} and {JSON})")
    meta = json.loads(json_path.read_text())
    arrays = np.load(npz_path)
    nets = []
    for name, info in meta.items():
        if "mean" in info and "std" in info:
            kind, mu, sd = "log_z", float(info["mean"]), float(info["std"])
        elif str(info.get("input", "")).startswith("raw counts"):
            kind, mu, sd = "raw", float("nan"), float("nan")
        else:
            raise ValueError(f"{json_path}: net {name!r} has neither a raw-count input nor a log transform's mean and std")
        layers = []
        for i in LAYERS:
            keys = [f"{name}/conv{i}.weight"] + [f"{name}/bn{i}.{k}" for k in ("weight", "bias", "running_mean", "running_var")]
            missing = [k for k in keys if k not in arrays.files]
            if missing:
                raise KeyError(f"{npz_path}: net {name!r} lacks {', '.join(missing)}")
            layers.append(Layer(*(arrays[k].astype(np.float64) for k in keys)))
        nets.append(Backbone(name, kind, mu, sd, tuple(layers)))
    return nets


def _offsets(net: Backbone, hist: np.ndarray, depth: int):
    """Per chunk of samples, each of the first `depth` layers' BN input minus
    its running mean, (n, C, T) float32 torch tensors: the backbone run as
    at evaluation, in float32 as the nets ran."""
    import torch  # here: the workflow reads this module's file names without loading torch

    hist = np.asarray(hist)
    if hist.ndim != 3 or hist.shape[1] != net.layers[0].conv.shape[1]:
        raise ValueError(f"feature moments need histograms (N, {net.layers[0].conv.shape[1]}, bins), got {hist.shape}")
    params = [
        (
            torch.from_numpy(layer.conv).float(),
            torch.from_numpy(layer.running_mean).float()[:, None],
            torch.from_numpy(layer.bn_weight / np.sqrt(layer.running_var + layer.eps)).float()[:, None],
            torch.from_numpy(layer.bn_bias).float()[:, None],
        )
        for layer in net.layers[:depth]
    ]
    with torch.no_grad():
        for start in range(0, len(hist), CHUNK):
            x = torch.from_numpy(net.transform(hist[start : start + CHUNK])).float()
            offsets = []
            for w, mean, scale, bias in params:
                d = torch.nn.functional.conv1d(x, w, padding=w.shape[-1] // 2) - mean
                offsets.append(d)
                x = torch.nn.functional.gelu(d * scale + bias)
            yield offsets


def layer_moments(net: Backbone, hist: np.ndarray, depth: int = len(LAYERS)) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per layer, the mean and (population) variance of every channel of the
    BN's input over the samples and time positions: [(mean (C,), var (C,))]
    for the first `depth` layers. hist: counts (N, 9, 128), float allowed."""
    import torch

    layers = net.layers[:depth]
    # sums about the running mean keep the variance exact in float64
    s1 = [np.zeros(len(layer.running_mean)) for layer in layers]
    s2 = [np.zeros(len(layer.running_mean)) for layer in layers]
    count = 0
    for offsets in _offsets(net, hist, depth):
        count += offsets[0].shape[0] * offsets[0].shape[-1]
        for i, d in enumerate(offsets):
            s1[i] += d.sum(dim=(0, 2), dtype=torch.float64).numpy()
            s2[i] += (d * d).sum(dim=(0, 2), dtype=torch.float64).numpy()
    out = []
    for layer, a, b in zip(layers, s1, s2):
        mean_off = a / count
        out.append((layer.running_mean + mean_off, b / count - mean_off**2))
    return out


def time_profile(net: Backbone, hist: np.ndarray) -> np.ndarray:
    """Where in time the captures leave the real moments: per layer and time
    position, the median over channels of E[(y - running_mean)^2] / running_var
    over the samples, (layers, T). The real data average 1 + (mean term)^2
    over positions; a position far above 1 holds patterns the nets saw little of."""
    sums, count = None, 0
    for offsets in _offsets(net, hist, len(LAYERS)):
        z2 = [((d * d).sum(0).numpy().astype(np.float64)) / layer.running_var[:, None] for d, layer in zip(offsets, net.layers)]
        sums = z2 if sums is None else [a + b for a, b in zip(sums, z2)]
        count += offsets[0].shape[0]
    return np.stack([np.median(s / count, axis=0) for s in sums])


def moment_terms(mean: np.ndarray, var: np.ndarray, layer: Layer) -> tuple[float, float, float]:
    """Part 7's mean and variance terms of one layer, and the median signed
    log(var / running_var) (below 0: less variance than the real data)."""
    log_ratio = np.log(np.maximum(var, 1e-300) / layer.running_var)
    mean_term = float(np.median(np.abs(mean - layer.running_mean) / np.sqrt(layer.running_var)))
    return mean_term, float(np.median(np.abs(log_ratio))), float(np.median(log_ratio))


def feature_distances(nets: list[Backbone], hist: np.ndarray) -> pd.DataFrame:
    """One row per net and layer (COLUMNS): the moment terms of raw 3x3
    histograms (N, 9, 128) against the real statistics."""
    rows = []
    for net in nets:
        for i, (layer, (mean, var)) in enumerate(zip(net.layers, layer_moments(net, hist)), start=1):
            m, v, signed = moment_terms(mean, var, layer)
            rows.append(
                {
                    "net": net.name,
                    "input": net.input,
                    "layer": i,
                    "channels": len(mean),
                    "mean_term": m,
                    "var_term": v,
                    "distance": m + v,
                    "var_log_ratio": signed,
                }
            )
    return pd.DataFrame(rows, columns=list(COLUMNS))


def summary(table: pd.DataFrame) -> dict:
    """The yardsticks of a `feature_distances` table: the distance averaged
    over nets and layers (`distance`), per layer (`layer N`), and the raw-count
    nets' layer-1 variance term (`raw layer-1 var`)."""
    out = {"distance": float(table.distance.mean())}
    for layer, g in table.groupby("layer"):
        out[f"layer {layer}"] = float(g.distance.mean())
    raw1 = table[(table.input == "raw") & (table.layer == 1)]
    out["raw layer-1 var"] = float(raw1.var_term.mean())
    return out


def log_zone_means(hist: np.ndarray) -> np.ndarray:
    """Each zone's mean of Part 7's z over samples and bins, (9,) in the
    captures' row-major zone order, from raw counts (N, 9, 128)."""
    z = (log_counts(hist) - LOG_MEAN) / LOG_STD
    return z.mean(axis=(0, 2))


def log_counts(hist: np.ndarray) -> np.ndarray:
    """log1p(max(counts, 0)) of raw counts, float64, the shape of `hist`:
    what the log-input nets' transform starts from."""
    return np.log1p(np.maximum(np.asarray(hist, float), 0.0))


def log_moments(hist: np.ndarray) -> tuple[float, float]:
    """The mean and (population) std of `log_counts` over every sample, zone
    and bin of raw counts (N, Z, bins): what a log-input net's transform is
    fitted to."""
    logs = log_counts(hist)
    return float(logs.mean()), float(logs.std())


def real_log_moments_by_size(nets: list[Backbone]) -> dict[str, tuple[float, float]]:
    """{"4inch", "8inch", "both": (mean, std) of log1p(counts)} over the real
    base-object captures of each size and of both, read from the transforms
    of the `SIZE_NETS`."""
    by_name = {net.name: net for net in nets}
    missing = [name for name in SIZE_NETS.values() if name not in by_name]
    if missing:
        raise KeyError(f"feature statistics: no net {', '.join(missing)} (the log moments per size need {', '.join(SIZE_NETS.values())})")
    return {size: (by_name[name].log_mean, by_name[name].log_std) for size, name in SIZE_NETS.items()}
