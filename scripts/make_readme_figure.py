#!/usr/bin/env python
"""Draw the README's picture: the capture scene from above and the workflow's stages.

    python scripts/make_readme_figure.py                  # writes docs/img/pipeline.png
    python scripts/make_readme_figure.py --out fig.png

Left: the scene in the world frame (metres, top view), drawn from
`denali_pipe.core.geometry` (the one source of the rig's geometry): the relay
wall, the two tables, the 10 x 10 gantry grid, the LiDAR and its laser spot on
the wall, a hidden object at one gantry location, the three-bounce path
(laser spot -> object -> wall -> sensor) and the tracking camera's direction.
Right: the DAG's stages, from captures to the paper's tables and figures.
The PNG is committed; rerun this script when the geometry or the stages change.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch, Rectangle  # noqa: E402

from denali_pipe.core import geometry as geo  # noqa: E402

OUT = Path(__file__).resolve().parent.parent / "docs" / "img" / "pipeline.png"
# A gantry location near the middle of the grid, to show one object position.
SHOWN_LOCATION = 44
# The plate's width in the top view, m: an 8 in object.
PLATE_WIDTH = 0.2032
# Where the three-bounce path returns to the wall, m along x from the laser
# spot: an illustrative wall patch, not a computed zone centre.
RETURN_OFFSET = 0.15

# (label, what it writes) per stage, top to bottom; the side branch is the
# digital twin and the sim-to-real fit.
STAGES = [
    ("captures", "rig (synthetic) | release | pickle"),
    ("ingest", "Zarr stores, capture index, Table 4"),
    ("poses + calibrate", "AprilTag poses, location labels, Table 6, Fig 12"),
    ("preprocess + dataset", "align, subtract background, crop"),
    ("train (cells)", "model x task x split x seed"),
    ("report", "Tables 2, 5, 7-10; Figs 10, 11, 13, 14, 16, 17"),
]
TWIN_STAGES = [
    ("twin", "simulated histograms"),
    ("transforms", "sim-to-real fit; Figs 9, 18"),
]


def draw_scene(ax: plt.Axes) -> None:
    """Top view (x, y) of the capture scene in the world frame."""
    for table in geo.TABLES.values():
        (x0, y0, _), (x1, y1, _) = table.corners()[0], table.corners()[2]
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fc="#f1ede4", ec="#c9c0ad", lw=0.8))
    wall_x = geo.WALL.centre[0] + np.array([-0.5, 0.5]) * geo.WALL.size[0]
    wall_y = geo.WALL.centre[1]
    ax.plot(wall_x, [wall_y] * 2, color="#555", lw=5, solid_capstyle="butt")
    ax.text(geo.WALL.centre[0], wall_y + 0.04, "relay wall", ha="center", fontsize=9)

    grid = geo.tag1_position(np.arange(geo.N_LOCATIONS))
    ax.scatter(grid[:, 0], grid[:, 1], s=4, color="#8aa2c8", zorder=2)
    ax.text(grid[:, 0].max() + 0.03, grid[:, 1].min(), "gantry\n10 x 10", fontsize=8, va="bottom")

    # The object plate stands vertically, facing the wall, in front of tag 1.
    obj = geo.object_pose(SHOWN_LOCATION).t
    ax.plot(obj[0] + np.array([-0.5, 0.5]) * PLATE_WIDTH, [obj[1]] * 2, color="#c0392b", lw=4)
    ax.text(obj[0], grid[:, 1].min() - 0.03, "hidden object", ha="center", va="top", fontsize=9, color="#c0392b")

    sensor = geo.SENSOR_POSITION
    spot = geo.intersect_plane(sensor, geo.SENSOR_FORWARD, geo.WALL)
    back = spot + np.array([RETURN_OFFSET, 0.0, 0.0])
    ax.plot(*sensor[:2], marker="s", ms=9, color="#2c3e50", zorder=4)
    ax.text(sensor[0] - 0.03, sensor[1] - 0.03, "TMF8828\nLiDAR", ha="right", va="top", fontsize=9)
    path = [sensor, spot, obj, back, sensor]
    for a, b, c in zip(path[:-1], path[1:], ["#e67e22", "#e67e22", "#e67e22", "#999"], strict=True):
        ax.add_patch(FancyArrowPatch(a[:2], b[:2], arrowstyle="-|>", mutation_scale=10, color=c, lw=1.3))
    ax.plot(*spot[:2], marker="o", ms=6, color="#e67e22", zorder=4)

    cam = geo.TRACKING_CAMERA
    ax.annotate(
        "tracking camera\n(AprilTags, above)",
        xy=(cam.position[0], -0.05),
        xytext=(cam.position[0], -0.2),
        ha="center",
        fontsize=8,
        arrowprops={"arrowstyle": "-|>", "color": "#7f8c8d"},
    )
    ax.set_xlim(-0.1, 1.65)
    ax.set_ylim(-0.3, 0.95)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("The capture scene, from above", fontsize=10)


def _box(ax: plt.Axes, x: float, y: float, w: float, label: str, note: str, colour: str) -> None:
    ax.add_patch(FancyBboxPatch((x, y - 0.035), w, 0.07, boxstyle="round,pad=0.01", fc=colour, ec="#555", lw=0.8))
    ax.text(x + w / 2, y + 0.012, label, ha="center", va="center", fontsize=9, weight="bold")
    ax.text(x + w / 2, y - 0.017, note, ha="center", va="center", fontsize=7)


def _arrow(ax: plt.Axes, a: tuple[float, float], b: tuple[float, float]) -> None:
    ax.add_patch(FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=9, color="#555", lw=0.9))


def draw_stages(ax: plt.Axes) -> None:
    """The workflow's stages as boxes, top to bottom, the twin beside them."""
    ys = np.linspace(0.92, 0.1, len(STAGES))
    x, w = 0.02, 0.56
    for y, (label, note) in zip(ys, STAGES, strict=True):
        _box(ax, x, y, w, label, note, "#eaf1fb")
    for y0, y1 in zip(ys[:-1], ys[1:], strict=True):
        _arrow(ax, (x + w / 2, y0 - 0.045), (x + w / 2, y1 + 0.045))
    tx, tw = 0.64, 0.35
    twin_ys = [ys[3], ys[4]]
    for y, (label, note) in zip(twin_ys, TWIN_STAGES, strict=True):
        _box(ax, tx, y, tw, label, note, "#fdf2e4")
    _arrow(ax, (x + w + 0.01, ys[2]), (tx + tw / 2, twin_ys[0] + 0.045))
    _arrow(ax, (tx + tw / 2, twin_ys[0] - 0.045), (tx + tw / 2, twin_ys[1] + 0.045))
    _arrow(ax, (tx + tw / 2, twin_ys[1] - 0.045), (x + w + 0.01, ys[5]))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.axis("off")
    ax.set_title("The workflow: one Snakemake DAG", fontsize=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    fig, (scene, stages) = plt.subplots(1, 2, figsize=(10, 4.2), gridspec_kw={"width_ratios": [1.1, 1]})
    draw_scene(scene)
    draw_stages(stages)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=100)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
