"""`results/rig_examples.png`: raw histograms of the rig with the three-bounce bump marked.

For each (object set, NOOBJECT set) pair, three locations (nearest, middle,
farthest from the wall) are shown for the centre zone, averaged over repeats:
the zone the release's figures plot, and the one the beam's core lights (an
8 in circle's bump there is 3-10x the one in the zone nearest the object,
docs/rig_zones.md). The difference is also shown smoothed. The shaded window
is where geometry alone puts the object's retroreflective return:
2|s - q| + 2|q - o| over the zone's wall samples q and the corners of the
object's plate o, widened by the pulse.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.figure import plt, save_figure
from denali_pipe.core.objects import BOTTOM_Y, SIZES
from denali_pipe.io.store import open_set
from denali_pipe.rig.histograms import wall_samples

PULSE_MARGIN_BINS = (3, 8)  # jitter before, SPAD tail after the geometric window
SMOOTH_BINS = 5  # the bump spans ~10 bins; a short box mean shows it above shot noise


def plate_corners(size: str, location: int) -> np.ndarray:
    """(4, 3) world corners of a square plate of the object's size at a location."""
    s = SIZES[size]
    local = np.array([[x, y, 0.0] for x in (-s / 2, s / 2) for y in (BOTTOM_Y, BOTTOM_Y + s)])
    return geo.object_pose(location).apply(local)


def bump_window(resolution: str, size: str, location: int, zone: tuple[int, int], axis: geo.TimeAxis) -> tuple[float, float]:
    """First and last bin (fractional, on `axis`) of the predicted three-bounce return."""
    ws = wall_samples(resolution)
    z = zone[0] * geo.RESOLUTIONS[resolution] + zone[1]
    q, r = ws.q[z], ws.r[z]
    o = plate_corners(size, location)
    opl = 2 * r[:, None] + 2 * np.linalg.norm(q[:, None, :] - o[None, :, :], axis=-1)
    b = axis.opl_to_bin(opl)
    return float(b.min() - PULSE_MARGIN_BINS[0]), float(b.max() + PULSE_MARGIN_BINS[1])


def rig_examples(pairs: list[tuple[Path, Path]], axis: geo.TimeAxis, out_png: Path) -> None:
    """Plot each (object set store, NOOBJECT set store) pair, captured on
    `axis`; write PNG + CSV."""
    rows = []
    fig, axes = plt.subplots(len(pairs), 3, figsize=(13, 3.4 * len(pairs)), squeeze=False)
    for ax_row, (obj_path, bg_path) in zip(axes, pairs):
        obj_store, bg_store = open_set(obj_path), open_set(bg_path)
        cs = obj_store.capture_set
        locations = sorted(set(obj_store.locations) & set(bg_store.locations))
        if not locations:
            raise ValueError(f"{obj_path} and {bg_path} share no gantry location")
        dist = geo.wall_distance(np.array([geo.object_pose(k).t for k in locations]))
        picks = [locations[i] for i in (int(dist.argmin()), int(np.argsort(dist)[len(dist) // 2]), int(dist.argmax()))]
        for ax, k in zip(ax_row, picks):
            zone = geo.centre_zone(cs.resolution)
            obj = obj_store.histogram(obj_store.index_of(k)).mean(0)[zone]
            bg = bg_store.histogram(bg_store.index_of(k)).mean(0)[zone]
            lo, hi = bump_window(cs.resolution, cs.size, k, zone, axis)
            bins = np.arange(geo.N_BINS)
            diff = obj - bg
            smooth = np.convolve(diff, np.ones(SMOOTH_BINS) / SMOOTH_BINS, mode="same")
            ax.plot(bins, obj, lw=1, label=f"{cs.object} {cs.size}")
            ax.plot(bins, bg, lw=1, label="NOOBJECT")
            ax.axvspan(lo, hi, color="tab:green", alpha=0.15, label="predicted 3-bounce")
            twin = ax.twinx()
            twin.plot(bins, diff, color="tab:red", lw=0.5, alpha=0.35)
            twin.plot(bins, smooth, color="tab:red", lw=1.5, label=f"difference ({SMOOTH_BINS}-bin mean)")
            twin.axhline(0, color="tab:red", lw=0.5, ls=":")
            twin.set_ylabel("difference (counts)", color="tab:red")
            ax.set_title(f"{cs.resolution} {cs.light}, location {k} ({geo.wall_distance(geo.object_pose(k).t):.2f} m), zone {zone}", fontsize=9)
            ax.set_xlabel(axis.label())
            ax.set_ylabel("counts (mean of repeats)")
            if k == picks[0]:
                ax.legend(fontsize=7, loc="upper left")
                twin.legend(fontsize=7, loc="upper right")
            for b in bins:
                rows.append(
                    {
                        "set": cs.name,
                        "location": k,
                        "zone_row": zone[0],
                        "zone_col": zone[1],
                        "bin": b,
                        "object_mean": obj[b],
                        "background_mean": bg[b],
                        "difference": diff[b],
                        "difference_smoothed": smooth[b],
                        "in_predicted_window": lo <= b <= hi,
                    }
                )
    fig.tight_layout()
    save_figure(fig, out_png, pd.DataFrame(rows))
