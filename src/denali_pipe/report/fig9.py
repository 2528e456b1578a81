"""Fig 9: localisation RMSE on real test captures against the number of real
training samples, one panel per view of the captures (the paper's centre
zone; all 9 zones), one curve per simulation fidelity and one for the
real-only control, mean +- std over seeds, and the predict-the-mean
baseline as a dashed horizontal line.

`results/fig9.csv` (one row per panel, fidelity and n_real, then the
control's rows and one for `experiments.fig9.MEAN_BASELINE` at n_real 0 per
panel: `experiments.fig9.CAPPED`, the counts asked for that n_real stands in
for where the training captures hold fewer real samples (the figure's ticks
and titles say so too); rmse, mse, mae, rmse_euclidean, each a mean over seeds with a
matching `_std`, n_seeds, n_sim, n_test; for the fidelities,
control_n_same_rmse, the real samples the control needs to reach the same
RMSE (interpolated linearly between its n; "<=" its fewest n where it is
there already, so the need is at most that; ">max" where it never gets
there: `samples_for`), real_samples_saved, that less n_real (negative:
the twins cost real samples), and real_samples_saved_std, its spread over
seeds, each seed against its own control (`saved_spread`)) beside
`results/fig9.png`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.experiments.fig9 import CAPPED, CONTROL, MEAN_BASELINE, PANELS
from denali_pipe.transforms.sim_to_real import FIDELITIES

METRICS = ("rmse", "mse", "mae", "rmse_euclidean")
LABELS = {
    "raw": "raw simulation",
    "scaled": "scaled",
    "blurred": "scaled + blurred",
    "noisy": "scaled + blurred + noisy",
    CONTROL: "control: real samples only",
    MEAN_BASELINE: "predict the training mean",
}
TITLES = {"centre": "centre zone (the paper's)", "all_zones": "all 9 zones"}
ROWS = (*FIDELITIES, CONTROL, MEAN_BASELINE)  # the table's order of `fidelity`
NEVER = ">max"  # the control never reaches the RMSE within the n it was run at
AT_MOST = "<="  # the control reaches it with its fewest n already: it needs at most that


def aggregate(runs: pd.DataFrame) -> pd.DataFrame:
    """Mean and std (ddof 1; 0 for one seed) over seeds per (panel, fidelity, n_real), in PANELS then ROWS order."""
    g = runs.groupby(["panel", "fidelity", "n_real"], sort=False)
    table = g[list(METRICS)].mean()
    std = g[list(METRICS)].std().fillna(0.0).add_suffix("_std")
    extra = g.agg(**{CAPPED: (CAPPED, "first")}, n_seeds=("seed", "nunique"), n_sim=("n_sim", "first"), n_test=("n_test", "first"))
    out = pd.concat([table, std, extra], axis=1).reset_index()
    cols = ["panel", "fidelity", "n_real", CAPPED, *[c for m in METRICS for c in (m, f"{m}_std")], "n_seeds", "n_sim", "n_test"]
    out["order"] = out["panel"].map(list(PANELS).index) * len(ROWS) + out["fidelity"].map(ROWS.index)
    return out.sort_values(["order", "n_real"])[cols].reset_index(drop=True)


def samples_for(rmse: float, control_n: np.ndarray, control_rmse: np.ndarray) -> float:
    """The real samples the control needs to reach `rmse`: the first n along
    its curve (control_n ascending) where it gets there, interpolated
    linearly between the two n around that crossing; its fewest n when it
    is already there; inf when it never is."""
    if control_rmse[0] <= rmse:
        return float(control_n[0])
    for i in range(1, len(control_n)):
        if control_rmse[i] <= rmse:
            f = (control_rmse[i - 1] - rmse) / (control_rmse[i - 1] - control_rmse[i])
            return float(control_n[i - 1] + f * (control_n[i] - control_n[i - 1]))
    return float("inf")


def _saved(rmse: float, n_real: int, control: pd.DataFrame) -> tuple[float, bool]:
    """The real samples a model of `rmse` at `n_real` saves against a control
    curve (rows n_real, rmse): (samples_for(...) - n_real, whether that is a
    bound: the control is there with its fewest n already, so it needs at
    most those). inf where the control never gets there."""
    c = control.sort_values("n_real")
    n = samples_for(rmse, c["n_real"].to_numpy(float), c["rmse"].to_numpy(float))
    return n - n_real, bool(c["rmse"].iloc[0] <= rmse)


def real_samples_saved(table: pd.DataFrame) -> pd.DataFrame:
    """`table` with control_n_same_rmse and real_samples_saved filled for the
    fidelities' rows (strings: a number of samples, or NEVER)."""
    table = table.copy()
    table["control_n_same_rmse"] = ""
    table["real_samples_saved"] = ""
    for _, g in table.groupby("panel", sort=False):
        control = g[g["fidelity"] == CONTROL]
        if control.empty:
            continue
        for i in g.index[g["fidelity"].isin(FIDELITIES)]:
            saved, bounded = _saved(table.at[i, "rmse"], table.at[i, "n_real"], control)
            bound = AT_MOST if bounded else ""
            table.at[i, "control_n_same_rmse"] = NEVER if np.isinf(saved) else f"{bound}{saved + table.at[i, 'n_real']:.0f}"
            table.at[i, "real_samples_saved"] = NEVER if np.isinf(saved) else f"{bound}{saved:.0f}"
    return table


