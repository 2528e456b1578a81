"""Feature stores and the benchmark dataset built from them."""

import numpy as np
import pandas as pd
import pytest

from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.io.features import Features, read_features, write_features
from denali_pipe.train.dataset import build_dataset, location_labels, read_dataset, write_dataset


def _features(seed, locations=(0, 5, 9), crop=77, bins=51):
    rng = np.random.default_rng(seed)
    L = len(locations)
    return Features(rng.normal(size=(L, 3, 3, 3, bins)).astype(np.float32), np.array(locations), np.zeros((L, 3), int), crop)


def test_features_round_trip(tmp_path):
    f = _features(1)
    cs = parse_set_name("A_4inch_3x3_lighton")
    write_features(tmp_path / "A.zarr", cs, f, "NOOBJECT_8inch_3x3_lighton")
    cs2, g = read_features(tmp_path / "A.zarr")
    assert cs2 == cs and g.crop_start == 77
    assert np.array_equal(g.values, f.values) and np.array_equal(g.locations, f.locations)


def test_read_features_names_a_bad_file(tmp_path):
    (tmp_path / "junk.zarr").mkdir()
    with pytest.raises(ValueError, match="junk.zarr"):
        read_features(tmp_path / "junk.zarr")


def _write(tmp_path, name, **kw):
    p = tmp_path / f"{name}.zarr"
    write_features(p, parse_set_name(name), _features(hash(name) % 100, **kw), "NOOBJECT_8inch_3x3_lighton")
    return p


def test_dataset_rows_follow_the_reference_order_and_carry_labels(tmp_path, catalogue):
    names = ["circle_8inch_3x3_lighton", "A_4inch_3x3_lightoff", "1_4inch_3x3_lighton"]
    paths = [_write(tmp_path, n) for n in names]
    labels = {0: (1.0, 0.2), 5: (1.1, 0.3), 9: (1.2, 0.4)}
    x, samples = build_dataset(paths, catalogue, labels)
    assert x.shape == (27, 3, 3, 51)
    assert samples["set"].tolist() == [n for n in sorted(names) for _ in range(9)]
    first = samples[samples["set"] == "1_4inch_3x3_lighton"]
    assert first["location"].tolist() == [0, 0, 0, 5, 5, 5, 9, 9, 9] and first["repeat"].tolist() == [0, 1, 2] * 3
    assert samples.loc[samples["location"] == 5, ["x", "y"]].drop_duplicates().values.tolist() == [[1.1, 0.3]]
    assert set(samples["class"]) == {"1", "A", "circle"}
    # the first sample is the first set's first location, first repeat
    _, f = read_features(tmp_path / "1_4inch_3x3_lighton.zarr")
    assert np.array_equal(x[0], f.values[0, 0])

    write_dataset(x, samples, tmp_path / "d.zarr", tmp_path / "d.parquet", 77)
    x2, s2, crop = read_dataset(tmp_path / "d.zarr", tmp_path / "d.parquet")
    assert np.array_equal(x2, x) and crop == 77
    pd.testing.assert_frame_equal(s2, samples)


def test_dataset_refuses_mismatches(tmp_path, catalogue):
    a = _write(tmp_path, "A_4inch_3x3_lighton")
    b = _write(tmp_path, "B_4inch_3x3_lighton", bins=40)
    labels = {0: (1.0, 0.2), 5: (1.1, 0.3), 9: (1.2, 0.4)}
    with pytest.raises(ValueError, match="differ from the other sets"):
        build_dataset([a, b], catalogue, labels)
    with pytest.raises(ValueError, match="no location label .* \\[9\\]"):
        build_dataset([a], catalogue, {0: (1.0, 0.2), 5: (1.1, 0.3)})
    v = _write(tmp_path, "generalization1white_4inch_3x3_lighton")
    with pytest.raises(ValueError, match="not a base object"):
        build_dataset([v], catalogue, labels)
    with pytest.raises(ValueError, match="'A' is not a nonrr object"):
        build_dataset([a, v], catalogue, labels, variant="nonrr")


def test_a_variant_dataset_holds_its_variant_with_the_base_class(tmp_path, catalogue):
    labels = {0: (1.0, 0.2), 5: (1.1, 0.3), 9: (1.2, 0.4)}
    paths = [_write(tmp_path, n) for n in ("generalization1white_4inch_3x3_lighton", "generalization1cardstock_8inch_3x3_lightoff")]
    x, samples = build_dataset(paths, catalogue, labels, variant="nonrr")
    assert x.shape == (18, 3, 3, 51) and set(samples["class"]) == {"1"}
    assert sorted(set(samples["object"])) == ["generalization1cardstock", "generalization1white"]
    with pytest.raises(ValueError, match="lacks the columns"):
        location_labels(pd.DataFrame({"location": [0], "x": [1.0]}))
