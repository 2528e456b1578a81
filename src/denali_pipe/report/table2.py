"""Table 2: every registered model (the paper's four and any of
train.models) on the three tasks (random split), in the order given, beside
the paper's (the supplement prints only the 1D CNN's row)."""

from __future__ import annotations

from pathlib import Path

from denali_pipe.atomic import atomic_file
from denali_pipe.report.paper import TABLE2
from denali_pipe.report.runs import load_runs, metric_table, protocol_of


def write_table2(metrics_paths: list[Path], out: Path) -> None:
    runs = load_runs(metrics_paths)
    if set(runs["split"]) != {"random"}:
        raise ValueError(f"Table 2 uses the random split; got {sorted(set(runs['split']))}")
    table = metric_table(runs, "model", list(dict.fromkeys(runs["model"])), TABLE2)
    table.insert(1, "protocol", protocol_of(runs))
    table.insert(2, "resolution", runs["resolution"].iloc[0])
    with atomic_file(out) as tmp:
        table.to_csv(tmp, index=False)
