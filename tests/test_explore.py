"""The explorer's pieces without the workflow: what a results folder lacks
and how to build it, what the controls select, the geometry, a cell's
per-location test error; and, in a real browser, the page over an empty
results folder (the full page is tested on the tiny run's outputs in
test_workflow_tiny.py)."""

import numpy as np
import pandas as pd
import plotly.graph_objects as go
import pytest
import torch
from browser import chromium, ensure_chromium, explorer, wait_for
from test_train import _cell, data  # noqa: F401 (the fixture)

from denali_pipe.core.capture_sets import CaptureSet
from denali_pipe.core.geometry import N_LOCATIONS, TimeAxis, gantry_row_col
from denali_pipe.explore.app import pick_choice, pick_set
from denali_pipe.explore.capture import Calibration, gantry_grid
from denali_pipe.explore.figures import histogram_grid, title
from denali_pipe.explore.outputs import CellChoice, dataset_paths, scan
from denali_pipe.explore.predictions import error_by_location
from denali_pipe.poses.pnp import project
from denali_pipe.train.dataset import write_dataset
from denali_pipe.train.training import Hyper, run_cell


def test_an_empty_results_folder_names_what_builds_each_output(tmp_path):
    inv = scan(tmp_path / "results")  # absent: holds nothing
    missing = {m.what: m.command for m in inv.missing()}
    assert missing == {
        "no capture stores (store/)": "snakemake --cores all results/index/captures.parquet",
        "no calibration (tag-1 positions and tracking camera)": "snakemake --cores all results/calibration/tag1_positions.parquet",
        "no sim-to-real transforms": "snakemake --cores all results/transforms.json",
        "no training cells (runs/)": "snakemake --cores all results/table5.csv",
    }


def test_a_missing_cell_names_its_target_or_why_it_is_never_trained(tmp_path):
    inv = scan(tmp_path)
    choice = CellChoice("clean", "3x3", "shape_held_out", "cnn1d", 42)
    assert inv.cell_status(choice, "location").command == "snakemake --cores all results/runs/clean/3x3/all/shape_held_out/cnn1d_location/seed42/metrics.json"
    ill_posed = inv.cell_status(choice, "shape")
    assert "never occur in training" in ill_posed.what and ill_posed.command == ""


SETS = tuple(
    CaptureSet(o, s, r, li)
    for o, s, r, li in [("A", "4inch", "3x3", "lighton"), ("A", "4inch", "8x8", "lightoff"), ("A", "8inch", "8x8", "lighton"), ("B", "8inch", "3x3", "lighton")]
)


def test_a_control_the_object_lacks_moves_to_what_it_has():
    assert pick_set(SETS, "A", "8inch", "3x3", "lighton") == SETS[2]  # no 8 in 3x3: size first, then what it has
    assert pick_set(SETS, "A", "4inch", "8x8", "lighton") == SETS[1]  # lighting last
    assert pick_set(SETS, "A", "4inch", "3x3", "lightoff") == SETS[0]
    assert pick_set(SETS, "C", "4inch", "3x3", "lighton") is None
    choices = [CellChoice("clean", "3x3", sp, m, s) for sp in ("random", "location_held_out") for m in ("cnn1d", "mlp") for s in (42, 43)]
    assert pick_choice(choices, "clean", "random", "mlp", None) == CellChoice("clean", "3x3", "random", "mlp", 42)  # lowest seed
    assert pick_choice(choices, "paper", "location_held_out", "cnn1d", 43) == CellChoice("clean", "3x3", "location_held_out", "cnn1d", 43)


def test_the_grid_keeps_calibrated_labels_and_follows_their_affine_map():
    loc = np.array([0, 9, 27, 45, 81, 99])
    row, col = gantry_row_col(loc)
    # a gantry rotated 2 deg off the drawing, with steps of 3.65 cm
    a = np.radians(2.0)
    xy = np.array([1.26, 0.47]) + np.column_stack([row, col]) @ (0.0365 * np.array([[np.sin(a), -np.cos(a)], [-np.cos(a), -np.sin(a)]]))
    labels = pd.DataFrame({"x": xy[:, 0] + [0, 1e-3, 0, 0, 0, 0], "y": xy[:, 1], "z": 0.35}, index=pd.Index(loc, name="location"))
    grid = gantry_grid(labels)
    assert len(grid) == N_LOCATIONS and grid.calibrated.sum() == len(loc)
    assert np.array_equal(grid.set_index("location").loc[loc, ["x", "y"]].to_numpy(), labels[["x", "y"]].to_numpy())
    free = grid[~grid.calibrated]
    r, c = gantry_row_col(free.location.to_numpy())
    expect = np.array([1.26, 0.47]) + np.column_stack([r, c]) @ (0.0365 * np.array([[np.sin(a), -np.cos(a)], [-np.cos(a), -np.sin(a)]]))
    assert np.abs(free[["x", "y"]].to_numpy() - expect).max() < 1e-3  # the one label off by 1 mm moves the fit by less


