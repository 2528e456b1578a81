"""Figs 16 and 17: 1D CNN training curves (location regression, shape
classification) on the random split, mean over seeds with a +-1 std band.

Under the `clean` protocol the curves are train and validation, and the test
split appears once, as a marker at each seed's selected epoch; under `paper`
they are train and test, as in the paper."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.figure import plt, save_figure

PANELS = {"location": ("mse", "mae"), "shape": ("top1", "top5", "f1", "precision", "recall")}
LABELS = {"mse": "MSE (m$^2$)", "mae": "MAE (m)", "top1": "Top-1", "top5": "Top-5", "f1": "macro F1", "precision": "macro precision", "recall": "macro recall"}
COLOURS = {"train": "tab:blue", "validation": "tab:orange", "test": "tab:red"}


def load_curves(paths: list[Path]) -> pd.DataFrame:
    """Concatenate curves.csv files with a `seed` column (the run folder order)."""
    frames = []
    for seed, p in enumerate(paths):
        c = pd.read_csv(p)
        missing = {"epoch", "part", "metric", "value"} - set(c.columns)
        if missing:
            raise ValueError(f"{p}: curves lack the columns {sorted(missing)}")
        frames.append(c.assign(seed=seed))
    return pd.concat(frames, ignore_index=True)


def write_training_curves(paths: list[Path], task: str, title: str, out: Path) -> None:
    """Plot `task`'s curves from several seeds' curves.csv; data beside as CSV."""
    curves = load_curves(paths)
    metrics = PANELS[task]
    summary = curves.groupby(["part", "metric", "epoch"])["value"].agg(["mean", "std", "count"]).reset_index()
    fig, axes = plt.subplots(1, len(metrics), figsize=(3.2 * len(metrics), 3.0), squeeze=False)
    for ax, metric in zip(axes[0], metrics):
        for part in ("train", "validation", "test"):
            s = summary[(summary["part"] == part) & (summary["metric"] == metric)]
            if s.empty:
                continue
            if s["epoch"].nunique() < curves[curves["part"] == "train"]["epoch"].nunique():  # test: once per seed
                pts = curves[(curves["part"] == part) & (curves["metric"] == metric)]
                ax.plot(pts["epoch"], pts["value"], "*", color=COLOURS[part], ms=9, label=f"{part} (selected epoch)")
                continue
            ax.plot(s["epoch"], s["mean"], color=COLOURS[part], label=part)
            ax.fill_between(s["epoch"], s["mean"] - s["std"].fillna(0), s["mean"] + s["std"].fillna(0), color=COLOURS[part], alpha=0.2)
        ax.set_xlabel("epoch")
        ax.set_ylabel(LABELS[metric])
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, out, summary)
