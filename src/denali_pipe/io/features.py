"""Preprocessed features of one capture set: `results/features/<set>.zarr`.

Arrays: `features` (L, R, n, n, T) float32 background-subtracted counts,
`location` (L,) int16, `shift` (L, R) int8 alignment shifts in bins. Attrs:
the set's fields, `crop_start` (first kept bin of the original histogram),
`background` (the subtracted set's name).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from denali_pipe.core.atomic import atomic_dir
from denali_pipe.core.capture_sets import CaptureSet, parse_set_name

FORMAT_VERSION = 1


@dataclass(frozen=True)
class Features:
    """One set's preprocessed histograms.

    values: (L, R, n, n, B - crop_start) float32 background-subtracted counts;
    locations: (L,) gantry locations; shifts: (L, R) whole-bin alignment
    shifts applied; crop_start: first kept bin of the original 128."""

    values: np.ndarray
    locations: np.ndarray
    shifts: np.ndarray
    crop_start: int


def write_features(path: Path, cs: CaptureSet, features: Features, background: str) -> None:
    """Write atomically: a failed job leaves no store behind."""
    with atomic_dir(Path(path)) as tmp:
        root = zarr.open_group(tmp, mode="w", zarr_format=3)
        values = features.values
        root.create_array("features", data=values, chunks=(1, *values.shape[1:]))
        root.create_array("location", data=features.locations.astype(np.int16))
        root.create_array("shift", data=features.shifts.astype(np.int8))
        root.attrs.update(
            {
                "format_version": FORMAT_VERSION,
                "set": cs.name,
                "object": cs.object,
                "size": cs.size,
                "resolution": cs.resolution,
                "light": cs.light,
                "crop_start": int(features.crop_start),
                "background": background,
            }
        )


def read_features(path: Path) -> tuple[CaptureSet, Features]:
    """The set and its features; ValueError naming the file if it is not one."""
    path = Path(path)
    try:
        root = zarr.open_group(path, mode="r")
        attrs = dict(root.attrs)
        version = attrs.get("format_version")
        if version != FORMAT_VERSION:
            raise ValueError(f"format_version {version!r}, expected {FORMAT_VERSION}")
        feats = Features(root["features"][...], root["location"][...].astype(np.int64), root["shift"][...].astype(np.int64), int(attrs["crop_start"]))
    except (KeyError, FileNotFoundError, zarr.errors.GroupNotFoundError) as e:
        raise ValueError(f"{path}: not a features store ({e})") from None
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None
    return parse_set_name(attrs["set"]), feats
