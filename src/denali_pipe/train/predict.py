"""Trained cells on one raw capture: the capture read from a release file or
a pickle stream, preprocessed as the training data was, and every cell's
answer as one JSON-ready record (`denali predict`).

Preprocessing is the pipeline's (preprocess.py), for one gantry location:
the capture's repeats are aligned with the background's direct return,
the background (the NOOBJECT set of the same resolution and lighting, at the
same location, with its shot noise removed across the set's locations) is
subtracted, and the histograms are cropped to the resolution's window
(results/features/crop_<res>.json); each cell then applies its own
normalisation (evaluate.predict). Outputs are averaged over the
repeats used: positions in metres, class probabilities (softmax of the logits).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from denali_pipe.io.pickle_stream import iter_records
from denali_pipe.io.release import histogram_files
from denali_pipe.preprocess.histograms import CropWindow, background_means, preprocess
from denali_pipe.train.evaluate import TrainedCell, predict

BINS = 128  # the sensor's histogram length
ZONES = (3, 8)  # zones per side of the 3x3 and 8x8 modes
TOP_SHAPES = 5
_NNN = re.compile(r"^(\d{3})\.npy$")


@dataclass(frozen=True)
class Capture:
    """One gantry location's histograms: counts (R, n, n, 128), R repeats."""

    counts: np.ndarray
    location: int
    source: str


@dataclass(frozen=True)
class Background:
    """The background at one gantry location: counts (n, n, 128), the
    NOOBJECT set's at `location` (preprocess.background_means, over the
    `n_locations` locations read from `source`)."""

    counts: np.ndarray
    location: int
    source: str
    n_locations: int


def _checked(counts: np.ndarray, source: str) -> np.ndarray:
    counts = np.asarray(counts)
    if counts.ndim != 4 or counts.shape[1] != counts.shape[2] or counts.shape[1] not in ZONES or counts.shape[-1] != BINS:
        raise ValueError(f"{source}: histograms of shape {counts.shape}; expected (repeats, n, n, {BINS}) with n in {ZONES}")
    return counts


def read_capture(path: Path, location: int | None = None) -> Capture:
    """The capture at `path`: a release file `<set>_NLOSdata/spad_histogram/NNN.npy`
    (of location NNN; `location`, when given, must agree), a capture-set
    store `<set>.zarr`, or a pickle stream `<set>_short_NLOSdata.pkl` (both
    need `location` when they hold more than one). ValueError naming the
    file for anything else."""
    path = Path(path)
    if path.suffix == ".npy":
        m = _NNN.match(path.name)
        if m is None and location is None:
            raise ValueError(f"{path}: not named NNN.npy after its gantry location; give the location")
        if m is not None and location is not None and int(m[1]) != location:
            raise ValueError(f"{path}: the file of gantry location {int(m[1])}, not of location {location}")
        return Capture(_checked(np.load(path, allow_pickle=False), str(path)), int(m[1]) if m is not None else location, str(path))
    if path.suffix == ".zarr":
        from denali_pipe.io.store import open_set

        store = open_set(path)
        k = _only_location(path, [int(v) for v in store.locations], location)
        return Capture(_checked(store.histogram(store.index_of(k)), str(path)), k, str(path))
    if path.suffix == ".pkl":
        records = _stream_histograms(path)
        k = _only_location(path, list(records), location)
        return Capture(_checked(records[k], f"{path} (location {k})"), k, str(path))
    raise ValueError(f"{path}: not a capture (expected a release NNN.npy, a <set>.zarr store or a .pkl capture stream)")


def read_background(path: Path, location: int) -> Background:
    """The background at `location` from a whole NOOBJECT set, as the
    pipeline computes it: a release folder `<set>_NLOSdata`, a store
    `<set>.zarr` or a pickle stream. A single NNN.npy is read too, but one
    capture gives its plain mean over repeats: its shot noise stays in the
    features, where the training's backgrounds had it removed."""
    path = Path(path)
    if path.is_dir() and path.suffix != ".zarr":
        files = histogram_files(path)
        locations = list(files)
        counts = [_checked(np.load(p, allow_pickle=False), str(p)) for p in files.values()]
    elif path.suffix == ".zarr":
        from denali_pipe.io.store import open_set

        store = open_set(path)
        locations, counts = [int(k) for k in store.locations], [_checked(h, str(path)) for h in store.histograms[...]]
    elif path.suffix == ".pkl":
        records = _stream_histograms(path)
        locations, counts = list(records), [_checked(h, f"{path} (location {k})") for k, h in records.items()]
    else:
        one = read_capture(path, location)
        locations, counts = [one.location], [one.counts]
    _only_location(path, locations, location)
    if len({c.shape for c in counts}) != 1:
        raise ValueError(f"{path}: its captures differ in shape ({sorted({c.shape for c in counts})})")
    means = background_means(np.stack(counts))
    return Background(means[locations.index(location)], location, str(path), len(locations))


