"""Where the run's methods fail (`results/stability.csv` and `.png`): one row
per failure mode over every training cell, the sim-to-real fit and the twin's
calibration of the run, read from what each already wrote (the cells'
metrics.json, transforms.json, twin_calibration.json), never recomputed.

Each row gives how many cases failed (`count`) of how many were checked
(`of`), which ones (`which`: a cell by its run folder under results/runs/,
with the numbers that condemn it), the config key that governs them
(`governed_by`) and the rule applied (`criterion`). The modes:

- location cells no better than predicting the training mean (test RMSE
  at or above the baseline's, both in metrics.json);
- classifiers within one standard deviation of chance: top-1 at or below
  p + sqrt(p (1 - p) / n_test), p the majority-class predictor's top-1 on the
  same test split: the binomial spread of a chance classifier's accuracy;
- diverged cells (a non-finite test metric; a loss that diverges fails its
  job before any metric is written, `train.training.fit`, so a run holding
  one never reaches this report);
- networks stopped by the time budget before their last epoch;
- location cells with any test prediction outside the gantry's workspace
  (`metrics.workspace_metrics`);
- sim-to-real transforms the captures do not identify (transforms.json's check);
- twin calibration coordinates pinned at a bound, and a calibration fit
  stopped at its evaluation budget (twin_calibration.json).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.core.geometry import WORKSPACE_MARGIN
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import LINEAR, Cell
from denali_pipe.transforms.sim_to_real import read_fit_check, read_transforms
from denali_pipe.twin.calibrate import read_fit_status

COLUMNS = ["failure", "count", "of", "which", "governed_by", "criterion"]
CLASSIFIER_TASKS = ("shape", "size")


def cell_id(cell: Cell) -> str:
    """The cell's run folder under results/runs/."""
    return f"{cell.protocol}/{cell.resolution}/{cell.condition}/{cell.split}/{cell.model}_{cell.task}/seed{cell.seed}"


def _row(failure: str, failed: list[str], of: int, governed_by: str, criterion: str) -> dict:
    return {"failure": failure, "count": len(failed), "of": of, "which": "; ".join(failed), "governed_by": governed_by, "criterion": criterion}


def cell_rows(cells: list[CellMetrics]) -> list[dict]:
    """The training cells' failure modes (module docstring); a diverged
    cell counts as diverged only, not in the modes that read its metrics."""
    finite = [m for m in cells if all(np.isfinite(v) for v in m.test.values())]
    location = [m for m in finite if m.cell.task == "location"]
    classifiers = [m for m in finite if m.cell.task in CLASSIFIER_TASKS]
    networks = [m for m in cells if m.cell.model != LINEAR]
    placed = [m for m in location if "outside_workspace" in m.test]

    worse = [f"{cell_id(m.cell)} (RMSE {m.test['rmse']:.3f} m, mean {m.baseline['rmse']:.3f} m)" for m in location if m.test["rmse"] >= m.baseline["rmse"]]
    chance = []
    for m in classifiers:
        p = m.baseline["top1"]
        sd = math.sqrt(p * (1 - p) / m.n_test)
        if m.test["top1"] <= p + sd:
            chance.append(f"{cell_id(m.cell)} (top-1 {m.test['top1']:.3f}, chance {p:.3f} +- {sd:.3f})")
    diverged = [cell_id(m.cell) for m in cells if m not in finite]
    budget = [f"{cell_id(m.cell)} ({m.epochs_run} of {m.hyper.get('epochs')} epochs)" for m in networks if m.stopped_by_budget]
    outside = [
        f"{cell_id(m.cell)} ({m.test['outside_workspace']:.1%}, up to {m.test['max_outside_workspace']:.2f} m out)"
        for m in placed
        if m.test["outside_workspace"] > 0
    ]
    return [
        _row("location worse than the mean", worse, len(location), "train.models.<model>.location",
             "test RMSE at or above predicting the training mean position (metrics.json test.rmse >= baseline.rmse)"),
        _row("classifier at chance", chance, len(classifiers), "train.models.<model>.<task>",
             "test top-1 <= p + sqrt(p (1 - p) / n_test), p the majority-class predictor's top-1: within a binomial sd of chance"),
        _row("diverged training", diverged, len(cells), "train.models.<model>.<task>.lr, train.precision",
             "a non-finite test metric; a diverged run fails its cell's job, naming the first non-finite tensor, and writes no metrics.json (train.training.fit)"),
        _row("training stopped by its budget", budget, len(networks), "train.budget_seconds",
             "a network stopped by the training-time budget before its last epoch (metrics.json stopped_by_budget)"),
        _row("location outside the workspace", outside, len(placed), "train.models.<model>.location.norm",
             f"any test prediction outside the gantry's workspace: its locations' box widened by {WORKSPACE_MARGIN * 100:.2f} cm (geometry.WORKSPACE_MARGIN)"),
    ]  # fmt: skip


