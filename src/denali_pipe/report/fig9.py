"""Fig 9: localisation RMSE on real test captures against the number of real
training samples, one curve per simulation fidelity, mean +- std over seeds,
and the predict-the-mean baseline as a dashed horizontal line.

`results/fig9.csv` (one row per fidelity and n_real, then one for
`experiments.fig9.MEAN_BASELINE` at n_real 0: rmse, mse, mae, rmse_euclidean, each a mean
over seeds with a matching `_std`, n_seeds, n_sim, n_test) beside
`results/fig9.png`.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.experiments.fig9 import MEAN_BASELINE
from denali_pipe.report.figure import plt, save_figure
from denali_pipe.transforms import FIDELITIES

METRICS = ("rmse", "mse", "mae", "rmse_euclidean")
LABELS = {
    "raw": "raw simulation",
    "scaled": "scaled",
    "blurred": "scaled + blurred",
    "noisy": "scaled + blurred + noisy",
    MEAN_BASELINE: "predict the training mean",
}
ROWS = (*FIDELITIES, MEAN_BASELINE)  # the table's order of `fidelity`


def aggregate(runs: pd.DataFrame) -> pd.DataFrame:
    """Mean and std (ddof 1; 0 for one seed) over seeds per (fidelity, n_real), fidelities in ROWS order."""
    g = runs.groupby(["fidelity", "n_real"], sort=False)
    table = g[list(METRICS)].mean()
    std = g[list(METRICS)].std().fillna(0.0).add_suffix("_std")
    extra = g.agg(n_seeds=("seed", "nunique"), n_sim=("n_sim", "first"), n_test=("n_test", "first"))
    out = pd.concat([table, std, extra], axis=1).reset_index()
    cols = ["fidelity", "n_real", *[c for m in METRICS for c in (m, f"{m}_std")], "n_seeds", "n_sim", "n_test"]
    out["order"] = out["fidelity"].map(ROWS.index)
    return out.sort_values(["order", "n_real"])[cols].reset_index(drop=True)


def write_fig9(runs: pd.DataFrame, out_png: Path, out_csv: Path) -> pd.DataFrame:
    """Aggregate the per-seed runs (`experiments.fig9.run_fig9`), write the CSV and the PNG; returns the table."""
    table = aggregate(runs)
    # constrained layout makes room for the legend outside the axes, clear of the curves
    fig, ax = plt.subplots(figsize=(7.2, 3.6), constrained_layout=True)
    for fidelity in FIDELITIES:
        s = table[table["fidelity"] == fidelity]
        ax.errorbar(s["n_real"], s["rmse"], yerr=s["rmse_std"], marker="o", ms=4, capsize=3, label=LABELS[fidelity])
    # the baseline uses no histogram, so it is one level for every n_real
    ax.axhline(table.loc[table["fidelity"] == MEAN_BASELINE, "rmse"].item(), color="k", lw=1, ls="--", label=LABELS[MEAN_BASELINE])
    ax.set_xticks(sorted(set(table["n_real"])))
    ax.set_xlabel("real samples added to the simulated training set")
    ax.set_ylabel("test RMSE on real captures (m)")
    # predictions are bounded to the workspace, so every RMSE is of its size: linear from 0 reads best
    ax.set_ylim(bottom=0)
    ax.ticklabel_format(axis="y", style="plain", useOffset=False)
    ax.set_title(f"Sim-to-real localisation (1D CNN, centre pixel, {int(table['n_seeds'].min())} seeds)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    save_figure(fig, out_png, table, out_csv)
    return table
