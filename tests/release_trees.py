"""Release-layout capture trees of empty files, for the tests of what reads
only their names (the tree survey, the workflow's refusal, check-release)."""

from __future__ import annotations

from pathlib import Path

from denali_pipe.core.capture_sets import FOLDER_SUFFIX
from denali_pipe.core.geometry import N_LOCATIONS


def write_set(raw: Path, name: str, locations=range(N_LOCATIONS), frames=None, folder=None) -> Path:
    """A public-layout set folder (`folder`, default `<name>_NLOSdata`) of
    empty files: spad_histogram/NNN.npy at `locations`, tracking_rgb/NNN.png
    at `frames` (default: the same)."""
    d = raw / (folder or f"{name}{FOLDER_SUFFIX}")
    for sub, ext, locs in (("spad_histogram", "npy", locations), ("tracking_rgb", "png", locations if frames is None else frames)):
        (d / sub).mkdir(parents=True)
        for k in locs:
            (d / sub / f"{k:03d}.{ext}").touch()
    return d


def write_tree(raw: Path, sets, skip=(), locations=range(N_LOCATIONS)) -> None:
    """Every set of `sets` but those named in `skip`, each at `locations`."""
    for s in sets:
        if s.name not in skip:
            write_set(raw, s.name, locations)
