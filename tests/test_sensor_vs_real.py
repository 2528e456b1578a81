"""The fitted sensor on scenes (experiments.sensor_vs_real, sensor.zones):
the zones' rays tile their field; a synthetic scene rendered through a known
sensor is fitted back to its albedos at the shot-noise floor; on the real
pyramid and tall block (../shared) the render puts every zone's return where
the captures do, the late floor holds, and the sensor's response alone
explains more than the render's radiometry; the command says what it could
not render."""

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import trimesh
from conftest import REPO
from scipy.stats import exponnorm

from denali_pipe.experiments import sensor_vs_real as svr
from denali_pipe.sensor.captures import BINS, SWEEP, ZONES, Captures, read_captures
from denali_pipe.sensor.fit import CENTRE, SensorFit, Timing, from_record, record, scores
from denali_pipe.sensor.response import counts_from_rates, pulse_area, pulse_offsets
from denali_pipe.sensor.zones import COLUMN_CENTRES, COLUMN_WIDTHS, ROW_CENTRES, ROW_HEIGHT, plane_view, zone_rays

REAL = REPO.parent / "shared" / "real-tmf8820"
CYCLES = 4.0e6


def test_the_zones_tile_the_field_and_a_plane_is_seen_by_all_nine():
    dirs, omega = zone_rays(8)
    assert dirs.shape == (ZONES, 64, 3) and np.allclose(np.linalg.norm(dirs, axis=-1), 1)
    x0, x1 = (COLUMN_CENTRES - COLUMN_WIDTHS / 2).min(), (COLUMN_CENTRES + COLUMN_WIDTHS / 2).max()
    y0, y1 = (ROW_CENTRES - ROW_HEIGHT / 2).min(), (ROW_CENTRES + ROW_HEIGHT / 2).max()
    assert omega.sum() == pytest.approx((np.sin(x1) - np.sin(x0)) * (y1 - y0), rel=1e-3)
    # zone 0 looks to +x +y, zone 8 to -x -y (the firmware's order); the centre along the axis
    assert dirs[0].mean(0)[0] > 0.1 and dirs[0].mean(0)[1] > 0.1 and dirs[8].mean(0)[0] < -0.1 and dirs[8].mean(0)[1] < -0.1
    geometric, mean_range = plane_view(8)
    assert geometric[CENTRE] == pytest.approx(omega[CENTRE].sum(), rel=0.01) and (geometric < omega.sum(-1)).all()
    assert mean_range[CENTRE] == pytest.approx(1.0, abs=0.01) and (mean_range[[0, 2, 6, 8]] > mean_range[CENTRE] + 0.02).all()


def box(extents, centre) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))


@pytest.fixture
def scene_stl(tmp_path):
    # a table 2 m square, its top at z = 0, and a block 6 x 6 x 10 cm on it
    path = tmp_path / "block.stl"
    trimesh.util.concatenate([box((2, 2, 0.1), (0, 0, -0.05)), box((0.06, 0.06, 0.1), (0.02, 0.0, 0.05))]).export(path)
    return path


def test_read_mesh_tells_the_table_from_the_object(scene_stl, tmp_path):
    mesh = svr.read_mesh(scene_stl)
    # the table's 12 triangles, and the block's base (hidden on the table's top); the block's other 10 are the object's
    assert mesh.table.sum() == 14 and (~mesh.table).sum() == 10
    assert mesh.vertices[mesh.faces[~mesh.table]][..., 2].max() == pytest.approx(0.1)
    table_only = tmp_path / "table.stl"
    box((2, 2, 0.1), (0, 0, -0.05)).export(table_only)
    with pytest.raises(ValueError, match="table.stl: every face is at or below the table's top"):
        svr.read_mesh(table_only)
    (tmp_path / "junk.stl").write_text("not a mesh")
    with pytest.raises(ValueError, match="junk.stl"):
        svr.read_mesh(tmp_path / "junk.stl")


def known_sensor() -> SensorFit:
    """A sensor whose zones' gains are constant with distance (a plane at 0.3 m returns 0.1 detections a cycle in each)."""
    u = pulse_offsets()
    cdf = lambda t: 0.93 * exponnorm.cdf(t, 0.8 / 0.4, scale=0.4) + 0.07 * exponnorm.cdf(t, 3.5 / 0.4, scale=0.4)  # noqa: E731
    pulse = cdf(u + 0.5) - cdf(u - 0.5)
    d = np.linspace(0.05, 0.4, 20)
    _, mean_range = plane_view(svr.RAYS_PER_SIDE)
    return SensorFit(
        timing=Timing(12.8, np.zeros(ZONES), 72.0 * mean_range), cycles=CYCLES, pulse=pulse / pulse_area(pulse),
        crosstalk=np.full(ZONES, 1e-5), se={}, chi2_dof=1.0, shift_sd=0.0, train_distances=d, test_distances=d[:2],
        amplitude=np.tile(0.1 * 0.09 / d[:, None] ** 2, (1, ZONES)),
    )  # fmt: skip


