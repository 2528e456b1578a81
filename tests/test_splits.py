"""Splits: determinism, the reference's draws, and no group crossing train/test."""

import json

import numpy as np
import pandas as pd
import pytest
from conftest import ASSETS

from denali_pipe.core.objects import BASE_SHAPES
from denali_pipe.core.splits import SPLITS, held_out_groups, make_split, validation_split
from denali_pipe.train.cells import is_ill_posed


def _samples(classes=BASE_SHAPES, n_loc=10, repeats=3):
    rows = []
    grid = {k: (1.0 + 0.0365 * (k % 10), 0.2 + 0.0365 * (k // 10)) for k in range(n_loc)}
    for cls in sorted(classes):
        for size in ("4inch", "8inch"):
            for light in ("lightoff", "lighton"):
                for k in range(n_loc):
                    for r in range(repeats):
                        rows.append(
                            {
                                "set": f"{cls}_{size}_3x3_{light}",
                                "class": cls,
                                "size": size,
                                "light": light,
                                "location": k,
                                "repeat": r,
                                "x": grid[k][0],
                                "y": grid[k][1],
                            }
                        )
    return pd.DataFrame(rows).sort_values(["set", "location", "repeat"], kind="stable").reset_index(drop=True)


@pytest.fixture(scope="module")
def samples():
    return _samples()


def _groups(df, rows, cols):
    return set(map(tuple, df.iloc[rows][list(cols)].to_numpy().tolist()))


@pytest.mark.parametrize("split", SPLITS)
def test_splits_partition_and_are_deterministic(samples, split):
    a = make_split(samples, split, 42)
    b = make_split(samples, split, 42)
    assert np.array_equal(a.train, b.train) and np.array_equal(a.test, b.test)
    assert len(np.intersect1d(a.train, a.test)) == 0
    assert len(a.train) + len(a.test) == len(samples)
    c = make_split(samples, split, 43)
    if split != "size_held_out":  # the only split without a random draw
        assert not np.array_equal(a.test, c.test)


@pytest.mark.parametrize(
    "split, cols",
    [("repeats_grouped", ("set", "location")), ("location_held_out", ("location",)), ("shape_held_out", ("class",)), ("size_held_out", ("size",))],
)
def test_held_out_groups_never_cross(samples, split, cols):
    for seed in (42, 7):
        s = make_split(samples, split, seed)
        assert not _groups(samples, s.train, cols) & _groups(samples, s.test, cols)


def test_random_split_mixes_repeats_and_is_stratified(samples):
    y = samples["class"].map({c: i for i, c in enumerate(sorted(BASE_SHAPES))}).to_numpy()
    s = make_split(samples, "random", 42, stratify=y)
    assert len(s.test) == int(np.ceil(0.3 * len(samples)))
    assert _groups(samples, s.train, ("set", "location")) & _groups(samples, s.test, ("set", "location"))  # the leak the paper has
    share = np.bincount(y[s.test], minlength=30) / np.bincount(y, minlength=30)
    assert np.allclose(share, 0.3, atol=0.02)


def test_fractions(samples):
    assert len(set(samples.iloc[make_split(samples, "shape_held_out", 42).test]["class"])) == 9
    assert len(set(samples.iloc[make_split(samples, "location_held_out", 42).test]["location"])) == 3
    s = make_split(samples, "size_held_out", 42)
    assert set(samples.iloc[s.train]["size"]) == {"4inch"} and set(samples.iloc[s.test]["size"]) == {"8inch"}
    n_groups = samples.groupby(["set", "location"]).ngroups
    assert samples.iloc[make_split(samples, "repeats_grouped", 42).test].groupby(["set", "location"]).ngroups == int(0.3 * n_groups)


def test_reference_shape_draw():
    _, test = held_out_groups(BASE_SHAPES, 42)
    assert sorted(test) == sorted(["6", "7", "A", "E", "U", "V", "circle", "square", "widerectangle"])


@pytest.mark.skipif(not (ASSETS / "tag1_positions.json").exists(), reason="release assets not beside the repository")
def test_reference_location_draw_from_the_release_labels():
    pos = json.loads((ASSETS / "tag1_positions.json").read_text())
    rows = [{"set": "A_4inch_3x3_lighton", "class": "A", "size": "4inch", "location": int(k[5:-5]), "repeat": 0, "x": v[0], "y": v[1]} for k, v in pos.items()]
    df = pd.DataFrame(rows).sort_values("location").reset_index(drop=True)
    s = make_split(df, "location_held_out", 42)
    assert sorted(df.iloc[s.test]["location"]) == [
        1,
        2,
        4,
        7,
        10,
        16,
        17,
        20,
        23,
        25,
        32,
        34,
        39,
        41,
        44,
        49,
        52,
        53,
        57,
        58,
        59,
        64,
        75,
        80,
        81,
        91,
        92,
        93,
        95,
        97,
    ]


@pytest.mark.parametrize("split", SPLITS)
def test_validation_is_carved_from_train_like_the_test(samples, split):
    s = make_split(samples, split, 42)
    v = validation_split(samples, s.train, split, 42, 0.2)
    assert set(v.train) | set(v.test) == set(s.train) and not set(v.train) & set(v.test)
    cols = {"repeats_grouped": ("set", "location"), "location_held_out": ("location",), "shape_held_out": ("class",), "size_held_out": ("set", "location")}.get(
        split
    )
    if cols:
        assert not _groups(samples, v.train, cols) & _groups(samples, v.test, cols)


def test_ill_posed_pairs():
    assert is_ill_posed("shape_held_out", "shape") and is_ill_posed("size_held_out", "size")
    assert not is_ill_posed("size_held_out", "shape") and not is_ill_posed("random", "size")


def test_bad_input_is_refused(samples):
    with pytest.raises(ValueError, match="unknown split"):
        make_split(samples, "by_colour", 42)
    with pytest.raises(ValueError, match="lacks the columns"):
        make_split(samples.drop(columns=["x"]), "random", 42)
    with pytest.raises(ValueError, match="needs both 4inch and 8inch"):
        make_split(samples[samples["size"] == "4inch"], "size_held_out", 42)
    with pytest.raises(ValueError, match="at least 2 groups"):
        make_split(samples[samples["class"] == "A"], "shape_held_out", 42)
