"""Conditions: which samples each keeps, the quadrants' definition, when a
task is ill-posed under one, and `denali train` training within one."""

import json
import re

import numpy as np
import pandas as pd
import pytest

from denali_pipe.cli import main
from denali_pipe.core import geometry as geo
from denali_pipe.train.conditions import (
    ALL,
    ATTRIBUTES,
    CONDITION_GROUPS,
    GROUP_OF,
    PATTERN,
    TABLES,
    condition_mask,
    condition_view,
    ill_posed,
    table_conditions,
)
from denali_pipe.train.dataset import write_dataset
from denali_pipe.train.jitter import centre_zone, jitter

OBJECTS = {"1": ("1", "number"), "7": ("7", "number"), "A": ("A", "letter"), "circle": ("circle", "shape")}


@pytest.fixture(scope="module")
def samples():
    """Every object, size and lighting at every gantry location, one repeat."""
    rows = [
        {"set": f"{o}_{size}_3x3_{light}", "object": o, "class": cls, "type": typ, "size": size, "light": light, "location": k, "repeat": 0}
        for o, (cls, typ) in OBJECTS.items() for size in ("4inch", "8inch") for light in ("lightoff", "lighton") for k in range(geo.N_LOCATIONS)
    ]  # fmt: skip
    frame = pd.DataFrame(rows)
    xy = geo.tag1_position(frame["location"].to_numpy())
    return frame.assign(x=xy[:, 0], y=xy[:, 1])


def test_attribute_conditions_keep_exactly_their_samples(samples):
    assert condition_mask(samples, ALL).all()
    for condition, (column, value) in ATTRIBUTES.items():
        assert np.array_equal(condition_mask(samples, condition), (samples[column] == value).to_numpy()), condition
    assert condition_mask(samples, "letters").sum() == len(samples) // 4


def test_quadrants_are_opposite_corners_of_the_grid_by_location_index(samples):
    front = set(samples.location[condition_mask(samples, "front_quadrant")])
    back = set(samples.location[condition_mask(samples, "back_quadrant")])
    assert len(front) == len(back) == geo.N_LOCATIONS // 4 and not front & back
    assert 0 in front and geo.N_LOCATIONS - 1 in back  # the gantry's first and last locations
    _, col_f = geo.gantry_row_col(np.array(sorted(front)))
    _, col_b = geo.gantry_row_col(np.array(sorted(back)))
    assert set(col_f) == set(col_b)  # the same columns: they differ only in the rows
    # front is the half nearer the relay wall (on our drawing; the definition holds on any positions)
    assert geo.wall_distance(geo.tag1_position(np.array(sorted(front)))).max() < geo.wall_distance(geo.tag1_position(np.array(sorted(back)))).min()


def test_every_condition_name_matches_the_wildcard_pattern_and_nothing_else():
    for name in [*GROUP_OF, "jitter0ps", "jitter600ps"]:
        assert re.fullmatch(PATTERN, name), name
    for name in ("none", "jitter", "jitter50", "8inch_x", "random"):
        assert not re.fullmatch(PATTERN, name), name
    for _, conditions in TABLES.values():
        assert set(conditions) <= set(GROUP_OF) and conditions[0] == ALL


def test_table_conditions_keep_the_baseline_and_the_groups_asked_for():
    assert table_conditions("table7", ["location", "object_type"]) == ("shape", [ALL, "front_quadrant", "back_quadrant"])
    task, conditions = table_conditions("table9", list(CONDITION_GROUPS))
    assert (task, tuple(conditions)) == TABLES["table9"]
    with pytest.raises(ValueError, match="unknown condition groups"):
        table_conditions("table8", ["colour"])


def test_unknown_condition(samples):
    with pytest.raises(ValueError, match="unknown condition 'blue'"):
        condition_mask(samples, "blue")


