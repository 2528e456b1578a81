"""Table 6: AprilTag position estimates of the static tags in the world frame.

Per static tag (sensor 0, wall 5-7, table 10-15): the number of estimates
kept after |z| > 2 rejection and the mean and standard deviation (ddof=1) of
each position axis in cm, over every estimate of every light-on set (one per
tracking frame). Rejection follows `poses.filtering` (default: robust z from
median/MAD, one pass, any axis). The paper's values stand in adjacent
`paper_*` columns. Every static tag has a row: `flag` says `too_few` (n <= 5,
nothing could be rejected) or `missing` (never located; its numbers are
empty). The moving object tag 1 is not in Table 6 (see
`poses.calibrate.object_positions`).
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.atomic import atomic_file
from denali_pipe.poses.filtering import DEFAULT_METHOD, THRESHOLD, filter_estimates, summarise
from denali_pipe.report.paper import TABLE6

STAT_COLUMNS = ("n_estimates", "x_mean_cm", "x_std_cm", "y_mean_cm", "y_std_cm", "z_mean_cm", "z_std_cm")
TAG_IDS = tuple(sorted(geo.STATIC_TAGS))


def table6(estimates: pd.DataFrame, *, threshold: float = THRESHOLD, method: str = DEFAULT_METHOD) -> pd.DataFrame:
    """Table 6 from pooled per-set estimates (`poses.estimate` tables), or from
    `filter_estimates` output (with a `kept` column) used as is.

    Columns: tag_id, component, then each of n_estimates, x_mean_cm, x_std_cm,
    y_mean_cm, y_std_cm, z_mean_cm, z_std_cm followed by its paper_ twin, then
    n_raw, n_rejected, flag.
    """
    filt = estimates if "kept" in estimates else filter_estimates(estimates, threshold=threshold, method=method)
    static = filt[filt["tag_id"].isin(TAG_IDS)]
    s = summarise(static, "tag_id", expected=TAG_IDS)
    out = pd.DataFrame({"tag_id": s["tag_id"].astype("int64"), "component": s["tag_id"].map(geo.TAG_COMPONENT)})
    for col in STAT_COLUMNS:
        if col == "n_estimates":
            out[col] = s["n_estimates"]
        else:
            axis, stat = col.split("_")[:2]
            out[col] = s[f"{axis}_{stat}"] * 100.0
        out[f"paper_{col}"] = s["tag_id"].map(lambda t, c=col: TABLE6.get(int(t), {}).get(c))
    out["paper_n_estimates"] = out["paper_n_estimates"].astype("Int64")
    out["n_raw"] = s["n_raw"]
    out["n_rejected"] = s["n_rejected"]
    out["flag"] = s["flag"]
    return out


def write_table6(estimates: pd.DataFrame, out: Path, **kw) -> pd.DataFrame:
    """Write `table6(estimates)` as CSV atomically; returns the table."""
    df = table6(estimates, **kw)
    with atomic_file(Path(out)) as tmp:
        df.to_csv(tmp, index=False, float_format="%.4f")
    return df
