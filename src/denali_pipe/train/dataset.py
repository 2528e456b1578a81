"""The benchmark's samples at one resolution: every repeat of every base-object
capture, both lightings pooled (as in the paper), with its labels.

Written by the `dataset` rule as `results/datasets/<res>.zarr` (array `x`,
(N, n, n, T) float32 preprocessed counts) and `results/datasets/<res>.parquet`
(one row per sample: set, object, class, type, size, light, location, repeat,
x, y). Rows follow the reference's order: capture-set name (ASCII), location,
repeat; the seeded splits depend on it. The `variant_dataset` rule writes the
italic and non-retroreflective sets the same way, as
`results/datasets/<variant>_<res>.zarr` + `.parquet`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import zarr

from denali_pipe.core.atomic import atomic_dir, atomic_file
from denali_pipe.core.capture_sets import CaptureSet
from denali_pipe.core.objects import VARIANTS, ObjectSpec
from denali_pipe.io.features import read_features

SAMPLE_COLUMNS = ("set", "object", "class", "type", "size", "light", "location", "repeat", "x", "y")


def location_labels(positions: pd.DataFrame) -> dict[int, tuple[float, float]]:
    """Location -> (x, y) of the object tag in metres, from the calibration's
    tag1_positions table (z is constant on the gantry plane and dropped)."""
    missing = {"location", "x", "y"} - set(positions.columns)
    if missing:
        raise ValueError(f"tag1 positions table lacks the columns {sorted(missing)}")
    return {int(r.location): (float(r.x), float(r.y)) for r in positions.itertuples()}


def sample_rows(
    cs: CaptureSet, spec: ObjectSpec, locations: np.ndarray, repeats: int, labels: dict[int, tuple[float, float]], where: Path | str
) -> pd.DataFrame:
    """The sample table (SAMPLE_COLUMNS) of one set's (L,) `locations` x
    `repeats`, location-major: each repeat its own row, labelled with its
    location's tag-1 position (x, y, metres). ValueError naming `where` when
    a location has no label."""
    unlabelled = sorted(int(k) for k in locations if int(k) not in labels)
    if unlabelled:
        raise ValueError(f"{where}: no location label (tag 1 position) for locations {unlabelled}")
    loc = np.repeat(np.asarray(locations), repeats)
    xy = np.array([labels[int(k)] for k in loc])
    return pd.DataFrame(
        {
            "set": cs.name, "object": cs.object, "class": spec.cls, "type": spec.type, "size": cs.size, "light": cs.light,
            "location": loc.astype(np.int64), "repeat": np.tile(np.arange(repeats), len(locations)), "x": xy[:, 0], "y": xy[:, 1],
        }
    )[list(SAMPLE_COLUMNS)]  # fmt: skip


def build_dataset(
    feature_paths: list[Path], catalogue: dict[str, ObjectSpec], labels: dict[int, tuple[float, float]], variant: str = "base"
) -> tuple[np.ndarray, pd.DataFrame]:
    """Stack the sets' features into (N, n, n, T) float32 and their sample table.

    Every set must share one resolution and crop window; the label of every
    location must exist. Every object must be of `variant` (objects.VARIANTS):
    the benchmark's samples are base objects only, and the italic and
    non-retroreflective sets are datasets of their own (held-out test sets,
    never training samples)."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; expected one of {VARIANTS}")
    blocks, rows, shape, crop = [], [], None, None
    for path in sorted(feature_paths, key=lambda p: Path(p).name):
        cs, f = read_features(path)
        spec = catalogue.get(cs.object)
        if spec is None or spec.variant != variant:
            raise ValueError(f"{path}: object {cs.object!r} is not a {variant} object of the catalogue")
        if shape is None:
            shape, crop = f.values.shape[2:], f.crop_start
        elif f.values.shape[2:] != shape or f.crop_start != crop:
            raise ValueError(f"{path}: features {f.values.shape[2:]} from bin {f.crop_start} differ from the other sets' {shape} from bin {crop}")
        L, R = f.values.shape[:2]
        rows.append(sample_rows(cs, spec, f.locations, R, labels, path))
        blocks.append(f.values.reshape(L * R, *shape))
    if not blocks:
        raise ValueError("build_dataset: no feature stores given")
    return np.concatenate(blocks), pd.concat(rows, ignore_index=True)[list(SAMPLE_COLUMNS)]


def write_dataset(x: np.ndarray, samples: pd.DataFrame, array_path: Path, table_path: Path, crop_start: int) -> None:
    with atomic_dir(Path(array_path)) as tmp:
        root = zarr.open_group(tmp, mode="w", zarr_format=3)
        root.create_array("x", data=x, chunks=(min(len(x), 4096), *x.shape[1:]))
        root.attrs.update({"crop_start": int(crop_start), "n_samples": int(len(x))})
    with atomic_file(Path(table_path)) as tmp:
        samples.to_parquet(tmp, index=False)


def read_dataset(array_path: Path, table_path: Path) -> tuple[np.ndarray, pd.DataFrame, int]:
    """(x (N, n, n, T) float32, samples, crop_start); ValueError if they disagree."""
    root = zarr.open_group(Path(array_path), mode="r")
    x = root["x"][...]
    samples = pd.read_parquet(table_path)
    if len(samples) != len(x):
        raise ValueError(f"{table_path}: {len(samples)} sample rows but {array_path} holds {len(x)} samples")
    return x, samples, int(root.attrs["crop_start"])