def test_markers_project_through_the_camera_at_the_frames_size():
    K = np.array([[460.0, 0, 320], [0, 461, 180], [0, 0, 1]])
    R, t = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0], np.array([0.1, -0.2, 1.5])
    cal = Calibration(pd.DataFrame(), K, R, t, (640, 360))
    points = np.array([[1.2, 0.4, 0.35], [0.9, 0.2, 0.34]])
    assert np.allclose(cal.pixels(points, (640, 360)), project(K, R, t, points))
    assert np.allclose(cal.pixels(points, (1280, 720)), 2 * project(K, R, t, points))  # the principal point scales too


@pytest.mark.parametrize("task, protocol", [("location", "clean"), ("shape", "clean"), ("location", "paper")])
def test_the_per_location_test_error_recombines_to_the_cells_test_metric(tmp_path, data, task, protocol):  # noqa: F811
    """On the dataset of the cell's protocol (a paper cell's is under datasets/paper/)."""
    x, samples = data
    results = tmp_path / "results"
    write_dataset(x, samples, *(results / p for p in dataset_paths("3x3", protocol)), crop_start=0)
    cell = _cell(task=task, protocol=protocol)
    result = run_cell(
        x, samples, cell, Hyper(lr=3e-3, epochs=2, batch_size=32, norm="raw"), validation_fraction=0.2, factory=f"denali_pipe.train.models:{cell.model}"
    )
    choice = CellChoice(cell.protocol, cell.resolution, cell.split, cell.model, cell.seed)
    run = results / choice.run_path(task)
    run.mkdir(parents=True)
    (run / "metrics.json").write_text(result.metrics.to_json())
    torch.save(result.state, run / "model.pt")
    error = error_by_location(scan(results), choice, task)
    test = result.metrics.test
    assert error["n"].sum() == result.metrics.n_test
    if task == "location":  # RMS distances, cm
        assert np.sqrt((error["n"] * error["value"] ** 2).sum() / error["n"].sum()) / 100 == pytest.approx(test["rmse_euclidean"], rel=1e-5)
    else:  # shares classified right, %
        assert (error["n"] * error["value"]).sum() / error["n"].sum() / 100 == pytest.approx(test["top1"], rel=1e-6)


def test_the_page_over_an_empty_results_folder_says_what_to_build(tmp_path):
    ensure_chromium()
    with explorer(tmp_path / "results", tmp_path / "explore.log") as server, chromium(tmp_path / "profile") as driver:
        driver.get(server.url)
        banner = wait_for(driver, "const e = document.getElementById('missing'); return e && e.innerText;")
        assert "snakemake --cores all results/index/captures.parquet" in banner and "snakemake --cores all results/table5.csv" in banner
        wait_for(driver, "const g = document.querySelector('#frame .js-plotly-plot'); return g && g.layout.annotations && g.layout.annotations.length;")
        frame = driver.execute_script("return document.querySelector('#frame .js-plotly-plot').layout.annotations[0].text;")
        assert frame.startswith("no capture stores")
        driver.save_screenshot(str(tmp_path / "explore_empty.png"))
        page = driver.page_source
        print(f"\nexplorer screenshot (empty results): {tmp_path / 'explore_empty.png'}")
    assert "Traceback" not in page and "Traceback" not in server.output()
    assert not (tmp_path / "results").exists()  # read only: not even created


@pytest.mark.parametrize("n", [3, 8])
def test_the_histogram_grid_is_a_valid_figure_with_a_subplot_per_zone(n):
    rng = np.random.default_rng(0)
    counts, background = rng.poisson(900, (n, n, 128)), np.full((n, n, 128), 900.0)
    axis = TimeAxis(bin_width_ps=93.0, zero_bin=16.0)
    fig = go.Figure(histogram_grid(counts, background, np.full((n, n), 71), True, axis, title("raw"), "plotly_dark"))  # plotly validates every key
    assert fig.layout[f"xaxis{(n - 1) * n + (n + 1) // 2}"].title.text == "time bin (93 ps)"  # the bin's time on the captures' axis
    assert len(fig.data) == 2 * n * n and len(fig.layout.shapes) == n * n
    last = fig.data[-2]  # the bottom-right zone's capture, on its own axes
    assert (last.xaxis, last.yaxis) == (f"x{n * n}", f"y{n * n}") and np.array_equal(last.y, counts[-1, -1])
    assert fig.layout[f"yaxis{n * n}"].type == "log" and fig.layout[f"xaxis{n * n}"].domain[1] == 1.0


def test_denali_explore_serves_results_on_localhost_8050_by_default():
    from denali_pipe.cli import build_parser
    from denali_pipe.cli.explore import cmd_explore

    args = build_parser().parse_args(["explore"])
    assert (args.func, args.results, args.host, args.port) == (cmd_explore, "results", "127.0.0.1", 8050)
