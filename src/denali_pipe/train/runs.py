"""Training cells' results as tables: one row per cell, and mean/std over seeds."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import pandas as pd

from denali_pipe.train.cell_metrics import CellMetrics

# Table metric name -> (task, metric key in metrics.json); the paper's columns.
METRICS = {
    "loc_rmse": ("location", "rmse"),
    "loc_mae": ("location", "mae"),
    "shape_top1": ("shape", "top1"),
    "shape_top5": ("shape", "top5"),
    "shape_f1": ("shape", "f1"),
    "size_precision": ("size", "precision"),
    "size_recall": ("size", "recall"),
    "size_accuracy": ("size", "top1"),
}
# Beside the paper's metrics, which has none of them: the share of a location
# cell's test predictions outside the gantry's workspace (metrics.workspace_metrics).
EXTRA_METRICS = {"loc_outside_workspace": ("location", "outside_workspace")}
# The one metric per task that charts use, and whether higher is better.
HEADLINE = {"location": ("rmse", False), "shape": ("top1", True), "size": ("top1", True)}
NA = "n/a"


def load_runs(paths: list[Path]) -> pd.DataFrame:
    """One row per metrics.json (`CellMetrics`): the cell's fields, seed,
    sizes, timings, `test_<metric>` and `baseline_<metric>` columns."""
    rows = []
    for p in paths:
        m = CellMetrics.read(p)
        rows.append(
            {
                **asdict(m.cell),
                "params": m.params,
                "flops": m.flops,
                "n_train": m.n_train,
                "n_validation": m.n_validation,
                "n_test": m.n_test,
                "best_epoch": m.best_epoch,
                "epochs": m.hyper.get("epochs"),
                "epochs_run": m.epochs_run,
                "stopped_by_budget": m.stopped_by_budget,
                "batch_size": m.hyper.get("batch_size"),
                "selected_on": m.selected_on,
                "train_seconds": m.train_seconds,
                "inference_seconds": m.inference_seconds,
                "train_samples_per_second": m.train_samples_per_second,
                "device": m.device,
                "precision": m.precision,
                **{f"test_{k}": v for k, v in m.test.items()},
                **{f"baseline_{k}": v for k, v in m.baseline.items()},
            }
        )
    if not rows:
        raise ValueError("no training cells given")
    return pd.DataFrame(rows)


def seed_stats(runs: pd.DataFrame, by: list[str], columns: list[str]) -> pd.DataFrame:
    """Mean and std (ddof=1; 0 for a single seed) of `columns` over seeds,
    per group of `by`; also n_seeds."""
    g = runs.groupby(by, sort=False)
    mean = g[columns].mean()
    std = g[columns].std(ddof=1).fillna(0.0).add_suffix("_std")
    out = pd.concat([mean, std, g.size().rename("n_seeds")], axis=1).reset_index()
    return out


def metric_table(runs: pd.DataFrame, key: str, keys: list[str], paper: dict) -> pd.DataFrame:
    """Rows = values of `key` (e.g. split or model) in order `keys`, columns =
    the paper's metrics, each with _std and the paper's value beside it, then
    `EXTRA_METRICS` with _std; cells never trained (ill-posed, or not run) read n/a."""
    table = pd.DataFrame({key: keys})
    for name, (task, metric) in {**METRICS, **EXTRA_METRICS}.items():
        sub = runs[runs["task"] == task]
        col = f"test_{metric}"
        stats = seed_stats(sub, [key], [col]).set_index(key) if len(sub) and col in sub else pd.DataFrame()
        table[name] = [_rounded(stats, k, col) for k in keys]
        table[f"{name}_std"] = [_rounded(stats, k, f"{col}_std") for k in keys]
        if name in METRICS:
            table[f"paper_{name}"] = [_paper_value(paper, k, name) for k in keys]
    seeds = runs.groupby(key)["seed"].nunique()
    table["n_seeds"] = [int(seeds.get(k, 0)) for k in keys]
    return table


def _rounded(stats: pd.DataFrame, key, column: str):
    """stats[column] at row `key` to 4 decimals; n/a for a row never trained,
    or whose cells predate the metric."""
    if key not in stats.index or pd.isna(stats.loc[key, column]):
        return NA
    return round(float(stats.loc[key, column]), 4)


def _paper_value(paper: dict, key: str, name: str):
    row = paper.get(key)
    if row is None:
        return ""  # not published
    v = row.get(name)
    return NA if v is None else v


def left_out_note(reason: str) -> str:
    """What a table prints in the row of a model the preset does not train."""
    return f"not trained on this preset: {reason}"


def protocol_of(runs: pd.DataFrame) -> str:
    protocols = sorted(runs["protocol"].unique())
    if len(protocols) != 1:
        raise ValueError(f"a table shows one protocol; the cells mix {protocols}")
    return protocols[0]
