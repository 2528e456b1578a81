"""The timing-jitter sweep (paper Sec 5.2, supplement 11.6): how the NLOS
tasks degrade as the LiDAR's timing gets worse. One 1D CNN is trained per
FWHM, task and seed, as training cells of condition `jitter<F>ps`
(train/jitter.py blurs the histograms); `jitter_curve` gathers them into
the sweep's table.
"""

from __future__ import annotations

import pandas as pd

from denali_pipe.core.geometry import TimeAxis
from denali_pipe.train.jitter import jitter_fwhm
from denali_pipe.train.runs import METRICS, seed_stats


def jitter_curve(runs: pd.DataFrame, axis: TimeAxis) -> pd.DataFrame:
    """The sweep's table from `train.runs.load_runs` rows of jitter cells:
    one row per task, metric (the paper's table metrics) and FWHM, with
    fwhm_bins (in bins of `axis`, the captures' time axis), the mean and
    std over seeds, n_seeds and the trivial predictor's mean (training mean
    position or majority class)."""
    fwhm = runs["condition"].map(jitter_fwhm)
    if fwhm.isna().any():
        raise ValueError(f"not jitter cells: conditions {sorted(set(runs['condition'][fwhm.isna()]))}")
    runs = runs.assign(fwhm_ps=fwhm.astype(int))
    rows = []
    for name, (task, metric) in METRICS.items():
        sub = runs[runs["task"] == task]
        if sub.empty:
            continue
        cols = [f"test_{metric}", f"baseline_{metric}"]
        stats = seed_stats(sub, ["fwhm_ps"], cols).sort_values("fwhm_ps")
        for r in stats.itertuples(index=False):
            r = r._asdict()
            rows.append(
                {
                    "task": task, "metric": name, "fwhm_ps": r["fwhm_ps"], "fwhm_bins": r["fwhm_ps"] / axis.bin_width_ps,
                    "mean": r[cols[0]], "std": r[f"{cols[0]}_std"], "n_seeds": r["n_seeds"], "trivial": r[cols[1]],
                }
            )  # fmt: skip
    return pd.DataFrame(rows)
