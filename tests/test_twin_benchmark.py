"""Cost vs fidelity of the twin renderers: scene sampling, Pareto front, a small run, the figure."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from denali_pipe.core.geometry import PAPER_TIME_AXIS
from denali_pipe.report.render_benchmark import plot_render_benchmark
from denali_pipe.twin.benchmark import SCENES_PER_OBJECT, benchmark_scenes, pareto_front, run_benchmark
from denali_pipe.twin.layout import load_calibration, nominal_scene

LOCATIONS = (0, 9, 27, 55, 72, 99)
AXIS = PAPER_TIME_AXIS


def test_pareto_front():
    cost = np.array([1.0, 2.0, 3.0, 0.5, 2.0])
    error = np.array([0.1, 0.05, 0.2, 0.3, 0.1])
    assert pareto_front(cost, error).tolist() == [True, True, False, True, False]


def test_scenes_are_fixed_and_grouped(catalogue):
    specs = [catalogue[n] for n in ("A", "1", "circle")]
    scenes = benchmark_scenes(specs, ["4inch", "8inch"], list(LOCATIONS), 10, seed=5)
    assert scenes == benchmark_scenes(specs, ["4inch", "8inch"], list(LOCATIONS), 10, seed=5)
    assert len(scenes) == 10
    groups = [scenes[i : i + SCENES_PER_OBJECT] for i in range(0, 10, SCENES_PER_OBJECT)]
    for g in groups:
        assert len({(s.spec.name, s.size) for s in g}) == 1  # one object and size per group
        assert len({s.location for s in g}) == len(g)  # distinct locations
    assert len({(s.spec.name, s.size) for s in scenes}) == 3
    assert {s.size for s in benchmark_scenes(specs, ["8inch"], list(LOCATIONS), 4, 5)} == {"8inch"}
    with pytest.raises(ValueError, match="no scene"):
        benchmark_scenes(specs, ["4inch"], [], 4, 5)


def test_small_benchmark_and_figure(catalogue, tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps(nominal_scene(LOCATIONS)))
    settings = {
        "wall_albedo": 1.0, "object_albedo": 0.5, "table": False, "table_albedo": 0.5,
        "footprint": {"film": 8, "scale": 1.0}, "analytic": {"samples": 40},
        "mitransient": {"variant": "auto", "spp": 100, "max_depth": 3},
        "benchmark": {"n_scenes": 3, "reference_spp": 4000, "paper_spp": 40, "footprint_spp": [100, 1000]},
    }  # fmt: skip
    summary, per_scene = run_benchmark(load_calibration(path), [catalogue["A"]], ["8inch"], settings, AXIS, seed=1)
    assert list(summary.configuration) == ["paper", "paper, footprint pixels", "footprint 100", "footprint 1k", "analytic"]
    # the paper's block reads the centre zone only; every other configuration all 9 zones of 3 scenes
    assert len(per_scene) == 3 + 4 * 9 * 3 and per_scene.error_nl2.notna().all()
    s = summary.set_index("configuration")
    assert s.loc["paper", "pixels"] == 64 and s.loc["paper, footprint pixels", "pixels"] > 30 and s.loc["footprint 1k", "pixels"] == 64
    assert (s.loc[["paper, footprint pixels", "footprint 100", "footprint 1k", "analytic"], "n_zones"] == 9).all() and s.loc["paper", "n_zones"] == 1
    zones = [f"error_zone_{r}{c}" for r in range(3) for c in range(3)]
    assert (s.loc["analytic", zones] < 0.03).all() and np.isnan(s.loc["paper", "error_zone_00"])
    assert s.loc["analytic", "error_nl2"] == pytest.approx(s.loc["analytic", zones].mean())
    assert s.loc["footprint 1k", "error_nl2"] < s.loc["footprint 100", "error_nl2"]  # more samples, less noise
    assert s.loc["analytic", "error_nl2"] < 0.03 and s.loc["analytic", "correlation_min"] > 0.99
    assert s.loc["paper", "speedup_vs_paper"] == 1.0 and s.pareto.any()
    png = tmp_path / "render_benchmark.png"
    plot_render_benchmark(summary, png)
    assert png.stat().st_size > 10_000
    back = pd.read_csv(png.with_suffix(".csv"))
    assert list(back.configuration) == list(summary.configuration)


def test_dag_selection(catalogue):
    from denali_pipe.core.capture_sets import expected_sets
    from denali_pipe.twin.selection import fig18_sets, twin_pairs

    cfg = {"objects": ["A", "generalization1italic"], "sizes": ["4inch", "8inch"], "resolutions": ["3x3", "8x8"], "lightings": ["lighton", "lightoff"]}
    assert twin_pairs(catalogue, cfg) == [("A", "4inch"), ("A", "8inch"), ("generalization1italic", "8inch")]
    sets = expected_sets(catalogue, cfg)
    picks = fig18_sets(sets, 2, seed=3)
    assert picks == fig18_sets(sets, 2, seed=3) and len(picks) == 2
    assert all(s.resolution == "3x3" and s.light_on and not s.is_background for s in picks)
    assert len(fig18_sets(sets, 10, seed=3)) == 3
    with pytest.raises(ValueError, match="light-on 3x3"):
        fig18_sets(expected_sets(catalogue, {**cfg, "resolutions": ["8x8"]}), 2, seed=3)


def test_centre_block():
    from denali_pipe.core.geometry import WALL
    from denali_pipe.twin.benchmark import centre_block
    from denali_pipe.twin.layout import pixel_centres

    m = centre_block(WALL, 64, WALL.centre, 8)
    assert m.sum() == 64 and m[28:36, 28:36].all()
    corner = WALL.corners()[0]  # bottom-left: the block is clipped into the film
    assert centre_block(WALL, 64, corner, 8)[:8, :8].all()
    off = pixel_centres(WALL, 64)[10, 40]  # on a pixel centre: it is one of the block's middle four
    m = centre_block(WALL, 64, off, 8)
    rows, cols = np.flatnonzero(m.any(axis=1)), np.flatnonzero(m.any(axis=0))
    assert m.sum() == 64 and 10 in rows[3:5] and 40 in cols[3:5]
