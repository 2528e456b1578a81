"""The `paper` protocol's data path (train/paper_inputs.py) against the
release's own benchmark code (../shared/reference/benchmark, MIT), imported
here by path and nowhere in the project.

One tiny raw tree in the release layout is read both ways: by the reference
(`DataSet.from_raw_captures` + `query_data` as its `build_query` calls it, its
array datasets' transform, its splits) and by this project (ingest into
stores, `paper_samples`, `transform`, `training.partition`). Sample order,
labels, transformed inputs and the train and test indices must be identical.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import REFERENCE, reference_module

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, parse_set_name
from denali_pipe.ingest.capture_set import ingest_release
from denali_pipe.train.cells import Cell
from denali_pipe.train.paper_inputs import paper_samples, transform
from denali_pipe.train.training import partition, targets

pytestmark = pytest.mark.skipif(not (REFERENCE / "main_table" / "data.py").exists(), reason="the release's benchmark code is not present")

# ASCII order puts digits before capitals before lower case; the 8x8 set, the
# held-out variant and the background are in the tree for the query to leave out.
OBJECTS = ("circle", "A", "1")
BASE_SETS = [f"{o}_{s}_3x3_{li}" for o in OBJECTS for s in ("8inch", "4inch") for li in ("lighton", "lightoff")]
OTHER_SETS = ["A_8inch_8x8_lighton", "generalization1white_4inch_3x3_lighton", "NOOBJECT_4inch_3x3_lighton"]
# capture (store) order is not location order: the rig's metadata.json lists a serpentine
LOCATIONS = [40, 12, 0, 7, 3]
REPEATS = 3
SEEDS = (42, 43)
REF_KEY = {"location": "locations", "shape": "objects", "size": "sizes"}


@pytest.fixture(scope="module")
def tree(tmp_path_factory, catalogue):
    """(raw tree, tag1_positions.json, labels, benchmark stores): random counts
    of every set, half with a metadata.json listing LOCATIONS in capture order."""
    root = tmp_path_factory.mktemp("paper")
    raw, stores = root / "raw", root / "store"
    rng = np.random.default_rng(7)
    benchmark = []
    for i, name in enumerate(BASE_SETS + OTHER_SETS):
        cs = parse_set_name(name)
        folder = raw / f"{name}{FOLDER_SUFFIX}"
        (folder / "spad_histogram").mkdir(parents=True)
        n = 8 if cs.resolution == "8x8" else 3
        for k in LOCATIONS:
            scale = rng.uniform(20, 5000, size=(1, n, n, 128))
            np.save(folder / "spad_histogram" / f"{k:03d}.npy", rng.poisson(scale, size=(REPEATS, n, n, 128)).astype(np.int32))
        if i % 2:
            (folder / "metadata.json").write_text(json.dumps({"locations": LOCATIONS}))
        store = stores / f"{name}.zarr"
        ingest_release(folder, store, None if cs.is_background else catalogue[cs.object])
        # the benchmark's sets, as the workflow picks them (common.smk's benchmark_sets)
        if cs.resolution == "3x3" and not cs.is_background and catalogue[cs.object].variant == "base":
            benchmark.append(store)
    labels = {k: (float(x), float(y)) for k, x, y in zip(LOCATIONS, rng.uniform(0.9, 1.3, 5), rng.uniform(0.16, 0.51, 5))}
    positions = root / "tag1_positions.json"
    positions.write_text(json.dumps({f"frame{k}_tag1": [x, y, 0.35] for k, (x, y) in labels.items()}))
    return raw, positions, labels, benchmark


@pytest.fixture(scope="module")
def ours(tree, catalogue):
    _, _, labels, stores = tree
    return paper_samples(stores, catalogue, labels)


@pytest.fixture(scope="module")
def theirs(tree):
    """The reference's query, exactly as its `build_query` makes it, and its data module."""
    raw, positions, _, _ = tree
    data = reference_module("main_table.data")
    query = data.DataSet.from_raw_captures(raw).query_data(
        capture_resolutions=["3x3"],
        average_spad_histograms=False,
        location_mapping=data.load_capture_number_to_location_mapping(positions),
        included_objects=data.BASE_OBJECTS,
    )
    return query, data


