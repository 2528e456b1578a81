"""Table 5: the 1D CNN under five train/test splits, beside the paper's."""

from __future__ import annotations

from pathlib import Path

from denali_pipe.atomic import atomic_file
from denali_pipe.cells import SPLITS
from denali_pipe.report.paper import TABLE5
from denali_pipe.report.runs import load_runs, metric_table, protocol_of


def write_table5(metrics_paths: list[Path], out: Path) -> None:
    runs = load_runs(metrics_paths)
    if set(runs["model"]) != {"cnn1d"}:
        raise ValueError(f"Table 5 shows the 1D CNN; got models {sorted(set(runs['model']))}")
    table = metric_table(runs, "split", list(SPLITS), TABLE5)
    table.insert(1, "protocol", protocol_of(runs))
    table.insert(2, "resolution", runs["resolution"].iloc[0])
    with atomic_file(out) as tmp:
        table.to_csv(tmp, index=False)