def synthetic_captures(fit, mesh, n=12, seed=0) -> Captures:
    """n captures from 0.3 m above the table looking down, moved over the block; object albedo 0.8, table 0.4."""
    rng = np.random.default_rng(seed)
    pose = np.tile(np.eye(4), (n, 1, 1))
    pose[:, :3, :3] = np.diag([1.0, -1.0, -1.0])
    pose[:, :3, 3] = np.column_stack([rng.uniform(-0.08, 0.08, (n, 2)), np.full(n, 0.3)])
    placeholder = Captures("synthetic", np.zeros((n, ZONES, BINS)), np.zeros((n, BINS)), pose, None)
    fine = svr.ray_returns(fit, mesh, placeholder)
    unit = svr.through_pulse(fit, fine, 0.0)
    rates = np.einsum("nzpb,p->nzb", unit, [0.8, 0.4]) + 3e-5 + svr.crosstalk_rates(fit)[None]
    hists = rng.poisson(counts_from_rates(rates, fit.cycles)).astype(float)
    return Captures("synthetic", hists, placeholder.reference, pose, None)


def test_a_rendered_scene_is_fitted_back_to_its_albedos_at_the_noise_floor(scene_stl):
    fit, mesh = known_sensor(), svr.read_mesh(scene_stl)
    captures = synthetic_captures(fit, mesh)
    assert (captures.hists.max(-1) > 1e4).all()  # every zone holds a return
    fine = svr.ray_returns(fit, mesh, captures)
    for mode in svr.MODES:
        expected, shift, albedo = svr.fit_scene(fit, captures, fine, mode)
        assert np.abs(shift).max() < 0.05
        assert (scores(captures.hists, expected)["nl2_net"] < 0.01).all()
        if mode == "render":
            np.testing.assert_allclose(albedo, [0.8, 0.4], rtol=0.02)
    # captures whose clock ran 0.4 bin late are found there
    late = dataclasses.replace(captures, hists=synthetic_captures(dataclasses.replace(fit, timing=dataclasses.replace(fit.timing, zero_bin=13.2)), mesh).hists)
    assert svr.fit_scene(fit, late, fine, "render")[1] == pytest.approx(np.full(len(late.hists), 0.4), abs=0.05)


def test_the_record_round_trips_what_the_render_reads(tmp_path):
    fit = known_sensor()
    back = from_record(json.loads(json.dumps(record(fit, pd.DataFrame({"zone": [0]}), "x"), default=float)))
    np.testing.assert_allclose(back.amplitude, fit.amplitude)
    np.testing.assert_allclose(back.timing.bins_per_metre, fit.timing.bins_per_metre)
    with pytest.raises(ValueError, match="not fitted: no real captures"):
        from_record({"status": "no real captures: x not found"})


needs_real = pytest.mark.skipif(not (REAL / SWEEP).is_file(), reason="needs ../shared/real-tmf8820 (the real TMF8820 captures)")


@pytest.fixture(scope="module")
def real_fit():
    from denali_pipe.sensor.fit import fit_sweep

    return fit_sweep(read_captures(REAL / SWEEP), held_out_every=4, min_distance_m=0.05, rounds=4)


@needs_real
@pytest.mark.parametrize("scene", ["pyramid", "tall_block"])
def test_the_real_scenes_are_rendered_where_the_captures_put_them(real_fit, scene):
    captures, mesh = read_captures(REAL / f"{scene}.npz"), svr.read_mesh(REAL / f"{scene}.stl")
    table, expected = svr.compare_scene(real_fit, captures, mesh)
    # every zone's strongest return within a bin of the measured one in most captures: 0.88-0.92 with the
    # zones' layout of sensor.zones, 0.23-0.54 with it mirrored in x, in y or both
    near = np.abs(captures.hists.argmax(-1) - expected["render"].argmax(-1)) <= 1
    assert near.mean() > 0.85
    render, free = (table[table["mode"] == m].set_index("zone") for m in svr.MODES)
    # the pile-up law keeps the late floor on scenes it was not fitted to
    assert (render["late_error"].abs() < 0.08).all() and (free["late_error"].abs() < 0.08).all()
    # the sensor's response alone (each zone's returns free in size) fits better than the render's radiometry
    assert (free["nl2_net"] < render["nl2_net"]).all() and 0.2 < render["albedo_object"].iloc[0] < 2


def test_the_command_says_what_it_could_not_render(tmp_path):
    fit_json = tmp_path / "sensor_fit.json"
    fit_json.write_text(json.dumps({"source": "x", "status": "no real captures: x not found"}))
    out = tmp_path / "out" / "sensor_vs_real.csv"
    out.parent.mkdir()
    cmd = [sys.executable, "-m", "denali_pipe.cli", "sensor-vs-real", str(tmp_path / "absent"), "--fit", str(fit_json), "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True)
    assert pd.read_csv(out)["status"].iloc[0].startswith("no fitted sensor") and out.with_suffix(".png").stat().st_size > 1_000
    fit_json.write_text(json.dumps(record(known_sensor(), pd.DataFrame({"zone": [0]}), "x"), default=float))
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    np.savez(scenes / "bust.npz", hists=np.zeros((1, ZONES, BINS)), reference=np.zeros((1, BINS)), pose=np.eye(4)[None])
    cmd[4] = str(scenes)
    subprocess.run(cmd, check=True, capture_output=True)
    table = pd.read_csv(out)
    assert table.to_dict(orient="records") == [{"scene": "bust", "status": "not rendered: no mesh bust.stl"}]
