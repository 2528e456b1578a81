"""One capture's arrays from the workflow's outputs, and the calibration's
geometry: plain numpy arrays and tables for the figures.

Readers are cached by path and modification time, so a rebuilt output is
read afresh and an unchanged one once.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import CaptureSet
from denali_pipe.explore.outputs import POSITIONS, SCENE, TRANSFORMS, Inventory, crop_path, features_path, index_path, store_path, twin_path
from denali_pipe.io.features import read_features
from denali_pipe.io.store import CaptureStore, open_set
from denali_pipe.preprocess.histograms import CropWindow, read_crop_window
from denali_pipe.transforms.sim_to_real import CENTRE_ZONE, apply, read_transforms
from denali_pipe.twin.render import read_twin

# The twin's overlay: the transforms that shape its mean (scale, then blur);
# noise would draw one random histogram instead of the expected one.
TWIN_FIDELITY = "blurred"
TRACKING = "tracking_rgb"


def _stamp(path: Path) -> int:
    return path.stat().st_mtime_ns


@dataclass(frozen=True)
class Calibration:
    """The calibration's geometry.

    positions: one row per calibrated gantry location (index `location`):
    x, y, z of tag 1 in metres, the location labels; K (3, 3), R (3, 3),
    t (3,): the tracking camera (world -> camera: X_cam = R X + t) at
    `image_size` (width, height) pixels."""

    positions: pd.DataFrame
    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    image_size: tuple[int, int]

    def pixels(self, points: np.ndarray, frame_size: tuple[int, int]) -> np.ndarray:
        """(N, 2) pixel coordinates (u right, v down) of world points (N, 3) in
        a tracking frame of `frame_size` (width, height): the intrinsics scale
        with the frame, as the rig's and the release's frame sizes differ."""
        s = np.diag([frame_size[0] / self.image_size[0], frame_size[1] / self.image_size[1], 1.0])
        pc = np.asarray(points, float) @ self.R.T + self.t
        uv = pc @ (s @ self.K).T
        return uv[:, :2] / uv[:, 2:3]


@lru_cache(maxsize=4)
def _calibration(positions: Path, scene: Path, _stamps: tuple[int, int]) -> Calibration:
    table = pd.read_parquet(positions)
    missing = {"location", "x", "y", "z"} - set(table.columns)
    if missing:
        raise ValueError(f"{positions}: tag-1 positions table lacks the columns {sorted(missing)}")
    try:
        cam = json.loads(scene.read_text())["tracking_camera"]
        intr = cam["intrinsics"]
        K = np.array([[intr["fx"], 0.0, intr["cx"]], [0.0, intr["fy"], intr["cy"]], [0.0, 0.0, 1.0]])
        R, t, size = np.array(cam["R_world_to_camera"], float), np.array(cam["t_world_to_camera"], float), (int(intr["width"]), int(intr["height"]))
    except (ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{scene}: no tracking camera in the scene ({type(e).__name__}: {e})") from None
    return Calibration(table.set_index("location")[["x", "y", "z"]].astype(float), K, R, t, size)


def read_calibration(inv: Inventory) -> Calibration:
    positions, scene = inv.path(POSITIONS), inv.path(SCENE)
    return _calibration(positions, scene, (_stamp(positions), _stamp(scene)))


def gantry_grid(positions: pd.DataFrame) -> pd.DataFrame:
    """Every gantry location (0..N_LOCATIONS-1): location, row, col, x, y
    (m) and `calibrated`. Calibrated locations sit at their labels; the
    others where an affine map of (row, col) fitted to the calibrated ones
    puts them (so the grid follows the measured gantry, not the drawing).
    `positions`: `Calibration.positions`, at least 3 locations not on one line."""
    loc = np.arange(geo.N_LOCATIONS)
    row, col = geo.gantry_row_col(loc)
    design = np.column_stack([np.ones(len(loc)), row, col])
    known = positions.index.to_numpy(int)
    coef, *_ = np.linalg.lstsq(design[known], positions[["x", "y"]].to_numpy(), rcond=None)
    xy = design @ coef
    xy[known] = positions[["x", "y"]].to_numpy()
    return pd.DataFrame({"location": loc, "row": row, "col": col, "x": xy[:, 0], "y": xy[:, 1], "calibrated": np.isin(loc, known)})


@lru_cache(maxsize=64)
def _store(path: Path, _stamp: int) -> CaptureStore:
    return open_set(path)


def capture_store(inv: Inventory, cs: CaptureSet) -> CaptureStore:
    path = inv.path(store_path(cs.name))
    return _store(path, _stamp(path))


def tracking_frame(store: CaptureStore, location: int) -> np.ndarray | None:
    """The tracking camera's (H, W, 3) uint8 RGB frame at a location, None
    when the set has no tracking frames."""
    if TRACKING not in store.modalities:
        return None
    return np.ascontiguousarray(store.frame(TRACKING, store.index_of(location))[..., ::-1])


def raw_histograms(store: CaptureStore, location: int) -> np.ndarray:
    """(repeats, n, n, 128) int32 counts at a location."""
    return store.histogram(store.index_of(location))


def background_mean(store: CaptureStore, location: int) -> np.ndarray:
    """(n, n, 128) float64: the repeats' mean at a location (what preprocessing subtracts)."""
    return raw_histograms(store, location).mean(axis=0, dtype=np.float64)


@lru_cache(maxsize=2)
def _crop(path: Path, _stamp: int) -> CropWindow:
    return read_crop_window(path)


def crop_window(inv: Inventory, resolution: str) -> CropWindow | None:
    path = inv.path(crop_path(resolution))
    return _crop(path, _stamp(path)) if path.is_file() else None


@lru_cache(maxsize=16)
def _features(path: Path, _stamp: int):
    return read_features(path)[1]


def capture_features(inv: Inventory, cs: CaptureSet, location: int) -> tuple[np.ndarray, int]:
    """((repeats, n, n, T) float32 background-subtracted cropped counts at a
    location, crop_start: the first kept bin). KeyError for a location the
    set lacks."""
    path = inv.path(features_path(cs.name))
    f = _features(path, _stamp(path))
    hit = np.flatnonzero(f.locations == int(location))
    if not len(hit):
        raise KeyError(f"{path}: no location {location}")
    return f.values[hit[0]], f.crop_start


@lru_cache(maxsize=16)
def _twin(path: Path, _stamp: int):
    return read_twin(path)


@lru_cache(maxsize=1)
def _transforms(path: Path, _stamp: int):
    return read_transforms(path)


def twin_histogram(inv: Inventory, obj: str, size: str, location: int) -> np.ndarray:
    """(128,) the calibrated twin's centre-zone transient at a location after
    that zone's fitted scale and blur: expected counts on the real histograms' time axis."""
    path, tpath = inv.path(twin_path(obj, size)), inv.path(TRANSFORMS)
    sim = _twin(path, _stamp(path)).histogram(location, "3x3")[1, 1]
    return apply(sim, _transforms(tpath, _stamp(tpath)).zones[CENTRE_ZONE], TWIN_FIDELITY)


@lru_cache(maxsize=64)
def _index_class(path: Path, _stamp: int) -> str:
    classes = pd.read_parquet(path, columns=["class"])["class"].unique()
    if len(classes) != 1:
        raise ValueError(f"{path}: a capture set's index with classes {sorted(classes)}")
    return str(classes[0])


def object_class(inv: Inventory, cs: CaptureSet) -> str | None:
    """The set's shape class (the index written with its store), None
    without an index."""
    path = inv.path(index_path(cs.name))
    return _index_class(path, _stamp(path)) if path.is_file() else None
