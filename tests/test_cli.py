"""`denali rig` through `denali_pipe.cli.main` (in-process)."""

from __future__ import annotations

import copy
import json
import logging

import numpy as np
import pytest

from denali_pipe.cli import main
from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.rig.capture import synth_sets

N_LOCATIONS = 2


@pytest.fixture(scope="module")
def job_config(demo_config) -> dict:
    """What the rig rule hands the verb: the seed and the rig section."""
    rig = copy.deepcopy(demo_config["rig"])
    rig.update(n_locations=N_LOCATIONS, repeats=2, frames={"tracking_scale": 0.25, "colocated_scale": 0.25})
    return {"seed": demo_config["seed"], "rig": rig}


@pytest.fixture(scope="module")
def job_args(job_config, demo_config) -> list[str]:
    """The rig rule's --config and --time-axis."""
    return ["--config", json.dumps(job_config), "--time-axis", json.dumps(demo_config["sensor"]["time_axis"])]


@pytest.fixture
def log(caplog):
    caplog.set_level(logging.INFO, logger="denali")
    return caplog


def obj_arg(catalogue, name: str) -> list[str]:
    return ["--object", json.dumps(catalogue[name].to_dict(), sort_keys=True)]


def errors(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "denali" and r.levelno >= logging.ERROR]


def test_synth_writes_sets(tmp_path, catalogue, job_args, log):
    outs = [tmp_path / f"A_4inch_{res}_lightoff_NLOSdata" for res in ("3x3", "8x8")]
    rc = main(["rig", *map(str, outs), *obj_arg(catalogue, "A"), *job_args])
    assert rc == 0
    assert errors(log) == []
    assert any("wrote" in r.getMessage() for r in log.records)
    locations = [int(k) for k in geo.select_locations(N_LOCATIONS)]
    for out in outs:
        n = parse_set_name(out.name).n_zones
        assert sorted(int(p.stem) for p in (out / "spad_histogram").iterdir()) == locations
        h = np.load(out / "spad_histogram" / f"{locations[0]:03d}.npy")
        assert h.shape == (2, n, n, geo.N_BINS) and h.dtype == np.int32
        md = json.loads((out / "metadata.json").read_text())
        assert (md["object"], md["size"], md["spad_res"], md["light"]) == ("A", "4inch", parse_set_name(out.name).resolution, "lightoff")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(o.name for o in outs)


def test_synth_matches_library_call(tmp_path, catalogue, job_config, job_args, time_axis, log):
    cli_out = tmp_path / "cli" / "A_4inch_3x3_lighton_NLOSdata"
    lib_out = tmp_path / "lib" / "A_4inch_3x3_lighton_NLOSdata"
    assert main(["rig", str(cli_out), *obj_arg(catalogue, "A"), *job_args]) == 0
    synth_sets([parse_set_name(lib_out.name)], catalogue["A"], job_config, time_axis, [lib_out], "release")
    for p in sorted(lib_out.rglob("*")):
        if p.is_file():
            assert (cli_out / p.relative_to(lib_out)).read_bytes() == p.read_bytes(), p


def test_synth_background_and_pickle(tmp_path, job_args, log):
    out = tmp_path / "NOOBJECTMOUNT_8inch_3x3_lighton_short_NLOSdata.pkl"
    assert main(["rig", str(out), *job_args, "--format", "pickle"]) == 0
    assert out.is_file()
    assert (tmp_path / "NOOBJECTMOUNT_8inch_3x3_lighton_rig_truth.json").is_file()
    assert errors(log) == []


@pytest.mark.parametrize(
    "set_name,record",
    [
        ("A_4inch_3x3_lighton", "B"),  # another object's record
        ("generalization1italic_8inch_3x3_lighton", "1"),  # same class, different object
        ("NOOBJECT_8inch_3x3_lighton", "A"),  # a background takes no record
        ("A_4inch_3x3_lighton", None),  # an object set needs one
    ],
)
def test_object_record_must_match_set(tmp_path, catalogue, job_args, log, set_name, record):
    out = tmp_path / f"{set_name}_NLOSdata"
    args = ["rig", str(out), *job_args]
    if record is not None:
        args += obj_arg(catalogue, record)
    assert main(args) == 1
    (msg,) = errors(log)
    assert set_name in msg and "does not match" in msg
    assert list(tmp_path.iterdir()) == []


def test_object_record_must_match_every_set(tmp_path, catalogue, job_args, log):
    outs = [tmp_path / "A_8inch_3x3_lighton_NLOSdata", tmp_path / "B_8inch_3x3_lighton_NLOSdata"]
    assert main(["rig", *map(str, outs), *obj_arg(catalogue, "A"), *job_args]) == 1
    (msg,) = errors(log)
    assert "B_8inch_3x3_lighton" in msg
    assert list(tmp_path.iterdir()) == []


def test_object_record_without_the_size(tmp_path, catalogue, job_args, log):
    # the italic plates exist at 8 in only
    out = tmp_path / "generalization1italic_4inch_3x3_lighton_NLOSdata"
    assert main(["rig", str(out), *obj_arg(catalogue, "generalization1italic"), *job_args]) == 1
    (msg,) = errors(log)
    assert "4inch" in msg
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["A_4inch_3x3_lightsout_NLOSdata", "capture_042", "A_6inch_3x3_lighton_NLOSdata"])
def test_unparsable_output_name(tmp_path, catalogue, job_args, log, name):
    out = tmp_path / name
    assert main(["rig", str(out), *obj_arg(catalogue, "A"), *job_args]) == 1
    (msg,) = errors(log)
    assert name in msg and "does not parse" in msg
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--config", "--object", "--time-axis"])
def test_invalid_json_is_an_argument_error(tmp_path, job_args, capsys, option):
    args = ["rig", str(tmp_path / "A_4inch_3x3_lighton_NLOSdata"), *job_args]
    args += [option, "{seed: 1,"]
    with pytest.raises(SystemExit) as e:
        main(args)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert option in err and "not valid JSON" in err
    assert list(tmp_path.iterdir()) == []


def test_unknown_format_is_an_argument_error(tmp_path, job_args, capsys):
    with pytest.raises(SystemExit) as e:
        main(["rig", str(tmp_path / "NOOBJECT_8inch_3x3_lighton_NLOSdata"), *job_args, "--format", "zarr"])
    assert e.value.code == 2
    assert "--format" in capsys.readouterr().err


def test_parser_imports_no_heavy_library():
    """Every job is a fresh `python -m denali_pipe.cli <verb>`: building the
    parser must leave each library to the verbs that use it (pandas alone
    cost every job ~0.3 CPU-s)."""
    import subprocess
    import sys

    heavy = ("pandas", "torch", "zarr", "matplotlib", "cv2", "mitsuba", "scipy", "sklearn", "trimesh")
    probe = f"import sys; from denali_pipe.cli import build_parser; build_parser(); print([m for m in {heavy!r} if m in sys.modules])"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
