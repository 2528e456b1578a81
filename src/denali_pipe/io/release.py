"""Reading a release-layout capture set folder `<set>_NLOSdata/`."""

from __future__ import annotations

import re
from pathlib import Path

HISTOGRAM_DIR = "spad_histogram"
FRAME_DIRS = ("tracking_rgb", "tracking_depth", "colocated_rgb", "colocated_depth")
# The published release's frames: tracking colour only (and no metadata.json).
PUBLIC_FRAME_DIRS = ("tracking_rgb",)
METADATA_FILE = "metadata.json"
# What a set folder of the public release holds, for the messages about a set with nothing to read.
PUBLIC_LAYOUT = (
    f"{HISTOGRAM_DIR}/NNN.npy (one (3 repeats, n, n, 128) count array per gantry location, NNN from 000 to 099) "
    f"and {PUBLIC_FRAME_DIRS[0]}/NNN.png (one tracking frame per location), and no {METADATA_FILE}"
)

_NNN = re.compile(r"^(\d{3})\.npy$")


def histogram_files(set_dir: Path) -> dict[int, Path]:
    """{gantry location: spad_histogram/NNN.npy} of a set folder, sorted by location."""
    folder = Path(set_dir) / HISTOGRAM_DIR
    if not folder.is_dir():
        raise FileNotFoundError(f"{set_dir}: no {HISTOGRAM_DIR}/ folder: a public-layout capture set holds {PUBLIC_LAYOUT}")
    files = {}
    for p in sorted(folder.iterdir()):
        m = _NNN.match(p.name)
        if m is None:
            raise ValueError(f"{p}: unexpected file in {HISTOGRAM_DIR}/ (expected NNN.npy)")
        files[int(m[1])] = p
    return files


def location_span(locations) -> str:
    """Gantry locations as their file stems in runs, e.g. [0, 1, 2, 4] -> '000-002, 004'
    (a message naming 99 locations stays one short line)."""
    locs = sorted(int(k) for k in locations)
    if not locs:
        return "none"
    runs, start = [], locs[0]
    for prev, k in zip(locs, [*locs[1:], None]):
        if k is None or k != prev + 1:  # a run ends at prev
            runs.append(f"{start:03d}" if start == prev else f"{start:03d}-{prev:03d}")
            start = k
    return ", ".join(runs)
