"""`report/rig_vs_real.py`: the centre zone's measurements and every zone's
mean counts, on stores of the rig's own histograms."""

import logging

import numpy as np
import pandas as pd
import pytest
from conftest import ASSETS

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.io.store import StoreWriter, open_set
from denali_pipe.report.paper import REAL_LOG_ZONE_MEANS, REAL_ZONE_MEANS
from denali_pipe.report.rig_vs_real import FEATURE_SOURCE, REAL_ZONE_SOURCE, RELEASE_SOURCE, ZONE_SOURCE, release_scores, rig_vs_real
from denali_pipe.rig import feature_moments as fm
from denali_pipe.rig import histograms as H
from denali_pipe.rig.scene import mount_scatterer, object_scatterer

LOCATIONS = (27, 45, 72)


def write_store(out, name, scene_at, phot, rng):
    cs = parse_set_name(name)
    with StoreWriter(out / f"{name}.zarr", cs, metadata={}, source_format="pickle") as w:
        for k in LOCATIONS:
            expected = H.expected_counts("3x3", cs.light_on, scene_at(k), phot)
            w.write_location(k, np.stack([H.sample_counts(expected, phot, rng) for _ in range(2)]))
    return out / f"{name}.zarr"


def release_table(scored: bool) -> pd.DataFrame:
    """A results/release_models.csv: two networks scored per lighting, or none (weights unavailable)."""
    loc, size = {"network": "nonrr_loc", "task": "location", "metric": "rmse"}, {"network": "nonrr_size", "task": "size", "metric": "top1"}
    if not scored:
        return pd.DataFrame([{**loc, "light": "both", "n_samples": 0, "note": "the release's weights are unavailable: offline"}])
    rows = []
    for light, value in (("both", 0.12), ("lightoff", 0.11), ("lighton", 0.13)):
        rows.append({**loc, "light": light, "value": value, "baseline": 0.10, "n_samples": 6, "corr_x": -0.3, "corr_y": 0.2})
        rows.append({**size, "light": light, "value": 0.6, "baseline": 0.5, "n_samples": 6})
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def pairs(tmp_path_factory, demo_config, time_axis, catalogue):
    """Square 8 in and 4 in, both lightings, at LOCATIONS, 2 repeats each, with their backgrounds."""
    out = tmp_path_factory.mktemp("rig_vs_real")
    phot = H.Photometry.from_config(demo_config["rig"]["photometry"], time_axis)
    rng = np.random.default_rng(0)
    mount = lambda k: [mount_scatterer(geo.object_pose(k).t)]  # noqa: E731
    bgs = {light: write_store(out, f"NOOBJECT_8inch_3x3_{light}", mount, phot, rng) for light in ("lightoff", "lighton")}
    pairs = []
    for size in ("8inch", "4inch"):
        for light in ("lightoff", "lighton"):
            scene = lambda k, size=size: mount(k) + [object_scatterer(catalogue["square"], size, geo.object_pose(k))]  # noqa: E731
            obj = write_store(out, f"square_{size}_3x3_{light}", scene, phot, rng)
            pairs.append((obj, bgs[light]))
    return pairs


def test_every_zone_beside_part_5_and_the_release_networks(tmp_path, pairs, caplog):
    release_table(True).to_csv(tmp_path / "release_models.csv", index=False)
    with caplog.at_level(logging.INFO):
        table = rig_vs_real(pairs, tmp_path / "rig_vs_real.png", tmp_path / "rig_vs_real.csv", release_models=tmp_path / "release_models.csv")
    # without the statistics' folder: no feature rows, and the log says so
    assert "feature_stats is not configured" in caplog.text
    df = pd.read_csv(tmp_path / "rig_vs_real.csv")
    assert len(df) == len(table) == 4 + 3 + 18 + 4
    assert not (df.source == FEATURE_SOURCE).any()
    # the release networks per lighting, beside their baselines, with the location predictions' correlations
    assert "release networks: 1 of 2 beat their baseline on these captures (both lightings)" in caplog.text
    release = df[df.source == RELEASE_SOURCE]
    assert sorted(zip(release.network, release.light)) == [(n, li) for n in ("nonrr_loc", "nonrr_size") for li in ("lightoff", "lighton")]
    assert release.baseline.notna().all() and release[release.task == "location"].corr_x.eq(-0.3).all()
    rig = df[df.source == ZONE_SOURCE].sort_values(["zone_row", "zone_col"])
    real = df[df.source == REAL_ZONE_SOURCE].sort_values(["zone_row", "zone_col"])
    np.testing.assert_allclose(real.mean_counts.to_numpy().reshape(3, 3), REAL_ZONE_MEANS)
    np.testing.assert_allclose(rig.real_mean_counts.to_numpy().reshape(3, 3), REAL_ZONE_MEANS)
    np.testing.assert_allclose(rig.real_mean_z.to_numpy().reshape(3, 3), REAL_LOG_ZONE_MEANS)
    # the rig's zone means are the object sets' histograms averaged over locations, repeats and bins
    hist = np.concatenate([open_set(p).histograms[:].astype(float) for p, _ in pairs])
    np.testing.assert_allclose(rig.mean_counts.to_numpy().reshape(3, 3), hist.mean(axis=(0, 1, -1)), rtol=1e-9)
    z = (np.log1p(hist) - fm.LOG_MEAN) / fm.LOG_STD
    np.testing.assert_allclose(rig.mean_z.to_numpy().reshape(3, 3), z.mean(axis=(0, 1, -1)), rtol=1e-9)
    assert (tmp_path / "rig_vs_real.png").stat().st_size > 20_000


@pytest.mark.skipif(not (ASSETS / "feature_stats" / fm.NPZ).exists(), reason="the release's feature statistics are not present")
def test_feature_moments_of_the_same_captures(tmp_path, pairs):
    rig_vs_real(pairs, tmp_path / "rig_vs_real.png", tmp_path / "rig_vs_real.csv", ASSETS / "feature_stats")
    df = pd.read_csv(tmp_path / "rig_vs_real.csv")
    feats = df[df.source == FEATURE_SOURCE]
    assert len(feats) == 18 * 3 and len(df) == 4 + 3 + 18 + 54
    # measured on every capture of the object sets, as the zone means are
    hist = np.concatenate([open_set(p).histograms[:].reshape(-1, 9, 128) for p, _ in pairs])
    direct = fm.feature_distances(fm.load_backbones(ASSETS / "feature_stats"), hist)
    np.testing.assert_allclose(feats.distance.to_numpy(), direct.distance.to_numpy(), rtol=1e-9)
    assert np.isfinite(feats[["mean_term", "var_term"]].to_numpy()).all()
    # the rig's zone means are within 15 % of Part 5's (test_histograms), so the raw-count nets'
    # layer-1 means, a linear function of them, must sit near the real ones: the captures
    # reach the nets in the stored zone order and in counts
    raw1 = feats[(feats.input == "raw") & (feats.layer == 1)]
    assert len(raw1) == 3 and (raw1.mean_term < 0.2).all()
    assert (tmp_path / "rig_vs_real.png").stat().st_size > 40_000


def test_without_release_scores_the_title_says_why():
    rows, note = release_scores(release_table(False))
    assert rows.empty and note == "release networks: none scored (the release's weights are unavailable: offline)"
