"""Table 2: every registered model (the paper's four and any of
train.models) on the three tasks (random split), in the order given, beside
the paper's (the supplement prints only the 1D CNN's row). A model the
preset leaves out (config `train.left_out`) keeps its row, metrics n/a,
with the reason in `note`."""

from __future__ import annotations

from pathlib import Path

from denali_pipe.core.atomic import atomic_file
from denali_pipe.report.paper import TABLE2
from denali_pipe.train.runs import left_out_note, load_runs, metric_table, protocol_of


def write_table2(metrics_paths: list[Path], out: Path, left_out: dict[str, str] | None = None) -> None:
    """left_out: {model: reason} of the registered models not trained (rows after the trained ones)."""
    runs = load_runs(metrics_paths)
    if set(runs["split"]) != {"random"}:
        raise ValueError(f"Table 2 uses the random split; got {sorted(set(runs['split']))}")
    left_out = left_out or {}
    trained = list(dict.fromkeys(runs["model"]))
    if both := sorted(set(trained) & set(left_out)):
        raise ValueError(f"Table 2: models {both} are both trained and left out")
    table = metric_table(runs, "model", trained + list(left_out), TABLE2)
    table.insert(1, "protocol", protocol_of(runs))
    table.insert(2, "resolution", runs["resolution"].iloc[0])
    table["note"] = [left_out_note(left_out[m]) if m in left_out else "" for m in table["model"]]
    with atomic_file(out) as tmp:
        table.to_csv(tmp, index=False)
