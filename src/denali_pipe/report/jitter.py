"""The timing-jitter sweep's figure: each task's metrics against the jitter's
FWHM (ps), mean +- std over seeds, the trivial predictor dashed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.core.geometry import TimeAxis

TASK_TITLES = {"location": "location (lower is better)", "shape": "shape (higher is better)", "size": "size (higher is better)"}
Y_LABELS = {"location": "test error (m)", "shape": "test score", "size": "test score"}
COLOURS = ("tab:blue", "tab:orange", "tab:green")


def plot_jitter(curve: pd.DataFrame, title: str, axis: TimeAxis, png: Path) -> None:
    """`experiments.jitter.jitter_curve`'s table as one panel per task, FWHM
    also in bins of `axis` (the captures' time axis); the table goes beside
    the PNG as CSV."""
    tasks = [t for t in TASK_TITLES if t in set(curve["task"])]
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 4.3), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        sub = curve[curve["task"] == task]
        for colour, (metric, m) in zip(COLOURS, sub.groupby("metric", sort=False)):
            label = metric.split("_", 1)[1]
            ax.errorbar(m["fwhm_ps"], m["mean"], yerr=m["std"], marker="o", ms=4, capsize=3, color=colour, label=label)
            ax.axhline(m["trivial"].mean(), color=colour, ls="--", lw=1)
        original = sub[sub["fwhm_ps"] == 0]
        ax.plot(original["fwhm_ps"], original["mean"], "k*", ms=10, zorder=5, label="unjittered" if len(original) else None)
        ax.set_title(TASK_TITLES[task], fontsize=9)
        ax.set_xlabel("timing jitter FWHM (ps)")
        ax.set_ylabel(Y_LABELS[task])
        if task != "location":
            ax.set_ylim(0, 1)  # scores: their whole range
        top = ax.secondary_xaxis("top", functions=(lambda ps: ps / axis.bin_width_ps, lambda b: b * axis.bin_width_ps))
        top.set_xlabel(f"FWHM (bins of {axis.bin_width_ps:.0f} ps)", fontsize=8)
        ax.grid(alpha=0.3)
        # below the panel, where no curve runs
        ax.legend(fontsize=7, title="dashed: trivial predictor", title_fontsize=7, ncol=2, loc="upper center", bbox_to_anchor=(0.5, -0.3))
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, png, curve)
