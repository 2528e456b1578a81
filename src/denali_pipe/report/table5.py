"""Table 5: one model (train.benchmark_model; the paper's: the 1D CNN) under
five train/test splits, beside the paper's 1D CNN."""

from __future__ import annotations

from pathlib import Path

from denali_pipe.core.atomic import atomic_file
from denali_pipe.core.splits import SPLITS
from denali_pipe.report.paper import TABLE5
from denali_pipe.train.runs import load_runs, metric_table, protocol_of


def write_table5(metrics_paths: list[Path], out: Path) -> None:
    runs = load_runs(metrics_paths)
    models = sorted(set(runs["model"]))
    if len(models) != 1:
        raise ValueError(f"Table 5 shows one model; got models {models}")
    table = metric_table(runs, "split", list(SPLITS), TABLE5)
    table.insert(1, "model", models[0])
    table.insert(2, "protocol", protocol_of(runs))
    table.insert(3, "resolution", runs["resolution"].iloc[0])
    with atomic_file(out) as tmp:
        table.to_csv(tmp, index=False)
