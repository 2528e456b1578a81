"""Tables 7-9: one model (train.benchmark_model; the paper's: the 1D CNN)
trained and tested within a condition (size, lighting, object type, gantry
quadrant: conditions.py), one task per table, at every resolution trained, beside the paper's numbers (published at 8x8
only, so the 3x3 rows have none)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core.atomic import atomic_file
from denali_pipe.core.geometry import RESOLUTIONS
from denali_pipe.report.paper import CONDITION_TABLES, CONDITION_TABLES_RESOLUTION
from denali_pipe.train.conditions import GROUP_OF, table_conditions
from denali_pipe.train.runs import EXTRA_METRICS, METRICS, NA, load_runs, protocol_of, seed_stats


def condition_table(runs: pd.DataFrame, table: str, groups: list[str]) -> pd.DataFrame:
    """One row per resolution (of those trained) and condition of `table`
    in its baseline and `groups` (conditions.table_conditions):
    each of the task's metrics with _std over seeds, the paper's value
    (`paper_`) and the trivial predictor's (`trivial_`: training mean
    position or majority class); for location, the share of test
    predictions outside the gantry's workspace (`runs.EXTRA_METRICS`); then
    the mean training and test sizes and n_seeds. A condition without cells
    (ill-posed there) reads n/a."""
    task, conditions = table_conditions(table, groups)
    got = sorted({(m, t) for m, t in zip(runs["model"], runs["task"])})
    if len(got) != 1 or got[0][1] != task:
        raise ValueError(f"{table} shows the {task} cells of one model; got {got}")
    unknown = sorted(set(runs["condition"]) - set(conditions))
    if unknown:
        raise ValueError(f"{table} has no row for conditions {unknown}; its rows are {list(conditions)}")
    names = [name for name, (t, _) in METRICS.items() if t == task]
    extra = {name: metric for name, (t, metric) in EXTRA_METRICS.items() if t == task and f"test_{metric}" in runs}
    columns = [f"{kind}_{METRICS[n][1]}" for n in names for kind in ("test", "baseline")] + [f"test_{m}" for m in extra.values()] + ["n_train", "n_test"]
    stats = seed_stats(runs, ["resolution", "condition"], columns).set_index(["resolution", "condition"])
    paper = CONDITION_TABLES[table]
    protocol = protocol_of(runs)
    rows = []
    for res in [r for r in RESOLUTIONS if r in set(runs["resolution"])]:
        for condition in conditions:
            row = {"resolution": res, "condition_group": GROUP_OF[condition], "condition": condition, "model": got[0][0], "protocol": protocol}
            trained = (res, condition) in stats.index
            s = stats.loc[(res, condition)] if trained else None
            for name in names:
                metric = METRICS[name][1]
                row[name] = round(float(s[f"test_{metric}"]), 4) if trained else NA
                row[f"{name}_std"] = round(float(s[f"test_{metric}_std"]), 4) if trained else NA
                row[f"paper_{name}"] = paper[condition][name] if res == CONDITION_TABLES_RESOLUTION else ""
                row[f"trivial_{name}"] = round(float(s[f"baseline_{metric}"]), 4) if trained else NA
            for name, metric in extra.items():
                known = trained and not pd.isna(s[f"test_{metric}"])
                row[name] = round(float(s[f"test_{metric}"]), 4) if known else NA
                row[f"{name}_std"] = round(float(s[f"test_{metric}_std"]), 4) if known else NA
            row["n_train"] = int(round(s["n_train"])) if trained else 0
            row["n_test"] = int(round(s["n_test"])) if trained else 0
            row["n_seeds"] = int(s["n_seeds"]) if trained else 0
            rows.append(row)
    return pd.DataFrame(rows)


def write_condition_table(metrics_paths: list[Path], table: str, groups: list[str], out: Path) -> None:
    frame = condition_table(load_runs(metrics_paths), table, groups)
    with atomic_file(out) as tmp:
        frame.to_csv(tmp, index=False)
