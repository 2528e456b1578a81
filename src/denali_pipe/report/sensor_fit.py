"""results/sensor_fit.png: the sensor fitted to the real distance sweep.

Four panels: the measured pulse (log scale) with the late share it holds;
two held-out captures, near and far, measured beside expected, centre
zone; every zone's held-out scores against the criteria (normalised L2 net
of shot noise, the tail's and the late floor's errors); each zone's bins
per metre of plane distance with its standard error. The CSV beside it
holds the held-out scores.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.sensor.captures import ZONES, Captures
from denali_pipe.sensor.fit import CENTRE, CRITERIA, LATE, TAIL, SensorFit, bin_width_ps
from denali_pipe.sensor.response import pulse_offsets, tail_summary


def write_sensor_fit(fit: SensorFit, held: pd.DataFrame, examples: Captures, expected: np.ndarray, png: Path) -> None:
    """The figure (module docstring) and its CSV; examples: two held-out
    captures (near, far) and their expected counts (2, ZONES, BINS)."""
    fig, ax = plt.subplots(2, 2, figsize=(11, 7.5))
    u, tail = pulse_offsets(), tail_summary(fit.pulse)
    a = ax[0, 0]
    a.semilogy(u, fit.pulse / fit.pulse.max(), color="k")
    a.axvspan(tail["peak_offset_bins"] + 5, u[-1], color="C1", alpha=0.15, label=f"from 5 bins on: {tail['share_from_5_bins']:.1%} of the area")
    a.set(xlabel="bins from the return", ylabel="bin-integrated pulse / peak", ylim=(1e-4, 1.5), xlim=(-4, 40),
          title=f"pulse (tail time constant {tail['time_constant_bins']:.2f} bins)")  # fmt: skip
    a.legend(fontsize=8)
    a = ax[0, 1]
    for i, (colour, h, e) in enumerate(zip(("C0", "C3"), examples.hists, expected)):
        d = examples.distance_m[i]
        a.semilogy(h[CENTRE], ".", color=colour, ms=3, label=f"measured, {d:.3f} m")
        a.semilogy(e[CENTRE], "-", color=colour, lw=1, label="expected")
    a.set(xlabel="bin", ylabel="counts", title="held-out captures, centre zone", ylim=(10, None))
    a.legend(fontsize=8)
    a = ax[1, 0]
    x = np.arange(ZONES)
    for j, (name, limit) in enumerate(CRITERIA.items()):
        values = held[name].abs() if name != "nl2_net" else held[name]
        a.bar(x + (j - 1) * 0.27, values, 0.27, color=f"C{j}", label=f"{name.replace('_', ' ')} (limit {limit:g})")
        a.hlines(limit, -0.5, ZONES - 0.5, colors=f"C{j}", linestyles="--", lw=1)
    a.set(xlabel="zone", ylabel="held-out score", xticks=x,
          title=f"{int(held['n_captures'].iloc[0])} held-out distances: tail = bins {TAIL[0]}-{TAIL[1]}, late = {LATE[0]}-{LATE[1]} after the peak")  # fmt: skip
    a.title.set_fontsize(9)
    a.legend(fontsize=8)
    a = ax[1, 1]
    a.errorbar(x, fit.timing.bins_per_metre, yerr=fit.se["bins_per_metre"], fmt="o", color="k")
    ps = bin_width_ps(fit.timing.bins_per_metre[CENTRE])
    a.axhline(fit.timing.bins_per_metre[CENTRE], color="0.6", lw=1, label=f"centre zone: {ps:.1f} ps a bin")
    a.set(xlabel="zone", ylabel="bins per metre of plane distance", xticks=x, title=f"timing (zero distance at bin {fit.timing.zero_bin:.2f})")
    a.legend(fontsize=8)
    fig.suptitle(f"TMF8820 sensor fitted to {len(fit.train_distances)} real captures; N = {fit.cycles / 1e6:.2f} M cycles (pile-up)", fontsize=11)
    fig.tight_layout()
    save_figure(fig, png, held, float_format="%.4f")


def write_absent(source: Path, png: Path) -> None:
    """The figure where no real captures were found: it says so."""
    fig, ax = plt.subplots(figsize=(6, 2))
    ax.axis("off")
    ax.text(0.5, 0.5, f"no real captures at {source}:\nthe sensor was not fitted (config sensor.real_dir)", ha="center", va="center")
    save_figure(fig, png, pd.DataFrame({"status": ["no real captures"], "source": [str(source)]}))
