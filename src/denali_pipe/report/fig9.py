"""Fig 9: localisation RMSE on real test captures against the number of real
training samples, one curve per simulation fidelity, mean +- std over seeds.

`results/fig9.csv` (one row per fidelity and n_real: rmse, mse, mae,
rmse_euclidean, each a mean over seeds with a matching `_std`, n_seeds,
n_sim, n_test) beside `results/fig9.png`.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

from denali_pipe.atomic import atomic_file  # noqa: E402
from denali_pipe.transforms import FIDELITIES  # noqa: E402

METRICS = ("rmse", "mse", "mae", "rmse_euclidean")
LABELS = {"raw": "raw simulation", "scaled": "scaled", "blurred": "scaled + blurred", "noisy": "scaled + blurred + noisy"}


def aggregate(runs: pd.DataFrame) -> pd.DataFrame:
    """Mean and std (ddof 1; 0 for one seed) over seeds per (fidelity, n_real), fidelities in FIDELITIES order."""
    g = runs.groupby(["fidelity", "n_real"], sort=False)
    table = g[list(METRICS)].mean()
    std = g[list(METRICS)].std().fillna(0.0).add_suffix("_std")
    extra = g.agg(n_seeds=("seed", "nunique"), n_sim=("n_sim", "first"), n_test=("n_test", "first"))
    out = pd.concat([table, std, extra], axis=1).reset_index()
    cols = ["fidelity", "n_real", *[c for m in METRICS for c in (m, f"{m}_std")], "n_seeds", "n_sim", "n_test"]
    out["order"] = out["fidelity"].map(FIDELITIES.index)
    return out.sort_values(["order", "n_real"])[cols].reset_index(drop=True)


def write_fig9(runs: pd.DataFrame, out_png: Path, out_csv: Path) -> pd.DataFrame:
    """Aggregate the per-seed runs (`fig9.run_fig9`), write the CSV and the PNG; returns the table."""
    table = aggregate(runs)
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    for fidelity in FIDELITIES:
        s = table[table["fidelity"] == fidelity]
        ax.errorbar(s["n_real"], s["rmse"], yerr=s["rmse_std"], marker="o", ms=4, capsize=3, label=LABELS[fidelity])
    ax.set_xlabel("real samples added to the simulated training set")
    ax.set_ylabel("test RMSE on real captures (m)")
    ax.set_yscale("log")  # a model that never saw real-looking inputs misses by orders of magnitude
    ax.set_title(f"Sim-to-real localisation (1D CNN, centre pixel, {int(table['n_seeds'].min())} seeds)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    with atomic_file(Path(out_csv)) as tmp:
        table.to_csv(tmp, index=False)
    with atomic_file(Path(out_png)) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)
    return table
