"""`denali predict`: one raw capture through the training preprocessing and
trained cells, the same answer from a release file, a store-less pickle
stream or the library, and clear refusals."""

import json
import pickle

import numpy as np
import pandas as pd
import pytest
import torch

from denali_pipe.cli import main
from denali_pipe.preprocess.histograms import background_means, crop_window, preprocess
from denali_pipe.train.evaluate import load_cell, predict
from denali_pipe.train.predict import capture_features, predict_capture, read_background, read_capture, softmax
from denali_pipe.train.training import Hyper, run_cell

N, BINS, REPEATS, LOCATION = 3, 128, 3, 37
CLASSES = ("A", "B", "circle")


def background_counts(rng, shift=0):
    """(R, n, n, 128) counts: a floor, a direct wall return at bin ~20 (+ shift) and its tail."""
    t = np.arange(BINS)
    direct = 5000 * np.exp(-0.5 * ((t - 20 - shift) / 1.5) ** 2) + 400 * np.exp(-np.clip(t - 20 - shift, 0, None) / 6.0) * (t >= 20 + shift)
    return rng.poisson(200 + direct, size=(REPEATS, N, N, BINS)).astype(np.int32)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """A background and a capture (its background plus a bump) in the release
    layout and as pickle streams, the crop window of the background, and
    cells of the three tasks trained on features of the window's length."""
    root = tmp_path_factory.mktemp("predict")
    rng = np.random.default_rng(3)
    bg, capture = {k: background_counts(rng) for k in (LOCATION - 1, LOCATION)}, background_counts(rng, shift=1)
    capture = capture + rng.poisson(300 * np.exp(-0.5 * ((np.arange(BINS) - 60) / 3.0) ** 2), size=capture.shape).astype(np.int32)
    window = crop_window([bg[LOCATION][None]], np.full((3, 3), np.inf))  # no object nearer than the tails
    (root / "crop_3x3.json").write_text(json.dumps(window.to_dict()))
    paths = {}
    for name, by_location in (("bg", bg), ("obj", {k: capture for k in bg})):
        d = root / f"{name}_NLOSdata" / "spad_histogram"
        d.mkdir(parents=True)
        cam = {"aligned_depth_image": np.zeros((2, 2), np.uint16), "aligned_rgb_image": np.zeros((2, 2, 3), np.uint8)}
        with open(root / f"{name}.pkl", "wb") as f:
            pickle.dump({"metadata": {"object": name}}, f)
            for k, counts in by_location.items():
                np.save(d / f"{k:03d}.npy", counts)
                pickle.dump({"iter": k, "histogram": counts, "spad_realsense_data": cam, "tracking_realsense_data": cam}, f)
        paths[name] = (d / f"{LOCATION:03d}.npy", root / f"{name}.pkl", d.parent)
    t = BINS - window.crop_start
    rows = [{"class": c, "size": s, "light": "lighton", "location": k, "repeat": r, "x": 1.0 + 0.01 * k, "y": 0.3 + 0.01 * (k % 3)}
            for c in CLASSES for s in ("4inch", "8inch") for k in range(8) for r in range(3)]  # fmt: skip
    samples = pd.DataFrame(rows).assign(set=lambda d: d["class"] + "_" + d["size"], object=lambda d: d["class"], type="letter")
    x = rng.normal(0, 50, (len(samples), N, N, t)).astype(np.float32)
    runs = {}
    for task, norm in (("location", "raw"), ("shape", "log_z"), ("size", "raw")):
        from denali_pipe.train.cells import Cell

        cell = Cell(model="cnn1d", task=task, split="random", resolution="3x3", protocol="clean", seed=42)
        result = run_cell(x, samples, cell, Hyper(lr=1e-3, epochs=1, batch_size=64, norm=norm), 0.2, "denali_pipe.train.models:cnn1d")
        run = root / "runs" / task
        run.mkdir(parents=True)
        torch.save(result.state, run / "model.pt")
        runs[task] = run
    return {"root": root, "paths": paths, "window": window, "runs": runs, "bg": np.stack([bg[k] for k in sorted(bg)]), "capture": capture}


def test_features_are_the_pipelines_preprocessing_of_the_capture(rig):
    capture = read_capture(rig["paths"]["obj"][0])
    background = read_background(rig["paths"]["bg"][2], capture.location)
    assert capture.location == LOCATION and np.array_equal(capture.counts, rig["capture"])
    assert background.n_locations == 2
    f = capture_features(capture, background, rig["window"])
    locations = np.array([LOCATION - 1, LOCATION])
    expected = preprocess(rig["capture"][None], np.array([LOCATION]), background_means(rig["bg"]), locations, rig["window"]).values[0]
    assert np.array_equal(f, expected) and f.shape == (REPEATS, N, N, BINS - rig["window"].crop_start)


def test_a_background_of_one_capture_is_its_plain_mean(rig):
    background = read_background(rig["paths"]["bg"][0], LOCATION)
    assert background.n_locations == 1 and np.array_equal(background.counts, rig["bg"][1].mean(axis=0))
    with pytest.raises(ValueError, match="no capture at gantry location 5"):
        read_background(rig["paths"]["bg"][2], 5)


