"""The twin's calibration figure (`results/twin_calibration.png`): real
against twin, zone by zone, before and after calibration.

One panel per zone of the 3x3 grid in the captures' order (row 0 at the
top, column 0 at the sensor's right), for the held-out capture with the
most signal: its background-subtracted repeat mean (counts), the design
twin (footprints as designed, no time offset; its zone gains and pulse
fitted) and the calibrated
twin, both times their gains, mixed by the fitted glare and through the
fitted pulse, on the real
bins. Each title gives the zone's held-out residual (||real - twin|| /
||real|| over every held-out capture) before and after, what the noise
alone leaves, and the calibrated twin's own residual with the noise's
share taken out (`calibrate.nl2_net_of_noise`, with its bootstrap interval). The CSV beside it
holds the plotted curves: zone_row, zone_col, bin, real, before, after.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.twin.calibrate import GRID, Problem, Result


def plot_calibration(result: Result, held: Problem, out_png: Path) -> None:
    i = int(np.argmax(held.y.sum(axis=(1, 2))))
    before = held.expected(result.x_before, result.gains_before)[i]
    after = held.expected(result.x, result.gains)[i]
    bins = held.crop + np.arange(held.T)
    fig, axes = plt.subplots(GRID, GRID, figsize=(11, 7.5), sharex=True, constrained_layout=True, squeeze=False)
    rows = []
    for z, ax in enumerate(axes.ravel()):
        r, c = divmod(z, GRID)
        ax.plot(bins, held.y[i, z], color="0.3", lw=0.8, label="real (bg-subtracted, its floor offset out, repeat mean)")
        ax.plot(bins, before[z], color="tab:orange", lw=1.2, ls="--", label="twin before calibration")
        ax.plot(bins, after[z], color="tab:blue", lw=1.4, label="twin after calibration")
        ax.axhline(0, color="k", lw=0.5)
        nb, na, nn = result.before["nl2"][r][c], result.after["nl2"][r][c], result.after["nl2_noise"][r][c]
        net, interval = result.after["nl2_net"], result.after["nl2_net_interval"]
        # none without repeats, nor where a zone's noise holds all of its captures
        twin_own = "" if net is None or net[r][c] is None else f"\ntwin's own, net of noise: {net[r][c]:.2f} [{interval[r][c][0]:.2f}, {interval[r][c][1]:.2f}]"
        ax.set_title(f"zone ({r}, {c}): held-out residual {nb:.2f} -> {na:.2f} (noise alone {nn:.2f}){twin_own}", fontsize=8)
        ax.tick_params(labelsize=7)
        if c == 0:
            ax.set_ylabel("counts", fontsize=8)
        if r == GRID - 1:
            ax.set_xlabel("time bin (config sensor.time_axis)", fontsize=8)
        rows.append(pd.DataFrame({"zone_row": r, "zone_col": c, "bin": bins, "real": held.y[i, z], "before": before[z], "after": after[z]}))
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=8, frameon=False)
    fig.suptitle(
        "Twin against a held-out real capture, per zone (residual: ||real - twin|| / ||real|| over the held-out captures;"
        " noise alone: what a twin exact to the photon would leave;\ntwin's own: ||expected real - twin|| / ||expected real||, estimated by taking"
        " the repeats' noise out of both norms)",
        fontsize=9,
    )
    save_figure(fig, out_png, pd.concat(rows, ignore_index=True))
