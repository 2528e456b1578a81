"""Reading a release-layout capture set folder `<set>_NLOSdata/`."""

from __future__ import annotations

import re
from pathlib import Path

HISTOGRAM_DIR = "spad_histogram"
FRAME_DIRS = ("tracking_rgb", "tracking_depth", "colocated_rgb", "colocated_depth")
# The published release's frames: tracking colour only (and no metadata.json).
PUBLIC_FRAME_DIRS = ("tracking_rgb",)
METADATA_FILE = "metadata.json"

_NNN = re.compile(r"^(\d{3})\.npy$")


def histogram_files(set_dir: Path) -> dict[int, Path]:
    """{gantry location: spad_histogram/NNN.npy} of a set folder, sorted by location."""
    folder = Path(set_dir) / HISTOGRAM_DIR
    if not folder.is_dir():
        raise FileNotFoundError(f"{set_dir}: no {HISTOGRAM_DIR}/ folder")
    files = {}
    for p in sorted(folder.iterdir()):
        m = _NNN.match(p.name)
        if m is None:
            raise ValueError(f"{p}: unexpected file in {HISTOGRAM_DIR}/ (expected NNN.npy)")
        files[int(m[1])] = p
    return files