def test_predict_averages_each_cells_answer_over_the_repeats(rig):
    capture, background = read_capture(rig["paths"]["obj"][0]), read_background(rig["paths"]["bg"][2], LOCATION)
    cells = [(run, load_cell(run)) for run in rig["runs"].values()]
    record = predict_capture(cells, capture, background, rig["window"])
    f = capture_features(capture, background, rig["window"])
    loc = predict(load_cell(rig["runs"]["location"]), f).mean(axis=0)
    assert (record["location"]["x_m"], record["location"]["y_m"]) == pytest.approx(tuple(loc))
    shape = softmax(predict(load_cell(rig["runs"]["shape"]), f)).mean(axis=0)
    top = record["shape"]["top5"]
    assert [c["class"] for c in top] == [CLASSES[i] for i in np.argsort(-shape)] and sum(c["probability"] for c in top) == pytest.approx(1.0)
    assert set(record["size"]["probabilities"]) == {"4inch", "8inch"} and record["size"]["class"] in ("4inch", "8inch")
    one = predict_capture(cells, capture, background, rig["window"], repeat=2)
    assert one["repeats"] == [2] and one["location"]["x_m"] == pytest.approx(float(predict(load_cell(rig["runs"]["location"]), f[2:3])[0, 0]))


def test_the_cli_prints_the_same_json_from_a_release_file_or_a_stream_record(rig, capsys):
    runs = [str(r) for r in rig["runs"].values()]
    crop = str(rig["root"] / "crop_3x3.json")
    (obj_npy, obj_pkl, _), (_, bg_pkl, bg_dir) = rig["paths"]["obj"], rig["paths"]["bg"]
    assert main(["predict", *runs, str(obj_npy), "--background", str(bg_dir), "--crop", crop]) == 0
    from_npy = json.loads(capsys.readouterr().out)
    assert main(["predict", *runs, str(obj_pkl), "--background", str(bg_pkl), "--crop", crop, "--location", str(LOCATION)]) == 0
    from_pkl = json.loads(capsys.readouterr().out)
    drop = ("capture", "background")
    assert {k: v for k, v in from_npy.items() if k not in drop} == {k: v for k, v in from_pkl.items() if k not in drop}
    assert from_npy["gantry_location"] == LOCATION and from_npy["repeats"] == [0, 1, 2] and len(from_npy["shape"]["top5"]) == 3
    assert from_npy["background_locations"] == 2


def test_the_cli_warns_that_one_background_capture_keeps_its_noise(rig, capsys, caplog):
    runs = [str(r) for r in rig["runs"].values()]
    (obj_npy, *_), (bg_npy, *_) = rig["paths"]["obj"], rig["paths"]["bg"]
    assert main(["predict", *runs, str(obj_npy), "--background", str(bg_npy), "--crop", str(rig["root"] / "crop_3x3.json")]) == 0
    assert json.loads(capsys.readouterr().out)["background_locations"] == 1
    assert "keeps its shot noise" in caplog.text


def test_what_predict_refuses(rig, tmp_path, caplog):
    runs = [str(r) for r in rig["runs"].values()]
    crop = str(rig["root"] / "crop_3x3.json")
    (obj_npy, obj_pkl, _), (bg_npy, *_) = rig["paths"]["obj"], rig["paths"]["bg"]
    assert main(["predict", *runs, str(obj_pkl), "--background", str(bg_npy), "--crop", crop]) == 1
    assert "holds 2 gantry locations; give the location" in caplog.text
    assert main(["predict", *runs, str(obj_pkl), "--background", str(bg_npy), "--crop", crop, "--location", "5"]) == 1
    assert "has no capture at gantry location 5" in caplog.text
    other = tmp_path / "038.npy"
    other.write_bytes(bg_npy.read_bytes())
    assert main(["predict", *runs, str(obj_npy), "--background", str(other), "--crop", crop]) == 1
    assert f"{other}: the file of gantry location 38, not of location {LOCATION}" in caplog.text
    assert main(["predict", runs[0], runs[0], str(obj_npy), "--background", str(bg_npy), "--crop", crop]) == 1
    assert "one cell per task" in caplog.text
    wider = tmp_path / "crop.json"
    wider.write_text(json.dumps({**rig["window"].to_dict(), "crop_start": rig["window"].crop_start - 4}))
    assert main(["predict", runs[0], str(obj_npy), "--background", str(bg_npy), "--crop", str(wider)]) == 1
    assert "do not fit a 3x3 cell" in caplog.text
    flat = tmp_path / "001.npy"
    np.save(flat, np.zeros((3, 9, 128), np.int32))
    assert main(["predict", runs[0], str(flat), "--background", str(bg_npy), "--crop", crop]) == 1
    assert f"{flat}: histograms of shape (3, 9, 128); expected (repeats, n, n, 128)" in caplog.text