def _stream_histograms(path: Path) -> dict:
    """{gantry location: histograms} of a pickle stream's location records."""
    return {int(rec["iter"]): rec["histogram"] for i, rec in iter_records(path) if i > 0}


def _only_location(path: Path, locations: list[int], wanted: int | None) -> int:
    if wanted is None:
        if len(locations) != 1:
            raise ValueError(f"{path} holds {len(locations)} gantry locations; give the location to use")
        return locations[0]
    if wanted not in locations:
        raise ValueError(f"{path} has no capture at gantry location {wanted} (it has {sorted(locations)[:10]}{' ...' if len(locations) > 10 else ''})")
    return wanted


def capture_features(capture: Capture, background: Background, window: CropWindow) -> np.ndarray:
    """(R, n, n, T) float32: the capture aligned, minus the background at
    the same location, cropped to `window` (preprocess.preprocess)."""
    if background.location != capture.location:
        raise ValueError(f"background {background.source} is gantry location {background.location}, the capture {capture.source} is {capture.location}")
    try:
        f = preprocess(capture.counts[None], np.array([capture.location]), background.counts[None], np.array([background.location]), window)
    except ValueError as e:
        raise ValueError(f"{capture.source} (background {background.source}): {e}") from None
    return f.values[0]


def softmax(logits: np.ndarray) -> np.ndarray:
    """Class probabilities (N, C) from logits (N, C)."""
    e = np.exp(logits - logits.max(axis=1, keepdims=True))
    return e / e.sum(axis=1, keepdims=True)


def answer(trained: TrainedCell, features: np.ndarray) -> dict:
    """One cell's answer for features (R, n, n, T), averaged over the R repeats:
    location {"x_m", "y_m"}; shape {"top5": [{"class", "probability"}, ...]};
    size {"class", "probabilities": {class: p}}."""
    out = predict(trained, features)
    task = trained.cell.task
    if task == "location":
        x, y = out.mean(axis=0)
        return {"x_m": float(x), "y_m": float(y)}
    p = softmax(out).mean(axis=0)
    ranked = np.argsort(-p, kind="stable")
    if task == "shape":
        return {"top5": [{"class": trained.classes[i], "probability": float(p[i])} for i in ranked[:TOP_SHAPES]]}
    return {"class": trained.classes[ranked[0]], "probabilities": {c: float(v) for c, v in zip(trained.classes, p)}}


def predict_capture(cells: list[tuple[Path, TrainedCell]], capture: Capture, background: Background, window: CropWindow, repeat: int | None = None) -> dict:
    """Every cell's answer for the capture (at most one cell per task), and
    what it was computed from: the capture, its location, the repeats
    averaged (all, or `repeat`), each task's run folder. `cells`: (run
    folder, its loaded cell) pairs."""
    tasks = [c.cell.task for _, c in cells]
    if len(set(tasks)) != len(tasks):
        raise ValueError(f"one cell per task: got tasks {tasks} from {[str(p) for p, _ in cells]}")
    features = capture_features(capture, background, window)
    repeats = list(range(len(features)))
    if repeat is not None:
        if repeat not in repeats:
            raise ValueError(f"{capture.source}: no repeat {repeat} (it has {len(repeats)})")
        repeats = [repeat]
    record = {
        "capture": capture.source,
        "background": background.source,
        "background_locations": background.n_locations,
        "gantry_location": capture.location,
        "repeats": repeats,
    }
    for run_dir, trained in cells:
        record[trained.cell.task] = {**answer(trained, features[repeats]), "run": str(run_dir), "model": trained.cell.model}
    return record