def transforms_row(path: Path) -> dict:
    """Transforms the captures do not identify: one case per zone fitted on
    its own (per_zone), or one for the shared fit."""
    mode, checks = read_transforms(path).mode, read_fit_check(path)
    fits = {"shared": checks[0]} if mode == "shared" else {f"zone {z}": c for z, c in enumerate(checks)}
    failed = [f"{name}: {'; '.join(f'{p}: {why}' for p, why in c.unidentified.items())}" for name, c in fits.items() if c.unidentified]
    return _row("sim-to-real transforms unidentified", failed, len(fits), "fit.bootstrap.max_rel_se",
                f"transforms.json's check ({mode} mode): a parameter whose bootstrap standard error exceeds max_rel_se of its value, or that the captures cannot tell apart")  # fmt: skip


def twin_rows(path: Path) -> list[dict]:
    """Twin calibration coordinates pinned at a bound; the fit stopped at its budget."""
    status = read_fit_status(path)
    return [
        _row("twin coordinate at its bound", list(status.at_bound), status.n_coordinates, "twin.calibration (bounds: twin/calibrate.py _bounds)",
             "twin_calibration.json's at_bound: within 0.1 % of the coordinate's range of a bound"),
        _row("twin calibration stopped by its budget", [] if status.converged else [f"twin calibration ({status.evaluations} evaluations)"], 1,
             "twin.calibration.max_evaluations", "twin_calibration.json's fit.converged false: the fit ran out of evaluations"),
    ]  # fmt: skip


def stability_table(cells: list[CellMetrics], transforms: Path, calibration: Path) -> pd.DataFrame:
    """Every failure mode's row (COLUMNS), cells' first."""
    if not cells:
        raise ValueError("stability: no training cells given")
    return pd.DataFrame([*cell_rows(cells), transforms_row(transforms), *twin_rows(calibration)], columns=COLUMNS)


def plot_stability(table: pd.DataFrame, title: str) -> plt.Figure:
    """One bar per failure mode: the share of its cases that failed, `count of of` beside it."""
    share = table["count"] / table["of"].where(table["of"] > 0)
    fig, ax = plt.subplots(figsize=(9.5, 0.45 * len(table) + 1.4), constrained_layout=True)
    y = np.arange(len(table))[::-1]
    ax.barh(y, share.fillna(0.0), color=np.where(table["count"] > 0, "tab:red", "0.6"), height=0.6)
    for yi, s, (_, r) in zip(y, share.fillna(0.0), table.iterrows()):
        ax.text(s + 0.01, yi, f"{r['count']} of {r['of']}   ({r['governed_by'].split(' (')[0]})", va="center", fontsize=7.5)
    ax.axvline(0, color="k", lw=0.8)
    ax.set_yticks(y, table["failure"], fontsize=8)
    ax.set_xlim(0, 1.6)
    ax.set_xticks(np.linspace(0, 1, 6))
    ax.set_xlabel("share of the cases checked that failed (count of cases; governing config key)")
    ax.set_title(title, fontsize=9)
    ax.grid(axis="x", alpha=0.3)
    return fig


def write_stability(metrics_paths: list[Path], transforms: Path, calibration: Path, out_png: Path) -> pd.DataFrame:
    """stability.png and, beside it, stability.csv (the table it plots)."""
    table = stability_table([CellMetrics.read(p) for p in metrics_paths], Path(transforms), Path(calibration))
    n = len(metrics_paths)
    save_figure(plot_stability(table, f"Where the run's methods fail: {n} training cells, the sim-to-real fit, the twin's calibration"), out_png, table)
    return table