def test_sample_order(ours, theirs):
    _, samples = ours
    query, _ = theirs
    assert len(samples) == len(query["names"]) == len(BASE_SETS) * len(LOCATIONS) * REPEATS
    assert [f"{s}{FOLDER_SUFFIX}" for s in samples["set"]] == query["names"]
    assert samples["location"].tolist() == query["capture_numbers"]
    assert samples["object"].tolist() == query["objects"] and samples["light"].tolist() == query["lightings"]


@pytest.mark.parametrize("task", ["location", "shape", "size"])
def test_labels(ours, theirs, task):
    _, samples = ours
    query, _ = theirs
    y, classes = targets(samples, task)
    if task == "location":
        # the reference's RegressionArrayDataset holds float32 metres
        assert y.dtype == np.float32 and np.array_equal(y, np.asarray(query["locations"], dtype=np.float32))
    else:
        from sklearn.preprocessing import LabelEncoder

        encoder = LabelEncoder().fit(query[REF_KEY[task]])
        assert classes == list(encoder.classes_)
        assert np.array_equal(y, encoder.transform(query[REF_KEY[task]]))


@pytest.mark.parametrize("norm", ["raw", "log_z"])
def test_inputs_after_the_transform(ours, theirs, norm):
    x, _ = ours
    query, data = theirs
    log = norm == "log_z"
    ds = data.RegressionArrayDataset(query["spad_histograms"], query["locations"], meta={}, log_transform=log, normalize=log)
    xt, stats = transform(x, norm)
    assert xt.dtype == ds.X.dtype == np.float32 and xt.shape == ds.X.shape == (len(x), 3, 3, 128)
    assert np.array_equal(xt, ds.X)  # bit for bit
    if log:
        assert stats == (ds.normalization_stats.mean, ds.normalization_stats.std)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("task", ["location", "shape", "size"])
def test_train_and_test_indices(ours, theirs, task, seed):
    """The main table's split (regression a plain shuffle, classification
    stratified), with the seed as the reference's random_state."""
    _, samples = ours
    query, data = theirs
    y, _ = targets(samples, task)
    split, validation = partition(samples, y, Cell("cnn1d", task, "random", "3x3", "paper", seed), validation_fraction=0.2)
    if task == "location":
        ref = data.random_split(len(query["names"]), random_state=seed)
    else:
        ref = data.stratified_split(query[REF_KEY[task]], random_state=seed)
    assert validation is None
    assert np.array_equal(split.train, np.sort(ref.train_indices)) and np.array_equal(split.test, np.sort(ref.eval_indices))


@pytest.mark.parametrize("seed", SEEDS)
def test_grouped_split_indices(ours, theirs, seed):
    """The release's generalisation code computes one split itself, its
    random_grouped (the repeats of a capture together); its others come from
    lists stored in its checkpoints (tests/test_splits.py draws those)."""
    _, samples = ours
    query, _ = theirs
    ref_test = reference_module("generalization.splits")._split_random_grouped(query, 0.3, seed)
    y, _ = targets(samples, "location")
    split, _ = partition(samples, y, Cell("cnn1d", "location", "repeats_grouped", "3x3", "paper", seed), validation_fraction=0.2)
    assert np.array_equal(split.test, np.sort(ref_test))
    assert np.array_equal(split.train, np.setdiff1d(np.arange(len(samples)), ref_test))


def test_bad_input_is_refused(tree, catalogue, tmp_path):
    _, _, labels, stores = tree
    with pytest.raises(ValueError, match=r"no location label .* \[40\]"):
        paper_samples(stores, catalogue, {k: v for k, v in labels.items() if k != 40})
    with pytest.raises(ValueError, match="not a italic object"):
        paper_samples(stores, catalogue, labels, variant="italic")
    with pytest.raises(ValueError, match="unknown normalisation"):
        transform(np.zeros((2, 3, 3, 128)), "log")