def saved_spread(runs: pd.DataFrame, table: pd.DataFrame) -> pd.DataFrame:
    """`table` with real_samples_saved_std filled for the fidelities' rows:
    the std over seeds (ddof 1) of the real samples saved, each seed's
    model against that seed's own control curve (the same real samples and
    initial weights). A string; "" where fewer than two seeds ran or a
    seed's control gives a bound, not a number (it never gets there, or it
    is there with its fewest n)."""
    table = table.copy()
    table["real_samples_saved_std"] = ""
    controls = dict(tuple(runs[runs["fidelity"] == CONTROL].groupby(["panel", "seed"])))
    models = runs.groupby(["panel", "fidelity", "n_real"])
    for i in table.index[table["fidelity"].isin(FIDELITIES)]:
        panel, fidelity, n_real = table.loc[i, ["panel", "fidelity", "n_real"]]
        seeds = models.get_group((panel, fidelity, n_real))
        saved = [
            _saved(rmse, n_real, controls[(panel, seed)]) if (panel, seed) in controls else (np.inf, False) for seed, rmse in zip(seeds["seed"], seeds["rmse"])
        ]
        if len(saved) > 1 and not any(np.isinf(n) or bounded for n, bounded in saved):
            table.at[i, "real_samples_saved_std"] = f"{np.std([n for n, _ in saved], ddof=1):.0f}"
    return table


def write_fig9(runs: pd.DataFrame, out_png: Path, out_csv: Path) -> pd.DataFrame:
    """Aggregate the per-seed runs (`experiments.fig9.run_fig9`), write the CSV and the PNG; returns the table."""
    table = saved_spread(runs, real_samples_saved(aggregate(runs)))
    panels = [p for p in PANELS if p in set(table["panel"])]
    # constrained layout makes room for the legend below the panels, clear of the curves
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.2), constrained_layout=True, sharey=True, squeeze=False)
    top = table["rmse"].max() + table["rmse_std"].max()
    for ax, panel in zip(axes[0], panels):
        t = table[table["panel"] == panel]
        for fidelity in FIDELITIES:
            s = t[t["fidelity"] == fidelity]
            ax.errorbar(s["n_real"], s["rmse"], yerr=s["rmse_std"], marker="o", ms=4, capsize=3, label=LABELS[fidelity])
        c = t[t["fidelity"] == CONTROL]
        ax.errorbar(c["n_real"], c["rmse"], yerr=c["rmse_std"], marker="s", ms=4, capsize=3, color="k", lw=1.8, label=LABELS[CONTROL])
        # the baseline uses no histogram, so it is one level for every n_real
        ax.axhline(t.loc[t["fidelity"] == MEAN_BASELINE, "rmse"].item(), color="k", lw=1, ls="--", label=LABELS[MEAN_BASELINE])
        ticks = t.drop_duplicates("n_real").sort_values("n_real")
        ax.set_xticks(ticks["n_real"], [f"{n}\n(asked {c.replace(' ', ', ')})" if c else f"{n}" for n, c in zip(ticks["n_real"], ticks[CAPPED])])
        ax.set_xlabel("real training samples (added to the twins; the control's only ones)")
        # predictions are bounded to the workspace, so every RMSE is of its size: linear from 0 reads best
        ax.set_ylim(0, top * 1.05)
        ax.ticklabel_format(axis="y", style="plain", useOffset=False)
        capped = sorted({int(a) for c in t[CAPPED] for a in c.split()})
        note = f"\nreal samples capped at the training captures' {int(t['n_real'].max())}: asked {capped}" if capped else ""
        ax.set_title(f"{TITLES[panel]}: 1D CNN, {int(t['n_seeds'].min())} seeds, test locations held out{note}", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("test RMSE on real captures (m)")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=7, loc="outside lower center", ncols=3, frameon=False)
    save_figure(fig, out_png, table, out_csv)
    return table
