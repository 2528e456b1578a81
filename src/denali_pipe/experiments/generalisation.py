"""Figs 10 and 11 (paper supplement §8): the benchmark model's cells (the paper's: the 1D CNN), trained
on the base (retroreflective, upright) objects, scored on objects they never
saw: the non-retroreflective cardstock and white plates (Fig 10: location,
shape, size) and the italic 1, A and circle (Fig 11: location, shape).

The cells are the random-split benchmark-model cells the tables train (every seed);
`denali evaluate` scores each on a variant dataset (`evaluate.Evaluation`,
every sample of it, both lightings). Beside each score stand the cells'
own test scores on the base data (`CellMetrics.test`) and a reference a
model must beat: for location the cell's predict-the-training-mean baseline
on the same samples, for shape and size chance (1 / classes: uniform
guessing), as the majority class of a balanced training set is an arbitrary
label, class "0", that a variant of class "1" never has.

Fig 10 also shows what the non-retroreflective return looks like: the
background-subtracted centre-zone histogram of each non-RR object beside a
retroreflective base object's (the same class where captured) at the same
size, lighting and gantry location.

Each figure's CSV is one long table; `panel` says which part of the figure a
row belongs to:
- `score`: task, metric (`train.runs.HEADLINE`: RMSE in m, Top-1), data
  (`BASE_TEST`, the variant's sets, or `ANY_DATA` for chance), predictor
  (`MODEL`, `MEAN_BASELINE`, `CHANCE`), value (mean over seeds), std (ddof 1;
  0 for one seed), n_seeds, n_samples (per seed);
- `histogram` (Fig 10): object, data (`NONRR` or `RR`), size, light,
  location, bin (absolute, on config sensor.time_axis), value (mean counts over
  the repeats), std (over the repeats), n_samples (repeats).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.train.cell_metrics import CellMetrics
from denali_pipe.train.cells import TASKS
from denali_pipe.train.evaluate import Evaluation
from denali_pipe.train.runs import HEADLINE

BASE_TEST = "base test split"
ANY_DATA = "any"  # the `data` of chance, which does not depend on the samples
# The cells' predictor (the title names its model: train.benchmark_model).
MODEL, MEAN_BASELINE, CHANCE = "trained model", "predict the training mean", "chance"
NONRR, RR = "non-retroreflective", "retroreflective"
VARIANT_DATA = {"fig10": "non-RR sets", "fig11": "italic sets"}
METRIC_LABELS = {"rmse": "RMSE (m), lower is better", "top1": "Top-1 accuracy, higher is better"}
COLUMNS = ("panel", "task", "metric", "data", "predictor", "value", "std", "n_seeds", "n_samples", "object", "size", "light", "location", "bin")
LIGHT_ORDER = ("lightoff", "lighton")  # lights off first: the lower floor shows the return best
SIZE_ORDER = ("8inch", "4inch")  # the larger plate first: the stronger return


def _stats(values: list[float]) -> tuple[float, float]:
    v = np.asarray(values, np.float64)
    return float(v.mean()), float(v.std(ddof=1)) if len(v) > 1 else 0.0


def score_table(cells: list[CellMetrics], evaluations: list[Evaluation], variant_data: str) -> pd.DataFrame:
    """The `score` rows: per task of the cells (TASKS order), their headline
    metric on their own test split and on the variant dataset, each beside
    its reference.

    `cells` must be cells of one model; every evaluation must be of one of them
    (the same cell and seed), all on one dataset, one per cell. ValueError
    otherwise."""
    models = {m.cell.model for m in cells}
    if len(models) != 1:
        raise ValueError(f"the figure shows the cells of one model; got models {sorted(models)}")
    tasks = [t for t in TASKS if t in {m.cell.task for m in cells}]
    datasets = sorted({e.dataset for e in evaluations})
    if len(datasets) != 1:
        raise ValueError(f"the evaluations mix datasets {datasets}; a figure scores one variant dataset")
    own = {m.cell: m for m in cells}
    rows = []
    for task in tasks:
        metric, _ = HEADLINE[task]
        evals = [e for e in evaluations if e.cell.task == task]
        stray = [e.cell for e in evals if e.cell not in own]
        if stray:
            raise ValueError(f"evaluations of cells whose metrics were not given: {stray}")
        mine = [m for m in cells if m.cell.task == task]
        if not evals or len(evals) != len(mine):
            raise ValueError(f"{task}: {len(mine)} cells but {len(evals)} evaluations on {datasets[0]}; expected one per cell")
        parts = [
            (BASE_TEST, MODEL, [m.test[metric] for m in mine], mine[0].n_test),
            (variant_data, MODEL, [e.metrics[metric] for e in evals], evals[0].n_samples),
        ]
        if task == "location":
            parts += [
                (BASE_TEST, MEAN_BASELINE, [m.baseline[metric] for m in mine], mine[0].n_test),
                (variant_data, MEAN_BASELINE, [e.baseline[metric] for e in evals], evals[0].n_samples),
            ]
        else:
            parts.append((ANY_DATA, CHANCE, [1.0 / mine[0].n_classes], 0))
        for data, predictor, values, n in parts:
            mean, std = _stats(values)
            rows.append({"panel": "score", "task": task, "metric": metric, "data": data, "predictor": predictor, "value": mean, "std": std,
                         "n_seeds": len(values) if predictor != CHANCE else 0, "n_samples": n})  # fmt: skip
    return pd.DataFrame(rows).reindex(columns=list(COLUMNS))


def _centre_zone(x: np.ndarray) -> np.ndarray:
    """(N, T) the centre zone of x (N, n, n, T) (n odd; for even n the zone
    right below and right of the centre)."""
    n = x.shape[1]
    return x[:, n // 2, n // 2, :]


def _mid_location(samples: pd.DataFrame, among: set[int]) -> int:
    """The location of `among` whose label is nearest the mean label of
    `samples` (the middle of the grid they cover)."""
    by_loc = samples[samples["location"].isin(among)].groupby("location")[["x", "y"]].first()
    d = np.hypot(by_loc["x"] - samples["x"].mean(), by_loc["y"] - samples["y"].mean())
    return int(d.idxmin())


def histogram_table(x_variant: np.ndarray, variant: pd.DataFrame, x_base: np.ndarray, base: pd.DataFrame, crop_start: int) -> pd.DataFrame:
    """The `histogram` rows: per variant object, its background-subtracted
    centre-zone histogram and a base object's at the same size, lighting and
    location, mean and std over the repeats.

    x_*: (N, n, n, T) features of the variant and base datasets with sample
    tables `variant`, `base`; crop_start: the features' first bin. Per
    object: the largest size, lights off where captured, the captured
    location nearest the middle of the grid where a base object of the same
    size and lighting is captured too; the base object of the object's class
    if captured there, else the first (ASCII) base object there. A `pair`
    column names the variant object each row is plotted with."""
    variant, base = variant.reset_index(drop=True), base.reset_index(drop=True)  # row labels = rows of x
    rows = []
    for obj in sorted(variant["object"].unique()):
        mine = variant[variant["object"] == obj]
        size = next(s for s in SIZE_ORDER if s in set(mine["size"]))
        light = next(v for v in LIGHT_ORDER if v in set(mine["light"]))
        mine = mine[(mine["size"] == size) & (mine["light"] == light)]
        peers = base[(base["size"] == size) & (base["light"] == light) & base["location"].isin(set(mine["location"]))]
        if peers.empty:
            raise ValueError(f"no base object captured at {size}, {light} at the locations of {obj}")
        location = _mid_location(mine, set(peers["location"]))
        peers = peers[peers["location"] == location]
        same_class = peers[peers["class"] == mine["class"].iloc[0]]
        reference = sorted((same_class if len(same_class) else peers)["object"].unique())[0]
        for data, name, x, table in ((NONRR, obj, x_variant, mine), (RR, reference, x_base, peers)):
            rows_of = table.index[(table["object"] == name) & (table["location"] == location)]
            h = _centre_zone(x[rows_of])
            bins = crop_start + np.arange(h.shape[-1])
            rows.append(pd.DataFrame({"panel": "histogram", "data": data, "object": name, "size": size, "light": light, "location": location, "bin": bins,
                                      "value": h.mean(axis=0), "std": h.std(axis=0), "n_samples": len(h), "pair": obj}))  # fmt: skip
    return pd.concat(rows, ignore_index=True)


def _plot_scores(axes, scores: pd.DataFrame, variant_data: str) -> None:
    order = (BASE_TEST, variant_data)
    for ax, task in zip(axes, dict.fromkeys(scores["task"])):
        s = scores[scores["task"] == task]
        metric = s["metric"].iloc[0]
        cnn = s[s["predictor"] == MODEL].set_index("data").loc[list(order)]
        ax.bar(range(len(order)), cnn["value"], yerr=cnn["std"], capsize=4, color=["tab:blue", "tab:orange"], width=0.6, label=MODEL)
        for i, v in enumerate(cnn["value"]):
            # inside the bar, boxed: at its top the error bar and the dashed baseline cross it
            ax.text(i, v / 2, f"{v:.3g}", ha="center", va="center", fontsize=7, bbox=dict(fc="white", alpha=0.8, lw=0))
        if task == "location":
            base = s[s["predictor"] == MEAN_BASELINE].set_index("data").loc[list(order)]
            for i, v in enumerate(base["value"]):
                ax.hlines(v, i - 0.4, i + 0.4, color="k", ls="--", lw=1.2, label=MEAN_BASELINE if i == 0 else None)
            top = max((cnn["value"] + cnn["std"]).max(), base["value"].max())
        else:
            ax.axhline(s.loc[s["predictor"] == CHANCE, "value"].item(), color="k", ls="--", lw=1.2, label=f"{CHANCE} (1 / classes)")
            ax.set_yticks(np.linspace(0, 1, 6))
            top = 1.0
        ax.set_ylim(0, 1.3 * top)  # headroom for the legend above the bars
        ax.set_xticks(range(len(order)), [f"{d}\n({int(n)} samples)" for d, n in zip(order, cnn["n_samples"])], fontsize=7)
        ax.set_ylabel(METRIC_LABELS[metric], fontsize=8)
        seeds = int(cnn["n_seeds"].min())
        ax.set_title(f"{task} ({seeds} seed{'s' if seeds != 1 else ''}, mean +- std)", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=7, loc="upper center", ncols=2)


def _title(cells: list[CellMetrics]) -> str:
    c = cells[0].cell
    return f"{c.model} cells trained on the base objects ({c.resolution}, {c.split} split, {c.protocol} protocol)"


def fig10(cells: list[CellMetrics], evaluations: list[Evaluation], histograms: pd.DataFrame, out_png: Path) -> pd.DataFrame:
    """Fig 10: `histogram_table` rows on top, the scores of `score_table`
    below (the paper's: location, shape, size); writes the PNG and its CSV,
    returns the table."""
    data = VARIANT_DATA["fig10"]
    scores = score_table(cells, evaluations, data)
    tasks = list(dict.fromkeys(scores["task"]))
    pairs = list(dict.fromkeys(histograms["pair"]))
    fig = plt.figure(figsize=(4.4 * len(tasks), 7.4), layout="constrained")
    top, bottom = fig.subfigures(2, 1)
    for ax, pair in zip(top.subplots(1, len(pairs), squeeze=False)[0], pairs):
        h = histograms[histograms["pair"] == pair]
        for data_kind, colour in ((RR, "tab:gray"), (NONRR, "tab:red")):
            c = h[h["data"] == data_kind]
            label = f"{c['object'].iloc[0]} ({data_kind})"
            ax.plot(c["bin"], c["value"], color=colour, lw=1.3, label=label)
            ax.fill_between(c["bin"], c["value"] - c["std"], c["value"] + c["std"], color=colour, alpha=0.2, lw=0)
        ax.axhline(0, color="k", lw=0.6)
        first = h.iloc[0]
        ax.set_title(f"centre zone, {first['size']} {first['light']}, location {int(first['location'])}", fontsize=9)
        ax.set_xlabel("time bin (config sensor.time_axis)")
        ax.set_ylabel(f"counts above background\n(mean +- std of {int(first['n_samples'])} repeats)", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    top.suptitle("Non-retroreflective objects: their three-bounce return beside a retroreflective object's", fontsize=9)
    _plot_scores(bottom.subplots(1, len(tasks), squeeze=False)[0], scores, data)
    bottom.suptitle(f"{_title(cells)}, scored on the non-RR sets", fontsize=9)
    table = pd.concat([histograms.drop(columns="pair"), scores], ignore_index=True).reindex(columns=list(COLUMNS))
    save_figure(fig, out_png, table)
    return table


def fig11(cells: list[CellMetrics], evaluations: list[Evaluation], out_png: Path) -> pd.DataFrame:
    """Fig 11: the scores of `score_table` on the italic sets (the paper's:
    location, shape); writes the PNG and its CSV, returns the table."""
    data = VARIANT_DATA["fig11"]
    table = score_table(cells, evaluations, data)
    n = table["task"].nunique()
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.8), squeeze=False)
    _plot_scores(axes[0], table, data)
    fig.suptitle(f"Italic variants of base objects (8 in): {_title(cells)} scored on them", fontsize=9)
    fig.tight_layout()
    save_figure(fig, out_png, table)
    return table
