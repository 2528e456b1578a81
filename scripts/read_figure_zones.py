#!/usr/bin/env python
"""Every zone of the release's plotted real 3x3 capture, read bar by bar,
beside the rig's; prints a table, writes nothing.

    python scripts/read_figure_zones.py
    python scripts/read_figure_zones.py --figure ../shared/denali-assets/figures/capture_setup.png

`capture_setup.png`'s "LiDAR Histograms (3x3 Mode)" grid plots one real
capture (a hexagon at about gantry location 84, docs/rig_zones.md), each
zone on its own scale: a bar's height is its pixel column's blue run, in
pixels, 128 bins across the panel (~1.8 px a bin), so a height is +-1 px.
The label box hides the tops of pixels 1 and 2: their peaks, and what is
measured against them, are lower bounds there (marked *).

Per zone, the real capture and the rig's expected counts (the design
scene, the 8 in hexagon at location 84, lights off as the figure's centre
floor of 1.6 % of its peak says), measured by `rig.measure.zone_shape`: the
bin where the direct return first reaches half its height above the floor
(relative to the centre zone's here), its width above half, its tails, the
late floor and the near-field return. `report.paper.REAL_FIGURE_ZONES`
records the real readings.

Cited by docs/rig_zones.md, "Every zone of the figure, read bar by bar".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import yaml

from denali_pipe.core import geometry as geo
from denali_pipe.core.objects import load_catalogue
from denali_pipe.rig import histograms as H
from denali_pipe.rig.measure import zone_shape
from denali_pipe.rig.scene import design_scene

REPO = Path(__file__).resolve().parents[1]
FIGURE = REPO.parent / "shared" / "denali-assets" / "figures" / "capture_setup.png"
# The grid's region of the figure (rows, columns, px) and its 3 x 3 panels'
# blue extents within it, found from the blue bars' column and row sums.
GRID = (slice(800, 1300), slice(50, 860))
PANEL_COLUMNS = ((18, 253), (285, 520), (551, 786))
PANEL_ROWS = ((0, 170), (185, 330), (345, 490))
CLIPPED = {0, 1}  # pixels 1 and 2: their tops lie under the figure's label


def panels(figure: Path) -> np.ndarray:
    """(9, N_BINS) bar heights in pixels, zones in the captures' order."""
    image = cv2.imread(str(figure))
    if image is None:
        raise SystemExit(f"{figure}: not a readable image")
    b, g, r = (image[GRID][..., i].astype(int) for i in range(3))
    blue = (b > 120) & (r < 80) & (b - r > 80)
    out = []
    for y0, y1 in PANEL_ROWS:
        for x0, x1 in PANEL_COLUMNS:
            p = blue[y0 : y1 + 1, x0 : x1 + 1]
            baseline = np.nonzero(p.any(1))[0].max()
            heights = np.array([baseline - np.nonzero(col)[0].min() + 1 if col.any() else 0 for col in p.T], float)
            edges = np.round(np.linspace(0, len(heights), geo.N_BINS + 1)).astype(int)
            out.append([heights[a:b].max() for a, b in zip(edges[:-1], edges[1:])])
    return np.asarray(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figure", type=Path, default=FIGURE)
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    args = ap.parse_args()
    with open(args.config) as f:
        config = yaml.safe_load(f)
    phot = H.Photometry.from_config(config["rig"]["photometry"], geo.TimeAxis.from_config(config["sensor"]["time_axis"]))
    scene = design_scene(load_catalogue(REPO / "config" / "objects.tsv")["hexagon"], "8inch", 84)
    rig = H.expected_counts("3x3", False, scene, phot).reshape(9, -1)
    real = panels(args.figure)
    centre = 4
    rows = {"real": [zone_shape(h) for h in real], "rig": [zone_shape(h) for h in rig]}
    for source, zones in rows.items():
        print(source)
        for key in zones[0]:
            values = [z[key] - zones[centre][key] if key == "half_rise" else z[key] for z in zones]
            marks = ["*" if source == "real" and i in CLIPPED and key not in ("half_rise", "late_over_floor") else " " for i in range(9)]
            print(f"  {key:16s}" + "".join(f"{v:8.3g}{m}" for v, m in zip(values, marks)))


if __name__ == "__main__":
    main()
