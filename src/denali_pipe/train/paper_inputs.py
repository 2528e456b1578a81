"""The `paper` protocol's inputs: the reference's data path, from the stores.

The release's benchmark (REFERENCE.md Part 2 section 1) trains on the raw
counts of every zone and all 128 bins, with no alignment, background
subtraction or crop, and each repeat is its own sample. This module builds
those samples from the ingested capture stores (`results/store/<set>.zarr`,
io/store.py) and applies the reference's input transform; the `clean`
protocol trains on the preprocessed features instead (dataset.py).

- Samples: every repeat of every location of every given set, in the order of
  the reference's query: capture-set name (ASCII, as its sorted folder
  names), then location (its sorted `NNN.npy` files), then repeat. The seeded
  splits (core/splits.py) depend on this order. The sample table has dataset.py's
  columns, so splits, conditions and labels read it unchanged.
- Transform (`transform`): `raw` float32 counts, or `log_z`: log1p(clip(x, 0))
  then one global z-score whose mean and std (+1e-6) are taken over every
  sample, train and test together, in float32 as the reference computes them.

The `paper_dataset` rule (`denali paper-dataset`) writes the samples in
dataset.py's format (crop_start 0) as `results/datasets/paper/<name>.zarr` +
`.parquet`; `training.run_cell` applies `transform` under `paper`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.objects import VARIANTS, ObjectSpec
from denali_pipe.io.store import open_set
from denali_pipe.train.dataset import SAMPLE_COLUMNS, sample_rows

NORMS = ("raw", "log_z")
# added to the std before dividing, in float32 (the reference's `X.std() + 1e-6`)
STD_EPSILON = np.float32(1e-6)


def paper_samples(
    store_paths: list[Path], catalogue: dict[str, ObjectSpec], labels: dict[int, tuple[float, float]], variant: str = "base"
) -> tuple[np.ndarray, pd.DataFrame]:
    """Raw counts (N, n, n, 128) float32 of every repeat of the sets' stores
    and their sample table (dataset.SAMPLE_COLUMNS), in the reference's order.

    Every set must share one resolution, be of a `variant` object of the
    catalogue and have a location label (tag-1 position, metres) at every
    location; otherwise ValueError naming the store."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; expected one of {VARIANTS}")
    if not store_paths:
        raise ValueError("paper_samples: no capture stores given")
    blocks, rows, shape = [], [], None
    stores = sorted((open_set(Path(p)) for p in store_paths), key=lambda s: s.name)
    for store in stores:
        cs = store.capture_set
        spec = catalogue.get(cs.object)
        if spec is None or spec.variant != variant:
            raise ValueError(f"{store.path}: object {cs.object!r} is not a {variant} object of the catalogue")
        h = store.histograms[...]
        if shape is None:
            shape = h.shape[2:]
        elif h.shape[2:] != shape:
            raise ValueError(f"{store.path}: histograms {h.shape[2:]} differ from the other sets' {shape}")
        order = np.argsort(store.locations, kind="stable")  # store order is capture order; the reference's is the frame's
        h = h[order]
        L, R = h.shape[:2]
        rows.append(sample_rows(cs, spec, store.locations[order], R, labels, store.path))
        blocks.append(h.reshape(L * R, *shape).astype(np.float32))
    return np.concatenate(blocks), pd.concat(rows, ignore_index=True)[list(SAMPLE_COLUMNS)]


def transform(x: np.ndarray, norm: str) -> tuple[np.ndarray, tuple[float, float] | None]:
    """The reference's input transform of raw counts x (N, ...): `raw` gives
    float32 counts and no statistics; `log_z` gives (log1p(clip(x, 0)) - mu) /
    sigma, float32, with mu and sigma (std + 1e-6) over the whole of x,
    returned as (mu, sigma). Same arithmetic as the reference, bit for bit."""
    if norm not in NORMS:
        raise ValueError(f"unknown normalisation {norm!r}; expected one of {NORMS}")
    x = np.asarray(x, dtype=np.float32)
    if norm == "raw":
        return x, None
    y = np.log1p(np.clip(x, 0.0, None))
    mu, sigma = float(y.mean()), float(y.std() + STD_EPSILON)
    return ((y - mu) / sigma).astype(np.float32, copy=False), (mu, sigma)
