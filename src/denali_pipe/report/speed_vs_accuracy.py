"""Speed vs accuracy: per task, training time (log axis) against the headline
metric for every model, error bars over seeds, the Pareto front marked, and
the predict-the-mean / majority baseline as a reference line; the models the
preset leaves out (config `train.left_out`) named under the title."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.figure import plt, save_figure
from denali_pipe.train.cells import TASKS
from denali_pipe.train.runs import HEADLINE, load_runs, protocol_of, seed_stats

LABELS = {"rmse": "test RMSE (m), lower is better", "top1": "test Top-1, higher is better"}


def pareto(points: pd.DataFrame, higher_is_better: bool) -> pd.Series:
    """True for models no other model beats on both time and metric."""
    t, m = points["train_seconds"].to_numpy(), points["metric"].to_numpy()
    better = (lambda a, b: a > b) if higher_is_better else (lambda a, b: a < b)
    not_worse = (lambda a, b: a >= b) if higher_is_better else (lambda a, b: a <= b)
    front = []
    for i in range(len(points)):
        dominated = any((t[j] <= t[i] and not_worse(m[j], m[i])) and (t[j] < t[i] or better(m[j], m[i])) for j in range(len(points)) if j != i)
        front.append(not dominated)
    return pd.Series(front, index=points.index)


def speed_vs_accuracy_table(runs: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for task in TASKS:
        sub = runs[runs["task"] == task]
        if sub.empty:
            continue
        metric, higher = HEADLINE[task]
        s = seed_stats(sub, ["model"], ["train_seconds", f"test_{metric}", f"baseline_{metric}", "train_samples_per_second"])
        s = s.rename(columns={f"test_{metric}": "metric", f"test_{metric}_std": "metric_std", f"baseline_{metric}": "baseline"})
        s.insert(0, "task", task)
        s.insert(2, "metric_name", metric)
        s["pareto"] = pareto(s, higher)
        rows.append(s)
    return pd.concat(rows, ignore_index=True)


def write_speed_vs_accuracy(metrics_paths: list[Path], out: Path, left_out: dict[str, str] | None = None) -> None:
    """left_out: {model: reason} of the registered models not trained."""
    runs = load_runs(metrics_paths)
    protocol = protocol_of(runs)
    table = speed_vs_accuracy_table(runs)
    tasks = [t for t in TASKS if t in set(table["task"])]
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.6), squeeze=False)
    for ax, task in zip(axes[0], tasks):
        s = table[table["task"] == task]
        for r in s.itertuples():
            ax.errorbar(r.train_seconds, r.metric, xerr=r.train_seconds_std, yerr=r.metric_std, fmt="o", capsize=3,
                        mfc="none" if not r.pareto else None, label=r.model)  # fmt: skip
            ax.annotate(r.model, (r.train_seconds, r.metric), textcoords="offset points", xytext=(4, 4), fontsize=7)
        front = s[s["pareto"]].sort_values("train_seconds")
        ax.step(front["train_seconds"], front["metric"], where="post", color="k", lw=0.8, ls="--", label="Pareto front")
        base = s["baseline"].mean()
        ax.axhline(base, color="grey", lw=1, ls=":", label="mean / majority baseline")
        ax.set_xscale("log")
        ax.set_xlabel("training time per cell (s, log)")
        ax.set_ylabel(LABELS[HEADLINE[task][0]])
        ax.set_title(task, fontsize=9)
        ax.grid(alpha=0.3, which="both")
    axes[0][0].legend(fontsize=6)
    title = f"speed vs accuracy ({runs['resolution'].iloc[0]}, random split, {protocol} protocol; filled: Pareto front)"
    if left_out:
        title += f"\nnot trained on this preset: {', '.join(left_out)} (Table 2 says why)"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, out, table.assign(protocol=protocol))
