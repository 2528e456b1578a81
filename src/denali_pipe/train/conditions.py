"""Conditions: the part of the benchmark's samples a training cell trains and
tests on (its split is drawn within them). `condition_mask` is the one
filter, used by `denali train` and, on the samples a config plans, by the
DAG to leave ill-posed cells out. Light enough for the Snakefile to import.

- `all`: every sample; every benchmark cell (Tables 2, 5, 10) and the
  baseline row of Tables 7-9.
- Tables 7-9 (paper supplement §10): size `8inch` / `4inch`, lighting
  `light_on` / `light_off`, object type `letters` / `numbers` / `shapes`:
  the samples with that attribute; location `front_quadrant` /
  `back_quadrant` (QUADRANTS).
- `jitter<F>ps`: the timing-jitter sweep's light-on 3x3 centre-zone
  histograms blurred by a Gaussian of FWHM F ps (train/jitter.py);
  `jitter0ps` is the unjittered original.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from denali_pipe.core.geometry import TimeAxis, gantry_row_col
from denali_pipe.train.cells import ALL
from denali_pipe.train.jitter import CONDITION_PATTERN as JITTER_PATTERN
from denali_pipe.train.jitter import centre_zone, jitter, jitter_fwhm

if TYPE_CHECKING:
    # annotations only: every `denali` verb's parser imports this module for
    # its choices, and pandas would cost each job ~0.3 CPU-s (docs/performance.md)
    import pandas as pd

# condition -> (sample-table column, value)
ATTRIBUTES = {
    "8inch": ("size", "8inch"),
    "4inch": ("size", "4inch"),
    "light_on": ("light", "lighton"),
    "light_off": ("light", "lightoff"),
    "letters": ("type", "letter"),
    "numbers": ("type", "number"),
    "shapes": ("type", "shape"),
}
# The paper names a front and a back quadrant but does not define them. Here
# each is a 5 x 5 block of the 10 x 10 gantry grid, as (rows, columns) of
# geometry.gantry_row_col (rows step away from the relay wall): front holds
# the gantry's first location (0, nearest the wall), back its last (99,
# farthest from it). They share their columns, so they differ only in the
# distance from the wall. Being defined on the gantry's location index, they
# hold on real captures, whose positions come from calibration.
QUADRANTS = {"front_quadrant": (range(0, 5), range(0, 5)), "back_quadrant": (range(5, 10), range(0, 5))}
JITTER_LIGHT = "lighton"
# The paper's condition groups, in its tables' order; every table has the baseline.
BASELINE = "baseline"
GROUPS = {
    BASELINE: (ALL,),
    "size": ("8inch", "4inch"),
    "lighting": ("light_on", "light_off"),
    "object_type": ("letters", "numbers", "shapes"),
    "location": tuple(QUADRANTS),
}
GROUP_OF = {c: g for g, conditions in GROUPS.items() for c in conditions}
# Tables 7-9: the task and the conditions, rows in the paper's order.
TABLES = {
    "table7": ("shape", (ALL, "8inch", "4inch", "light_on", "light_off", "front_quadrant", "back_quadrant")),
    "table8": ("size", (ALL, "letters", "numbers", "shapes", "light_on", "light_off", "front_quadrant", "back_quadrant")),
    "table9": ("location", (ALL, "letters", "numbers", "shapes", "light_on", "light_off", "8inch", "4inch")),
}
# The groups a config may choose from (config `conditions.groups`).
CONDITION_GROUPS = tuple(g for g in GROUPS if g != BASELINE)
# A regular expression matching every condition name (the Snakefile's wildcard).
PATTERN = "|".join([*GROUP_OF, JITTER_PATTERN])
# The label column a classification task needs two values of.
CLASS_COLUMN = {"shape": "class", "size": "size"}


def table_conditions(table: str, groups: list[str]) -> tuple[str, list[str]]:
    """(task, conditions) of Table 7, 8 or 9: its baseline and its conditions
    of `groups` (of CONDITION_GROUPS), in the paper's row order."""
    unknown = sorted(set(groups) - set(CONDITION_GROUPS))
    if unknown:
        raise ValueError(f"unknown condition groups {unknown}; expected some of {CONDITION_GROUPS}")
    task, conditions = TABLES[table]
    return task, [c for c in conditions if GROUP_OF[c] in (BASELINE, *groups)]


def condition_mask(samples: pd.DataFrame, condition: str) -> np.ndarray:
    """(N,) bool: the rows of a sample table (dataset.py's columns; `type`,
    `size`, `light` or `location` as the condition needs) that `condition` keeps."""
    if condition == ALL:
        return np.ones(len(samples), bool)
    if condition in ATTRIBUTES:
        column, value = ATTRIBUTES[condition]
        return (samples[column] == value).to_numpy()
    if condition in QUADRANTS:
        rows, cols = QUADRANTS[condition]
        row, col = gantry_row_col(samples["location"].to_numpy())
        return np.isin(row, rows) & np.isin(col, cols)
    if jitter_fwhm(condition) is not None:
        return (samples["light"] == JITTER_LIGHT).to_numpy()
    raise ValueError(f"unknown condition {condition!r}; expected one of {list(GROUP_OF)} or jitter<FWHM>ps")


def ill_posed(samples: pd.DataFrame, task: str, condition: str) -> str | None:
    """Why training `task` within `condition` on these samples cannot work
    (no sample kept, or a classification left with one class), or None."""
    kept = samples[condition_mask(samples, condition)]
    if kept.empty:
        return f"condition {condition} keeps no sample"
    column = CLASS_COLUMN.get(task)
    if column is not None and kept[column].nunique() < 2:
        return f"condition {condition} leaves one {task} class ({kept[column].iloc[0]})"
    return None


def condition_view(x: np.ndarray, samples: pd.DataFrame, task: str, condition: str, axis: TimeAxis | None = None) -> tuple[np.ndarray, pd.DataFrame]:
    """The features (N', n', n', T) and sample table (N' rows, renumbered) a
    cell of `task` trains and tests on under `condition`: the rows it keeps
    of x (N, n, n, T) and `samples`, for a jitter condition their 3x3 centre
    zone (N', 1, 1, T) blurred in bins of `axis` (the captures' time axis,
    which only a jitter condition needs). ValueError if the task is
    ill-posed there."""
    reason = ill_posed(samples, task, condition)
    if reason is not None:
        raise ValueError(f"{task} is ill-posed: {reason}")
    mask = condition_mask(samples, condition)
    kept = x if mask.all() else x[mask]  # `all` keeps the array itself, not a copy
    fwhm = jitter_fwhm(condition)
    if fwhm is not None:
        if axis is None:
            raise ValueError(f"condition {condition} blurs in ps: it needs the captures' time axis")
        kept = jitter(centre_zone(kept), fwhm, axis)
    return kept, samples[mask].reset_index(drop=True)
