"""results/sensor_vs_real.png and .csv: the fitted sensor on real scenes it
was not fitted to (experiments.sensor_vs_real).

One row of panels per rendered scene: left, one capture (the one of median
residual) in three zones, measured beside the render and beside the fit
with each zone's returns free in size; right, every zone's normalised L2
net of shot noise in both modes, against the sweep's criterion. The CSV
holds every scene's rows, and a row per scene not rendered saying why.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.sensor.captures import ZONES, Captures
from denali_pipe.sensor.fit import CRITERIA, scores

# Zones drawn for the example capture: a corner, the centre and the column on the other side.
SHOWN = (0, 4, 7)


def example_capture(captures: Captures, expected: np.ndarray) -> int:
    """The capture whose normalised L2 over its zones is the median of the scene's."""
    per_capture = np.array([np.median(scores(h[None], e[None])["nl2_net"]) for h, e in zip(captures.hists, expected)])
    return int(np.argsort(per_capture)[len(per_capture) // 2])


def write_sensor_vs_real(rendered: list[tuple[Captures, dict]], table: pd.DataFrame, png: Path) -> None:
    """The figure (module docstring) and its CSV; rendered: each scene's
    captures and each mode's expected counts (N, ZONES, BINS)."""
    fig, ax = plt.subplots(len(rendered), 2, figsize=(12, 3.8 * len(rendered)), squeeze=False)
    for row, (captures, expected) in zip(ax, rendered):
        i = example_capture(captures, expected["render"])
        a = row[0]
        for colour, z in zip(("C0", "C2", "C3"), SHOWN):
            a.semilogy(captures.hists[i, z], ".", color=colour, ms=3, label=f"zone {z}, measured")
            a.semilogy(expected["render"][i, z], "-", color=colour, lw=1)
            a.semilogy(expected["free"][i, z], ":", color=colour, lw=1)
        a.plot([], [], "k-", lw=1, label="render (albedos fitted)")
        a.plot([], [], "k:", lw=1, label="returns free in size")
        a.set(xlabel="bin", ylabel="counts", ylim=(10, None), title=f"{captures.name}: capture {i} of {len(captures.hists)} (median residual)")
        a.legend(fontsize=7, ncol=2)
        a = row[1]
        x = np.arange(ZONES)
        part = table[table["scene"] == captures.name]
        for j, mode in enumerate(("render", "free")):
            a.bar(x + (j - 0.5) * 0.4, part[part["mode"] == mode]["nl2_net"], 0.4, color=f"C{j}", label=mode)
        a.axhline(CRITERIA["nl2_net"], color="k", ls="--", lw=1, label=f"the sweep's held-out criterion ({CRITERIA['nl2_net']:g})")
        a.set(xlabel="zone", xticks=x, ylabel="normalised L2 net of shot noise", title=f"{captures.name}: every zone over {len(captures.hists)} captures")
        a.set_ylim(0, 1.35 * max(part["nl2_net"].max(), CRITERIA["nl2_net"]))
        a.legend(fontsize=8, ncol=3, loc="upper center")
    fig.suptitle("The sensor fitted to the distance sweep, on real scenes it never saw (direct view, one bounce)", fontsize=11)
    fig.tight_layout()
    save_figure(fig, png, table, float_format="%.4f")


def write_absent(reason: str, table: pd.DataFrame, png: Path) -> None:
    """The figure where no scene was rendered: it says why; the CSV lists the scenes found."""
    fig, ax = plt.subplots(figsize=(6, 2))
    ax.axis("off")
    ax.text(0.5, 0.5, reason, ha="center", va="center", wrap=True)
    save_figure(fig, png, table)
