"""`denali export`: the torch.export program and the ONNX model each predict
what the cell predicts, say what they take and give, and export without a
deprecation warning."""

import warnings

import numpy as np
import onnxruntime
import pytest
import torch
from conftest import REPO
from test_train import _cell, data  # noqa: F401 (the fixture)

from denali_pipe.cli import main
from denali_pipe.preprocess.histograms import CropWindow
from denali_pipe.train.evaluate import load_cell, predict
from denali_pipe.train.export import FORMATS, load_export
from denali_pipe.train.training import Hyper, run_cell

CASES = [
    ("cnn1d", "shape", "log_z", "denali_pipe.train.models:cnn1d"),
    ("mlp", "location", "raw", "denali_pipe.train.models:mlp"),
    ("cnn3d", "size", "log_z", "denali_pipe.train.models:cnn3d"),
    ("transformer", "shape", "log_z", "denali_pipe.train.models:transformer"),
    ("tof", "location", "raw", "examples.tof_matched_filter:tof_matched_filter"),
]


@pytest.mark.parametrize(("model", "task", "norm", "factory"), CASES, ids=[c[0] for c in CASES])
def test_the_export_predicts_what_the_cell_predicts(tmp_path, data, monkeypatch, model, task, norm, factory):  # noqa: F811
    monkeypatch.chdir(REPO)  # the example model is found from the workflow's folder
    x, samples = data
    result = run_cell(x, samples, _cell(task=task, model=model), Hyper(lr=3e-3, epochs=1, batch_size=64, norm=norm), 0.2, factory)
    run = tmp_path / "run"
    run.mkdir()
    torch.save(result.state, run / "model.pt")
    crop = tmp_path / "crop_3x3.json"
    crop.write_text('{"crop_start": 104, "zone_starts": [[104, 104, 104], [104, 104, 104], [104, 104, 104]]}')
    cell = load_cell(run)
    # unseen inputs of another batch size than the trace's, counts of both signs as after background subtraction
    probe = np.random.default_rng(5).normal(0, 40, (7, *cell.input_shape)).astype(np.float32)
    expected = predict(cell, probe)
    for suffix in FORMATS:
        out = tmp_path / f"cell{suffix}"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert main(["export", str(run), str(out), "--crop", str(crop)]) == 0
        deprecations = [str(w.message) for w in caught if issubclass(w.category, (DeprecationWarning, FutureWarning))]
        assert deprecations == [], deprecations
        module, meta = load_export(out)
        if suffix == ".onnx":
            session = onnxruntime.InferenceSession(str(out), providers=["CPUExecutionProvider"])
            exported = session.run(None, {session.get_inputs()[0].name: probe})[0]
        else:
            with torch.no_grad():
                exported = module(torch.from_numpy(probe)).numpy()
        np.testing.assert_allclose(exported, expected, rtol=1e-4, atol=1e-4, err_msg=suffix)
        assert meta["task"] == task and meta["classes"] == cell.classes and meta["input_shape"] == list(cell.input_shape)
        assert meta["normalisation"]["kind"] == norm and meta["factory"] == factory and meta["cell"]["model"] == model
        assert CropWindow.from_dict(meta["crop"]).crop_start == 104
        assert meta["outputs"] == (["x_m", "y_m"] if task == "location" else "logits over classes")
        if task == "location":  # a clean location cell: its bounded head's box, applied inside
            assert meta["targets"]["box_m"] == [list(row) for row in cell.target_stats[2:]]


def test_an_export_of_another_kind_is_refused_naming_the_file(tmp_path, data, caplog):  # noqa: F811
    x, samples = data
    result = run_cell(x, samples, _cell(task="size", model="mlp"), Hyper(lr=3e-3, epochs=1, batch_size=64, norm="raw"), 0.2, "denali_pipe.train.models:mlp")
    run = tmp_path / "run"
    run.mkdir()
    torch.save(result.state, run / "model.pt")
    assert main(["export", str(run), str(tmp_path / "cell.pt")]) == 1
    assert "cell.pt: an export is a torch.export program (.pt2) or an ONNX model (.onnx), not .pt" in caplog.text
    assert not (tmp_path / "cell.pt").exists()


def test_a_file_that_is_not_an_export_is_refused(tmp_path):
    plain = tmp_path / "plain.pt2"
    torch.export.save(torch.export.export(torch.nn.ReLU(), (torch.zeros(2),)), str(plain))
    with pytest.raises(ValueError, match="plain.pt2: a .pt2 file without denali-pipe's denali.json"):
        load_export(plain)
    for junk in ("junk.pt2", "junk.onnx"):
        (tmp_path / junk).write_bytes(b"not a zip")
        with pytest.raises(ValueError, match=f"{junk}: not a denali-pipe export"):
            load_export(tmp_path / junk)
