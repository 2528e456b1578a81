"""`report/rig_vs_real.py`: the centre zone's measurements and every zone's
mean counts, on stores of the rig's own histograms."""

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.io.store import StoreWriter, open_set
from denali_pipe.report.paper import REAL_ZONE_MEANS
from denali_pipe.report.rig_vs_real import REAL_ZONE_SOURCE, ZONE_SOURCE, rig_vs_real
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


def test_every_zone_beside_part_5(tmp_path, demo_config, catalogue):
    phot = H.Photometry.from_config(demo_config["rig"]["photometry"])
    rng = np.random.default_rng(0)
    mount = lambda k: [mount_scatterer(geo.object_pose(k).t)]  # noqa: E731
    bgs = {light: write_store(tmp_path, f"NOOBJECT_8inch_3x3_{light}", mount, phot, rng) for light in ("lightoff", "lighton")}
    pairs = []
    for size in ("8inch", "4inch"):
        for light in ("lightoff", "lighton"):
            scene = lambda k, size=size: mount(k) + [object_scatterer(catalogue["square"], size, geo.object_pose(k))]  # noqa: E731
            obj = write_store(tmp_path, f"square_{size}_3x3_{light}", scene, phot, rng)
            pairs.append((obj, bgs[light]))
    table = rig_vs_real(pairs, tmp_path / "rig_vs_real.png", tmp_path / "rig_vs_real.csv")
    df = pd.read_csv(tmp_path / "rig_vs_real.csv")
    assert len(df) == len(table) == 4 + 3 + 18
    rig = df[df.source == ZONE_SOURCE].sort_values(["zone_row", "zone_col"])
    real = df[df.source == REAL_ZONE_SOURCE].sort_values(["zone_row", "zone_col"])
    np.testing.assert_allclose(real.mean_counts.to_numpy().reshape(3, 3), REAL_ZONE_MEANS)
    np.testing.assert_allclose(rig.real_mean_counts.to_numpy().reshape(3, 3), REAL_ZONE_MEANS)
    # the rig's zone means are the object sets' histograms averaged over locations, repeats and bins
    direct = np.mean([open_set(p).histograms[:].astype(float).mean(axis=(0, 1, -1)) for p, _ in pairs], axis=0)
    np.testing.assert_allclose(rig.mean_counts.to_numpy().reshape(3, 3), direct, rtol=1e-9)
    assert (tmp_path / "rig_vs_real.png").stat().st_size > 20_000
