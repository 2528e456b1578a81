"""`results/render_benchmark.png` (+ `.csv`): the twin renderers' time per
scene (every zone of the 3x3 grid) against their error to the converged
reference, log axes, the Pareto front marked; beside it, the analytic
model's error per zone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.ticker import FormatStrFormatter

from denali_pipe.core.figure import plt, save_figure


def plot_render_benchmark(summary: pd.DataFrame, out_png: Path) -> None:
    """Scatter of `twin.benchmark.summarise` rows; writes the PNG and the
    summary as CSV beside it (same stem)."""
    fig, (ax, zax) = plt.subplots(1, 2, figsize=(11, 5), gridspec_kw={"width_ratios": [2.2, 1]})
    colours = {"paper": "tab:red", "paper, footprint pixels": "tab:orange", "analytic": "tab:green"}
    for r in summary.itertuples():
        c = colours.get(r.configuration, "tab:blue")
        ax.scatter(r.time_per_scene_s, 100 * r.error_nl2, s=60, color=c, edgecolor="k" if r.pareto else "none", zorder=3)
        spp = "" if pd.isna(r.spp) else f", {int(r.spp):,} spp"
        ax.annotate(f"{r.configuration} ({r.pixels} px{spp})\n{r.speedup_vs_paper:,.0f}x paper's speed",
                    (r.time_per_scene_s, 100 * r.error_nl2), textcoords="offset points", xytext=(6, 4), fontsize=7)  # fmt: skip
    front = summary[summary.pareto].sort_values("time_per_scene_s")
    ax.step(front.time_per_scene_s, 100 * front.error_nl2, where="post", color="k", lw=1, ls="--", label="Pareto front", zorder=2)
    ax.set_xscale("log")
    ax.set_yscale("log")
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_formatter(FormatStrFormatter("%g"))
    ax.set_xlabel("time per scene (s, median)")
    ax.set_ylabel("normalised L2 error vs reference (%)")
    n, ref = int(summary.n_scenes.iloc[0]), int(summary.reference_spp.iloc[0])
    ax.set_title(f"Twin renderers: cost vs fidelity ({n} scenes x 3x3 zones; reference: footprints, {ref:,} spp)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    analytic = summary[summary.configuration == "analytic"]
    if len(analytic):
        grid = np.array([[analytic[f"error_zone_{r}{c}"].item() for c in range(3)] for r in range(3)]) * 100
        im = zax.imshow(grid, cmap="viridis", vmin=0)
        for (r, c), e in np.ndenumerate(grid):
            zax.text(c, r, f"{e:.2f} %", ha="center", va="center", color="w" if e < grid.max() / 2 else "k", fontsize=9)
        fig.colorbar(im, ax=zax, shrink=0.7, label="normalised L2 error (%)")
        zax.set_xticks(range(3), [f"col {c}" for c in range(3)])
        zax.set_yticks(range(3), [f"row {r}" for r in range(3)])
        zax.set_title("analytic vs reference, per zone\n(captures' order: col 0 at the sensor's right)", fontsize=9)
    else:
        zax.axis("off")
    fig.tight_layout()
    save_figure(fig, out_png, summary)