def test_ill_posed_conditions(samples):
    assert ill_posed(samples, "shape", "8inch") is None and ill_posed(samples, "location", "front_quadrant") is None
    assert ill_posed(samples, "size", "8inch") == "condition 8inch leaves one size class (8inch)"
    assert ill_posed(samples, "shape", "letters") == "condition letters leaves one shape class (A)"
    assert ill_posed(samples, "shape", "numbers") is None  # two numbers
    dark = samples[samples.light == "lightoff"]
    assert ill_posed(dark, "location", "light_on") == "condition light_on keeps no sample"
    assert ill_posed(dark, "location", "jitter100ps") == "condition jitter100ps keeps no sample"


def test_condition_view(samples, time_axis):
    x = np.random.default_rng(0).normal(size=(len(samples), 3, 3, 20)).astype(np.float32)
    same, kept = condition_view(x, samples, "shape", ALL)
    assert same is x and kept.equals(samples)
    back, kept = condition_view(x, samples, "size", "back_quadrant")
    mask = condition_mask(samples, "back_quadrant")
    assert np.array_equal(back, x[mask]) and list(kept.index) == list(range(mask.sum()))
    blurred, kept = condition_view(x, samples, "location", "jitter100ps", time_axis)
    lit = (samples.light == "lighton").to_numpy()
    assert blurred.shape == (lit.sum(), 1, 1, 20) and (kept.light == "lighton").all()
    assert np.array_equal(blurred, jitter(centre_zone(x[lit]), 100, time_axis))
    with pytest.raises(ValueError, match="jitter100ps blurs in ps: it needs the captures' time axis"):
        condition_view(x, samples, "location", "jitter100ps")
    with pytest.raises(ValueError, match="size is ill-posed: condition 4inch leaves one size class"):
        condition_view(x, samples, "size", "4inch")
    with pytest.raises(ValueError, match="3x3 histograms"):
        condition_view(np.zeros((len(samples), 8, 8, 20), np.float32), samples, "shape", "jitter0ps", time_axis)


def test_denali_train_trains_and_tests_within_the_condition(tmp_path, samples, caplog, demo_config):
    sub = samples[samples.location % 10 < 2].reset_index(drop=True)  # 20 locations: a small, quick cell
    x = np.random.default_rng(1).poisson(5.0, size=(len(sub), 3, 3, 16)).astype(np.float32)
    write_dataset(x, sub, tmp_path / "3x3.zarr", tmp_path / "3x3.parquet", crop_start=70)
    hyper = json.dumps({"lr": 1e-3, "epochs": 1, "batch_size": 64, "norm": "raw"})

    def train(task, condition):
        cell = {"model": "cnn1d", "task": task, "split": "random", "resolution": "3x3", "condition": condition, "protocol": "clean", "seed": 42}
        out = tmp_path / task / condition
        args = [
            "train",
            str(tmp_path / "3x3.zarr"),
            "--table",
            str(tmp_path / "3x3.parquet"),
            "--cell",
            json.dumps(cell),
            "--hyper",
            hyper,
            "--factory",
            "denali_pipe.train.models:cnn1d",
        ]
        if condition.startswith("jitter"):  # as the rule passes it: to the jitter cells alone
            args += ["--time-axis", json.dumps(demo_config["sensor"]["time_axis"])]
        return main([*args, "--validation-fraction", "0.2", "--outdir", str(out)]), out

    rc, out = train("shape", "light_off")
    assert rc == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["cell"]["condition"] == "light_off" and m["n_train"] + m["n_validation"] + m["n_test"] == (sub.light == "lightoff").sum()
    rc, out = train("shape", "jitter50ps")
    assert rc == 0 and json.loads((out / "metrics.json").read_text())["input_shape"] == [1, 1, 16]
    rc, out = train("size", "8inch")
    assert rc == 1 and not out.exists()
    assert f"{tmp_path / '3x3.parquet'}: size is ill-posed: condition 8inch leaves one size class (8inch)" in caplog.text
