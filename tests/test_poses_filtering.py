"""|z| > 2 rejection (`poses/filtering.py`): gross outliers, symmetric and
one-sided, small groups, never-seen tags, and per-location grouping of the
moving object tag."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.poses.filtering import MIN_FILTER_N, filter_estimates, summarise, zscore_keep

N = 12_000
SIGMA = 0.001  # 1 mm inlier spread per axis
TRUE = np.array([0.47, 0.255, 0.388])


def _estimates(seed: int, frac: float, one_sided: bool) -> tuple[np.ndarray, np.ndarray]:
    """N 3-D estimates around TRUE with a fraction `frac` of gross outliers
    displaced by 5-50 sigma along x (as a depth error along a line of sight
    would), in either direction, or all toward +x when one_sided."""
    rng = np.random.default_rng(seed)
    v = TRUE + SIGMA * rng.standard_normal((N, 3))
    bad = rng.random(N) < frac
    size = SIGMA * rng.uniform(5, 50, N)
    sign = np.ones(N) if one_sided else rng.choice([-1.0, 1.0], N)
    v[bad, 0] += (sign * size)[bad]
    return v, bad


@pytest.mark.parametrize("one_sided", [False, True])
def test_mad_recovers_the_mean_with_3_percent_gross_outliers(one_sided):
    v, bad = _estimates(1, 0.03, one_sided)
    raw_bias = np.abs(v.mean(axis=0) - TRUE).max()
    keep = zscore_keep(v)  # default: median/MAD, one pass
    assert not keep[bad].any(), "every gross outlier (>= 5 sigma) is rejected"
    assert np.abs(v[keep].mean(axis=0) - TRUE).max() < 0.05 * SIGMA  # < 0.05 mm
    # any-axis rejection at 2 sigma drops about 13 % of 3-D inliers
    assert 0.08 < 1 - keep[~bad].mean() < 0.18
    if one_sided:
        assert raw_bias > 0.5 * SIGMA  # the outliers do move the raw mean


def test_single_pass_keeps_one_sided_outliers_iteration_removes_them():
    v, bad = _estimates(2, 0.03, one_sided=True)
    single = zscore_keep(v, method="single")
    # the outliers inflate the classical sigma: the paper's literal rule keeps ~14 % of them
    assert 0.05 < single[bad].mean() < 0.3
    assert not zscore_keep(v)[bad].any()
    it = zscore_keep(v, method="iterate")
    assert not it[bad].any()
    assert np.abs(v[it].mean(axis=0) - TRUE).max() < 0.05 * SIGMA
    # iterating trims the inliers further than one robust pass
    assert it[~bad].mean() < zscore_keep(v)[~bad].mean()


def test_symmetric_outliers_single_pass_is_fine():
    v, bad = _estimates(3, 0.03, one_sided=False)
    keep = zscore_keep(v, method="single")
    assert np.abs(v[keep].mean(axis=0) - TRUE).max() < 0.05 * SIGMA


def test_small_groups_are_never_filtered():
    v = np.array([[0.0], [0.0], [0.0], [0.0], [1.0]])  # n = 5: |z| <= sqrt(4) = 2 classically
    for method in ("mad", "iterate", "single"):
        assert zscore_keep(v, method=method).all()
    assert MIN_FILTER_N == 6
    v6 = np.array([[0.0], [0.001], [-0.001], [0.0005], [-0.0005], [1.0]])
    assert not zscore_keep(v6)[-1]


def test_constant_axis_rejects_nothing_on_it():
    rng = np.random.default_rng(4)
    v = np.c_[rng.standard_normal(100), np.zeros(100)]  # z on a plane: MAD 0 and std 0
    keep = zscore_keep(v)
    assert keep.mean() > 0.9
    with pytest.raises(ValueError, match="unknown z-score method"):
        zscore_keep(v, method="nope")


def _rows(tag_id: int, pos: np.ndarray, location: int = -1, status: str = "ok") -> pd.DataFrame:
    return pd.DataFrame({"tag_id": tag_id, "location": location, "status": status, "set": "S", "x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2]})


def test_filter_groups_static_per_tag_and_object_per_location():
    rng = np.random.default_rng(5)
    a = TRUE + SIGMA * rng.standard_normal((50, 3))
    a[0] += 0.05  # a gross outlier of tag 0
    objs = []
    for k in range(3):  # the object tag at three locations 3.65 cm apart, 20 estimates each
        p = geo.tag1_position(k) + SIGMA * rng.standard_normal((20, 3))
        objs.append(_rows(geo.OBJECT_TAG_ID, p, location=k))
    df = pd.concat([_rows(0, a), *objs, _rows(5, np.zeros((2, 3)), status="missing")], ignore_index=True)
    f = filter_estimates(df)
    assert set(f["status"]) == {"ok"}  # only located estimates are filtered
    assert not f.loc[0, "kept"]
    obj = f[f["tag_id"] == geo.OBJECT_TAG_ID]
    assert (obj["group_n"] == 20).all()  # grouped per location, not pooled
    assert obj["kept"].mean() > 0.75  # pooled, the 3.65 cm steps would dominate the spread
    s = summarise(obj, "location", expected=[0, 1, 2, 3])
    assert list(s["location"]) == [0, 1, 2, 3]
    assert s.loc[3, "flag"] == "missing" and s.loc[3, "n_estimates"] == 0 and np.isnan(s.loc[3, "x_mean"])
    np.testing.assert_allclose(s.loc[:2, ["x_mean", "y_mean", "z_mean"]].to_numpy(), geo.tag1_position(np.arange(3)), atol=1e-3)


def test_summary_reports_too_few_and_missing_tags_and_uses_ddof_1():
    df = pd.concat([_rows(0, np.array([[0.0, 0, 0], [0.002, 0, 0], [0.004, 0, 0]])), _rows(14, np.zeros((10, 3)))], ignore_index=True)
    f = filter_estimates(df)
    s = summarise(f, "tag_id", expected=[0, 5, 14]).set_index("tag_id")
    assert s.loc[0, "flag"] == "too_few" and s.loc[0, "n_estimates"] == 3 and s.loc[0, "n_rejected"] == 0
    assert s.loc[0, "x_std"] == pytest.approx(0.002)  # ddof=1: std of 0, 2, 4 mm is 2 mm
    assert s.loc[5, "flag"] == "missing" and s.loc[5, "n_estimates"] == 0
    assert s.loc[14, "flag"] == "ok"
