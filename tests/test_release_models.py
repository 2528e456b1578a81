"""`experiments/release_models.py`: the release's 15 networks' test parts,
inputs and scores on any tree; and parity with the release's own evaluation
code (../shared/reference/benchmark/generalization, MIT, imported here by
path and nowhere in the project) on one small tree, network by network.

The parity tree holds base sets at all 100 gantry locations, labelled with
the release's own positions (the by_location checkpoints' stored lists), so
that every split's test part is the release's; and a few italic and
non-retroreflective sets. Both sides read it as they would the release:
the reference through its raw-capture dataset and its joblib dataset, this
project through ingest, `paper_samples` and `evaluate_network`."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest
from conftest import REFERENCE, REPO, reference_module

from denali_pipe.core.capture_sets import FOLDER_SUFFIX, parse_set_name
from denali_pipe.experiments import release_models as rm
from denali_pipe.ingest.capture_set import ingest_release
from denali_pipe.io.release_weights import STATUS, WeightsStatus
from denali_pipe.train.paper_inputs import paper_samples

RELEASE = REPO.parent / "shared" / "denali-release"
GENERALISATION = REFERENCE / "generalization"
needs_shared = pytest.mark.skipif(
    not ((RELEASE / "SHA256SUMS").is_file() and (GENERALISATION / "splits.py").is_file()),
    reason="needs ../shared/denali-release (the release's checkpoints) and ../shared/reference (its evaluation code)",
)

BASE_SETS = ("1_4inch_3x3_lighton", "A_8inch_3x3_lightoff")
VARIANT_SETS = {
    "italic": ("generalization1italic_8inch_3x3_lighton", "generalizationAitalic_8inch_3x3_lightoff"),
    "nonrr": ("generalization1white_4inch_3x3_lighton", "generalization1cardstock_8inch_3x3_lightoff"),
}
VARIANT_LOCATIONS = (3, 40, 77)
# Repeats a capture: one keeps the 100-location base sets' inference to a few seconds (tests/test_paper_inputs.py
# holds the repeats' order against the reference's); the variants' two go through the reference's own flattening.
REPEATS = {"base": 1, "italic": 2, "nonrr": 2}


def samples_table(locations, objects=("1", "A"), sizes=("4inch", "8inch"), lights=("lighton",), repeats=2, xy=None) -> pd.DataFrame:
    """A sample table in the release's row order (set, location, repeat); labels on a 3.65 cm grid unless `xy` gives them."""
    rows = []
    for obj in objects:
        for size in sizes:
            for light in lights:
                for k in locations:
                    x, y = (1.0 + 0.0365 * (k % 10), 0.2 + 0.0365 * (k // 10)) if xy is None else xy[k]
                    rows += [{"set": f"{obj}_{size}_3x3_{light}", "object": obj, "class": obj, "size": size, "light": light, "location": k, "repeat": r,
                              "x": x, "y": y} for r in range(repeats)]  # fmt: skip
    return pd.DataFrame(rows).sort_values(["set", "location", "repeat"], ignore_index=True)


SPLIT_INFO = {
    "train_locations": [[1.0 + 0.0365 * (k % 10), 0.2 + 0.0365 * (k // 10)] for k in range(70)],
    "test_locations": [[1.0 + 0.0365 * (k % 10), 0.2 + 0.0365 * (k // 10)] for k in range(70, 100)],
    "train_objects": [str(i) for i in range(21)],
    "test_objects": ["A", "circle", "V"],
    "test_sizes": ["8inch"],
}
ENTRY = {"num_train_samples": 25200}


def part(strategy, samples, params=None, name="splits_loc_x"):
    entry = {**ENTRY, "split_strategy": strategy, "split_params": params or {}}
    return rm.held_out_part(rm.Network(name, "location"), samples, entry, SPLIT_INFO)


def test_by_location_takes_the_stored_test_positions_where_the_labels_are_the_releases():
    samples = samples_table(range(100))
    p = part("by_location", samples, {"n_train_locations": 70})
    assert p.note == "" and set(samples.location[p.rows]) == set(range(70, 100))
    # labels off by millimetres (a tree's own pose stage) still find their stored positions, and say so
    moved = samples.assign(x=samples.x + 0.004)
    q = part("by_location", moved, {"n_train_locations": 70})
    assert np.array_equal(q.rows, p.rows) and "within 4.0 mm" in q.note
    # part of the grid: the stored test positions it holds
    some = samples_table([5, 71, 72])
    r = part("by_location", some, {"n_train_locations": 70})
    assert set(some.location[r.rows]) == {71, 72} and "2 of the 30 stored test positions are among this tree's 3 locations" in r.note


def test_by_location_draws_the_same_share_where_the_labels_are_not_the_releases():
    # a grid shifted by 2 cm: every label is nearer another stored position than its tolerance allows
    samples = samples_table(range(25)).assign(x=lambda d: d.x + 0.02)
    p = part("by_location", samples, {"n_train_locations": 70})
    assert "not the release's positions" in p.note and "30% of this tree's locations drawn instead" in p.note
    assert samples.location[p.rows].nunique() == 25 - round(0.7 * 25)  # core.splits rounds the training share


def test_a_split_the_manifest_and_the_checkpoint_disagree_on_is_refused():
    with pytest.raises(ValueError, match="n_train_locations 80 but its checkpoint lists 70"):
        part("by_location", samples_table(range(10)), {"n_train_locations": 80})


def test_by_object_and_by_size_notes():
    samples = samples_table(range(4))
    p = part("by_object", samples, {"n_train_objects": 21})
    assert set(samples.object[p.rows]) == {"A"} and p.note == "1 of the 3 test objects are in this tree (A)"
    none = samples_table(range(4), objects=("1", "2", "3", "4"))
    q = part("by_object", none, {"n_train_objects": 21})
    assert "holds none of the 3 test objects" in q.note and none["class"][q.rows].nunique() == 1
    small = samples_table(range(4), sizes=("4inch",))
    r = part("by_size", small)
    assert len(r.rows) == 0 and r.note == "this tree holds no 8inch captures: nothing scored"


def test_random_grouped_keeps_a_captures_repeats_together_and_says_whose_draw_it_is():
    samples = samples_table(range(10), repeats=3)
    p = part("random_grouped", samples, {"test_size": 0.3})
    groups = samples.iloc[p.rows].groupby(["set", "location"]).size()
    assert (groups == 3).all() and len(groups) == int(0.3 * 40)
    assert "drawn over this tree's 120 samples (the release drew over its 36000)" in p.note


def test_a_variant_network_scores_its_variant_at_its_size():
    samples = samples_table(range(3), objects=("generalization1italic",), sizes=("4inch", "8inch"))
    p = rm.held_out_part(rm.Network("italics_loc", "location", "italic", "8inch"), samples, None, None)
    assert set(samples["size"][p.rows]) == {"8inch"} and p.note == ""


def test_inputs_are_log1p_then_the_stored_z_score_in_float32():
    x = np.array([[0.0, 1.0, -3.0, 1e4]], np.float32)
    z = rm.network_inputs(x, True, 7.1, 0.78)
    assert z.dtype == np.float32
    np.testing.assert_allclose(z, (np.log1p(np.clip(x, 0, None)) - np.float32(7.1)) / np.float32(0.78), rtol=1e-6)
    assert np.array_equal(rm.network_inputs(x, False, None, None), x)


def test_location_scores_beside_the_mean_position_with_the_correlations():
    samples = samples_table([0, 11, 22, 34, 45, 57], objects=("1",), sizes=("8inch",), lights=("lighton", "lightoff"), repeats=1)
    y = samples[["x", "y"]].to_numpy()
    out = np.column_stack([y[:, 0], y.mean(axis=0)[1] - (y[:, 1] - y.mean(axis=0)[1])])  # x exact, y mirrored
    scored = rm.Scored(rm.Network("nonrr_loc", "location", "nonrr"), rm.Part(np.arange(len(samples))), out, None, np.nan)
    rows = pd.DataFrame(rm.score_rows(scored, samples)).set_index("light")
    assert list(rows.index) == ["both", "lightoff", "lighton"] and rows.n_samples.tolist() == [12, 6, 6]
    both = rows.loc["both"]
    assert both.corr_x == pytest.approx(1.0) and both.corr_y == pytest.approx(-1.0)
    assert both.baseline == pytest.approx(np.sqrt(((y - y.mean(axis=0)) ** 2).mean())) and both.baseline_kind == rm.MEAN


def test_without_weights_every_network_says_why(tmp_path):
    (tmp_path / STATUS).write_text(WeightsStatus(False, "nowhere", "no local copy at x, and downloads are off").to_json())
    table = rm.release_models(tmp_path, {rm.BASE: None})
    assert len(table) == len(rm.NETWORKS) and (table.n_samples == 0).all()
    assert table.note.str.startswith("the release's weights are unavailable: no local copy at x").all()


# --- parity with the release's own evaluation code --------------------------------------


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """One torch thread: under `make test` the other worker has the other core, and a two-thread op waits on a busy one (4x slower here)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def tree(tmp_path_factory, catalogue):
    """(raw tree, tag1_positions.json, {dataset: (x, samples)}): random counts
    of BASE_SETS at the 100 locations, labelled with the release's positions,
    and of VARIANT_SETS at a few."""
    import torch

    root = tmp_path_factory.mktemp("release_models")
    raw, stores = root / "raw", root / "store"
    info = torch.load(RELEASE / rm.Network("splits_loc_by_location", "location").file, map_location="cpu", weights_only=False)["split_info"]
    labels = dict(enumerate(map(tuple, info["train_locations"] + info["test_locations"])))
    positions = root / "tag1_positions.json"
    positions.write_text(json.dumps({f"frame{k}_tag1": [x, y, 0.35] for k, (x, y) in labels.items()}))
    rng = np.random.default_rng(64)
    datasets = {}
    for variant, names in (("base", BASE_SETS), *VARIANT_SETS.items()):
        paths = []
        for name in names:
            folder = raw / f"{name}{FOLDER_SUFFIX}" / "spad_histogram"
            folder.mkdir(parents=True)
            for k in range(100) if variant == "base" else VARIANT_LOCATIONS:
                scale = rng.uniform(300, 6000, size=(1, 3, 3, 128))
                np.save(folder / f"{k:03d}.npy", rng.poisson(scale, size=(REPEATS[variant], 3, 3, 128)).astype(np.int32))
            paths.append(stores / f"{name}.zarr")
            ingest_release(folder.parent, paths[-1], catalogue[parse_set_name(name).object])
        datasets[variant] = paper_samples(paths, catalogue, labels, variant)
    return raw, positions, datasets


@pytest.fixture(scope="module")
def theirs(tree, tmp_path_factory):
    """The reference's base query (as its build_query makes it), its joblib dataset folder, its modules."""
    raw, positions, _ = tree
    data = reference_module("main_table.data")
    dataset = data.DataSet.from_raw_captures(raw)
    query = dataset.query_data(
        capture_resolutions=["3x3"],
        average_spad_histograms=False,
        location_mapping=data.load_capture_number_to_location_mapping(positions),
        included_objects=data.BASE_OBJECTS,
    )
    held_out_root = tmp_path_factory.mktemp("saved")
    dataset.save_to_directory(held_out_root / "saved_dataset")
    modules = {m: reference_module(f"generalization.{m}") for m in ("experiments", "splits", "loaders", "evaluate")}
    return query, held_out_root, modules


@needs_shared
@pytest.mark.parametrize("network", rm.NETWORKS, ids=lambda n: n.name)
def test_predictions_and_test_parts_are_the_releases(tree, theirs, network, monkeypatch):
    """The reference's test indices, inputs and network against ours: the same
    rows, and the same outputs sample by sample."""
    _, positions, datasets = tree
    query, held_out_root, ref = theirs
    x, samples = datasets[network.dataset]
    ours = rm.evaluate_network(network, RELEASE, rm.read_manifest(RELEASE), x, samples)
    evaluate = ref["evaluate"]
    if network.variant is None:
        exp = dataclasses.replace(ref["experiments"].SPLIT_EXPERIMENTS[network.name], ckpt=RELEASE / network.file)
        test = ref["splits"].load_split_test_set(exp, query)
        model, _ = ref["splits"].load_split_model(exp)
        histograms = [query["spad_histograms"][i] for i in test.test_indices]
        preds = evaluate._run_inference(model, evaluate._preprocess(histograms, test.train_mean, test.train_std), "cpu", 256)
        assert np.array_equal(ours.part.rows, test.test_indices)
        assert "drawn instead" not in ours.part.note and "within" not in ours.part.note  # the release's own definition, exact labels
    else:
        monkeypatch.setattr(ref["loaders"], "DEFAULT_TAG_POSITIONS", positions)
        exp = dataclasses.replace(ref["experiments"].EXPERIMENTS[network.name], ckpt=RELEASE / network.file)
        held = ref["loaders"].load_held_out_dataset(exp, held_out_root=held_out_root)
        model, payload = ref["loaders"].load_experiment_model(exp)
        preds = evaluate._run_inference(
            model, evaluate._preprocess(held.spad_histograms, float(payload["train_mean"]), float(payload["train_std"])), "cpu", 256
        )
        assert len(ours.part.rows) == len(held) > 0
        assert samples.iloc[ours.part.rows]["object"].tolist() == held.objects
    assert ours.outputs.shape == preds.shape and len(preds) > 0
    np.testing.assert_allclose(ours.outputs, preds, rtol=1e-5, atol=1e-5)
    # and the headline score, ours from our outputs, theirs from theirs
    row = rm.score_rows(ours, samples)[0]
    if network.task == "location":
        truth = samples.iloc[ours.part.rows][["x", "y"]].to_numpy()
        assert row["value"] == pytest.approx(evaluate._regression_metrics(preds, truth)["rmse"], rel=1e-5)
    else:
        column = "class" if network.task == "shape" else "size"
        truth = samples.iloc[ours.part.rows][column].tolist()
        classes = evaluate.BASE_OBJECT_CLASSES if network.task == "shape" else evaluate.BASE_SIZE_CLASSES
        assert row["value"] == pytest.approx(evaluate._classification_metrics(preds, truth, classes, num_classes=len(classes))["top1_acc"])
