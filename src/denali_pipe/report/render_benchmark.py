"""`results/render_benchmark.png` (+ `.csv`): the twin renderers' time per
scene against their error to the converged reference, log axes, the Pareto
front marked."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from matplotlib.ticker import FormatStrFormatter

from denali_pipe.report.figure import plt, save_figure


def plot_render_benchmark(summary: pd.DataFrame, out_png: Path) -> None:
    """Scatter of `twin.benchmark.summarise` rows; writes the PNG and the
    summary as CSV beside it (same stem)."""
    fig, ax = plt.subplots(figsize=(7.5, 5))
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
    ax.set_title(f"Twin renderers: cost vs fidelity ({n} scenes; reference: footprint, {ref:,} spp)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, out_png, summary)
