"""Table 10: per model (in the order given) and task, parameters, forward
FLOPs per sample, data sizes, training and inference cost, beside the
paper's (which prints no FLOPs). Hours are measured wall-clock of our cells (mean
over seeds), on the device and in the precision (`device`, `precision`) each
cell trained in; `epochs` is the configured count and `epochs_run` what the
time budget allowed (mean over seeds). A model the preset leaves out (config
`train.left_out`) keeps its rows, ours n/a beside the paper's, with the
reason in `note`."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.atomic import atomic_file
from denali_pipe.report.paper import TABLE10, TABLE10_COLUMNS
from denali_pipe.train.cells import TASKS
from denali_pipe.train.runs import NA, left_out_note, load_runs, protocol_of, seed_stats


def write_table10(metrics_paths: list[Path], out: Path, left_out: dict[str, str] | None = None) -> None:
    """left_out: {model: reason} of the registered models not trained (rows after the trained ones)."""
    runs = load_runs(metrics_paths)
    runs["train_hours"] = runs["train_seconds"] / 3600
    runs["inference_hours"] = runs["inference_seconds"] / 3600
    stats = seed_stats(runs, ["model", "task"], ["train_hours", "inference_hours", "train_samples_per_second"]).set_index(["model", "task"])
    first = runs.groupby(["model", "task"]).first()
    rows = []
    for model in dict.fromkeys(runs["model"]):
        for task in TASKS:
            if (model, task) not in stats.index:
                continue
            r, s, paper = first.loc[(model, task)], stats.loc[(model, task)], TABLE10.get((model, task), {})
            ours = {
                "params": int(r["params"]),
                "train_size": int(r["n_train"]),
                "train_hours": s["train_hours"],
                "epochs": int(r["epochs"]),
                "batch_size": int(r["batch_size"]),
                "test_size": int(r["n_test"]),
                "inference_hours": s["inference_hours"],
            }
            row = {"model": model, "task": task}
            for c in TABLE10_COLUMNS:
                row[c] = ours[c]
                if c.endswith("hours"):
                    row[f"{c}_std"] = s[f"{c}_std"]
                row[f"paper_{c}"] = paper.get(c, "")
                if c == "params":
                    row["flops"] = "" if pd.isna(r["flops"]) else int(r["flops"])
            row["epochs_run"] = float(runs[(runs["model"] == model) & (runs["task"] == task)]["epochs_run"].mean())
            row["stopped_by_budget"] = bool(runs[(runs["model"] == model) & (runs["task"] == task)]["stopped_by_budget"].any())
            row["train_samples_per_second"] = s["train_samples_per_second"]
            row["validation_size"] = int(r["n_validation"])
            row["device"] = r["device"]
            row["precision"] = r["precision"]
            row["n_seeds"] = int(s["n_seeds"])
            row["note"] = ""
            rows.append(row)
    for model, reason in (left_out or {}).items():
        for task in TASKS:
            paper = TABLE10.get((model, task), {})
            rows.append(
                {"model": model, "task": task, **{f"paper_{c}": paper.get(c, "") for c in TABLE10_COLUMNS}, "n_seeds": 0, "note": left_out_note(reason)}
            )
    table = pd.DataFrame(rows)
    ours = [c for c in table.columns if c not in ("model", "task", "n_seeds", "note") and not c.startswith("paper_")]
    table[ours] = table[ours].astype(object).where(table["note"] == "", NA)
    table.insert(2, "protocol", protocol_of(runs))
    with atomic_file(out) as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g")
