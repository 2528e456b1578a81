"""Real raw TMF882x captures in the layout the sensor is fitted to: one
`.npz` per scene (docs/sensor.md), each capture's nine zones' raw counts,
its reference channel, its pose, and for a distance sweep the plane's distance."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

ZONES, BINS = 9, 128
SWEEP = "iccp_distance_sweep.npz"  # the flat plane at known distances; the other .npz are scenes


@dataclass(frozen=True)
class Captures:
    """hists (N, ZONES, BINS) float raw counts; reference (N, BINS) the
    reference SPAD channel; pose (N, 4, 4) the sensor's pose (the source's
    frame); distance_m (N,) the plane's distance (a sweep), else None."""

    name: str
    hists: np.ndarray
    reference: np.ndarray
    pose: np.ndarray
    distance_m: np.ndarray | None

    def select(self, rows: np.ndarray) -> Captures:
        d = None if self.distance_m is None else self.distance_m[rows]
        return Captures(self.name, self.hists[rows], self.reference[rows], self.pose[rows], d)


def read_captures(path: Path) -> Captures:
    """One `.npz` of captures; ValueError naming the file and what is wrong
    when a key is missing or a shape or value is not a histogram's."""
    path = Path(path)
    try:
        with np.load(path) as f:
            data = {k: f[k] for k in f.files}
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: not a readable .npz of captures ({e})") from None
    missing = sorted({"hists", "reference", "pose"} - set(data))
    if missing:
        raise ValueError(f"{path}: missing {missing}; expected hists (N, {ZONES}, {BINS}), reference (N, {BINS}), pose (N, 4, 4)")
    hists, ref, pose = data["hists"], data["reference"], data["pose"]
    n = len(hists)
    if hists.shape != (n, ZONES, BINS) or ref.shape != (n, BINS) or pose.shape != (n, 4, 4):
        raise ValueError(f"{path}: hists {hists.shape}, reference {ref.shape}, pose {pose.shape}; expected (N, {ZONES}, {BINS}), (N, {BINS}), (N, 4, 4)")
    if np.any(hists < 0) or not np.all(np.isfinite(hists)):
        raise ValueError(f"{path}: hists holds negative or non-finite counts")
    dist = data.get("dist_to_plane_m")
    if dist is not None and dist.shape != (n,):
        raise ValueError(f"{path}: dist_to_plane_m {dist.shape}; expected ({n},)")
    return Captures(path.stem, hists.astype(float), ref.astype(float), pose.astype(float), None if dist is None else dist.astype(float))
