"""Raw capture pickle streams (`io/pickle_stream.py`): the restricted unpickler
admits numpy arrays, dtypes and scalars as pickle and cloudpickle write them,
refuses every other global without running it, and `iter_records` streams a
capture file record by record with clear errors for broken streams."""

from __future__ import annotations

import builtins
import codecs
import copy
import os
import pickle
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO

from denali_pipe.core.capture_sets import PICKLE_SUFFIX, parse_set_name
from denali_pipe.core.geometry import TimeAxis
from denali_pipe.core.objects import load_catalogue
from denali_pipe.io.pickle_stream import (
    ALLOWED_GLOBALS,
    RECORD_KEYS,
    UnsafePickleError,
    iter_records,
    read_metadata,
    restricted_loads,
)
from denali_pipe.rig import capture

SET = "A_8inch_3x3_lighton"


# --- fixtures -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def stream(tmp_path_factory, demo_config) -> Path:
    """One small capture stream written by the synthetic rig (3 locations, 3 repeats)."""
    cfg = copy.deepcopy(demo_config)
    cfg["rig"].update(n_locations=3, repeats=3, frames={"tracking_scale": 0.25, "colocated_scale": 0.25})
    out = tmp_path_factory.mktemp("pkl") / f"{SET}{PICKLE_SUFFIX}"
    spec = load_catalogue(REPO / "config" / "objects.tsv")["A"]
    capture.synth_sets([parse_set_name(SET)], spec, cfg, TimeAxis.from_config(cfg["sensor"]["time_axis"]), [out], "pickle")
    return out


def trusted_records(path: Path) -> list:
    """Every pickle of a stream we wrote ourselves (plain pickle is fine for those)."""
    items = []
    with open(path, "rb") as f:
        while f.peek(1):
            items.append(pickle.load(f))
    return items


def write_stream(path: Path, records: list, protocol: int = 4) -> Path:
    with open(path, "wb") as f:
        for r in records:
            pickle.dump(r, f, protocol=protocol)
    return path


# --- what a capture holds loads -------------------------------------------------------------

SAMPLES = {
    "int32 array": np.arange(24, dtype=np.int32).reshape(2, 3, 4),
    "uint16 depth": np.arange(12, dtype=np.uint16).reshape(3, 4),
    "uint8 bgr": np.arange(24, dtype=np.uint8).reshape(2, 4, 3),
    "float64 array": np.linspace(0, 1, 5),
    "fortran order": np.asfortranarray(np.arange(6.0).reshape(2, 3)),
    "non-contiguous": np.arange(10)[::2],
    "empty": np.zeros((0, 3), dtype=np.int32),
    "structured dtype": np.dtype([("a", "<i4"), ("b", "<f8")]),
    "dtype": np.dtype("uint16"),
    "int64 scalar": np.int64(7),
    "float32 scalar": np.float32(1.5),
    "bool scalar": np.bool_(True),
    "bytes": b"\x00\xffraw",
    "empty bytes": b"",
    "containers": {"a": [1, 2.5, None, True, "s"], "t": (1, (2, 3))},
}


def _equal(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
    return type(a) is type(b) and a == b


@pytest.mark.parametrize("protocol", [0, 1, 2, 3, 4, 5])
def test_accepts_numpy_and_builtins(protocol):
    for name, obj in SAMPLES.items():
        back = restricted_loads(pickle.dumps(obj, protocol=protocol))
        assert _equal(back, obj), (protocol, name)


def test_accepts_cloudpickle():
    cloudpickle = pytest.importorskip("cloudpickle")
    back = restricted_loads(cloudpickle.dumps(SAMPLES))
    for name, obj in SAMPLES.items():
        assert _equal(back[name], obj), name


def test_accepts_numpy1_spellings():
    # numpy 1.x wrote numpy.core.multiarray._reconstruct / .scalar
    for obj in (np.arange(5, dtype=np.int32), np.int64(3)):
        data = pickle.dumps(obj, protocol=2)
        assert b"numpy._core.multiarray" in data
        old = data.replace(b"numpy._core.multiarray", b"numpy.core.multiarray")
        assert _equal(restricted_loads(old), obj)


def test_allowed_globals_are_only_numpy_reconstructors():
    modules = {m for m, _ in ALLOWED_GLOBALS}
    assert modules <= {"numpy", "numpy._core.multiarray", "numpy.core.multiarray", "numpy._core.numeric",
                       "numpy.core.numeric", "_codecs", "builtins"}  # fmt: skip
    assert ("builtins", "getattr") not in ALLOWED_GLOBALS
    assert ("copyreg", "_reconstructor") not in ALLOWED_GLOBALS


# --- anything else is refused, and nothing runs -----------------------------------------------


class _Reduce:
    """Pickles as `func(*args)`: what a malicious stream would hold."""

    def __init__(self, func, *args):
        self.func, self.args = func, args

    def __reduce__(self):
        return self.func, self.args


def _attacks(target: Path) -> dict[str, tuple[object, str]]:
    """name -> (payload that would create `target` when unpickled, the global named)."""
    cmd = f"touch {target}"
    return {
        "os.system": (_Reduce(os.system, cmd), f"{os.system.__module__}.system"),
        "subprocess.call": (_Reduce(subprocess.call, ["touch", str(target)]), "subprocess.call"),
        "builtins.exec": (_Reduce(builtins.exec, f"open({str(target)!r}, 'w').close()"), "builtins.exec"),
        "builtins.open": (_Reduce(builtins.open, str(target), "w"), f"{builtins.open.__module__}.open"),
        "pathlib touch": (_Reduce(getattr, target, "touch"), "builtins.getattr"),
    }


@pytest.mark.parametrize("attack", ["os.system", "subprocess.call", "builtins.exec", "builtins.open", "pathlib touch"])
@pytest.mark.parametrize("protocol", [2, 4, 5])
def test_refuses_code_execution(tmp_path, attack, protocol):
    target = tmp_path / "pwned"
    payload, global_name = _attacks(target)[attack]
    data = pickle.dumps({"histogram": np.zeros(3), "x": [payload]}, protocol=protocol)
    with pytest.raises(UnsafePickleError) as e:
        restricted_loads(data, source="crafted.pkl")
    assert global_name in str(e.value)
    assert "crafted.pkl" in str(e.value)
    assert not target.exists()


def test_refuses_dotted_global():
    # protocol 4 STACK_GLOBAL resolves dotted names; an allowed module must not open its attributes
    data = b"\x80\x04\x8c\x05numpy\x8c\x0endarray.tofile\x93."
    with pytest.raises(UnsafePickleError, match=r"numpy\.ndarray\.tofile"):
        restricted_loads(data)


def test_refuses_calling_ndarray_directly():
    # np.ndarray((2**40,)) would allocate a terabyte; numpy's pickles never call it
    with pytest.raises(UnsafePickleError, match="numpy.ndarray called directly"):
        restricted_loads(pickle.dumps(_Reduce(np.ndarray, (2**40,)), protocol=2))
    from numpy._core.multiarray import _reconstruct

    with pytest.raises(UnsafePickleError, match="only \\(ndarray, \\(0,\\)\\) is admitted"):
        restricted_loads(pickle.dumps(_Reduce(_reconstruct, np.ndarray, (2**40,), b"b"), protocol=2))


def test_refuses_codecs_other_than_latin1():
    data = pickle.dumps(_Reduce(codecs.encode, "abc", "rot13"), protocol=2)
    with pytest.raises(UnsafePickleError, match="latin1"):
        restricted_loads(data)


def test_refuses_bytes_with_arguments():
    data = pickle.dumps(_Reduce(bytes, 10**12), protocol=2)  # would allocate a terabyte
    with pytest.raises(UnsafePickleError, match="bytes"):
        restricted_loads(data)


def test_refuses_out_of_band_buffers():
    buffers = []
    data = pickle.dumps(pickle.PickleBuffer(np.arange(4)), protocol=5, buffer_callback=buffers.append)
    assert buffers
    with pytest.raises(pickle.UnpicklingError):
        restricted_loads(data)


def test_stream_names_file_record_and_global(tmp_path, stream):
    target = tmp_path / "pwned"
    records = trusted_records(stream)
    records[2]["histogram"] = _Reduce(os.system, f"touch {target}")
    bad = write_stream(tmp_path / stream.name, records)
    seen = []
    with pytest.raises(UnsafePickleError) as e:
        for index, _ in iter_records(bad):
            seen.append(index)
    msg = str(e.value)
    assert str(bad) in msg and "record 2" in msg and f"{os.system.__module__}.system" in msg
    assert seen == [0, 1]  # streamed: earlier records came out before the bad one was read
    assert not target.exists()


# --- iter_records ------------------------------------------------------------------------------


def test_iter_records_reads_the_rig_stream(stream):
    expected = trusted_records(stream)
    got = list(iter_records(stream))
    assert [i for i, _ in got] == list(range(len(expected)))
    assert got[0][1] == expected[0]
    assert got[0][1]["spad_res"] == "3x3"
    for (_, rec), exp in zip(got[1:], expected[1:]):
        assert set(rec) == set(RECORD_KEYS)
        assert rec["iter"] == exp["iter"]
        assert np.array_equal(rec["histogram"], exp["histogram"]) and rec["histogram"].dtype == exp["histogram"].dtype
        for cam in ("spad_realsense_data", "tracking_realsense_data"):
            for key in ("aligned_depth_image", "aligned_rgb_image"):
                assert np.array_equal(rec[cam][key], exp[cam][key])
    assert read_metadata(stream) == expected[0]


def test_iter_records_is_lazy(stream):
    it = iter_records(stream)
    assert next(it)[0] == 0  # a generator: nothing past the metadata has been read yet
    assert next(it)[0] == 1


def test_metadata_wrapped_as_the_capture_script_writes_it(tmp_path, stream):
    records = trusted_records(stream)
    records[0] = {"metadata": records[0]}
    path = write_stream(tmp_path / stream.name, records)
    assert read_metadata(path) == trusted_records(stream)[0]


def test_truncated_stream(tmp_path, stream):
    data = stream.read_bytes()
    cut = tmp_path / stream.name
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(ValueError, match=r"record \d+ is cut or corrupt") as e:
        list(iter_records(cut))
    assert str(cut) in str(e.value)


def test_corrupt_length_field(tmp_path):
    # BINBYTES8 claiming a terabyte: refused without allocating it
    bad = tmp_path / f"{SET}{PICKLE_SUFFIX}"
    bad.write_bytes(b"\x80\x04\x8e" + (2**40).to_bytes(8, "little") + b"x" * 100)
    with pytest.raises(ValueError, match=r"record 0 (could not be unpickled: out of memory|is cut or corrupt)"):
        list(iter_records(bad))


def test_empty_stream(tmp_path):
    empty = tmp_path / f"{SET}{PICKLE_SUFFIX}"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="empty capture stream"):
        list(iter_records(empty))


def test_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such capture stream"):
        list(iter_records(tmp_path / "nothing.pkl"))


def test_missing_metadata_record(tmp_path, stream):
    path = write_stream(tmp_path / stream.name, trusted_records(stream)[1:])
    with pytest.raises(ValueError, match="metadata record is missing") as e:
        list(iter_records(path))
    assert str(path) in str(e.value) and "record 0" in str(e.value)


def test_record_not_a_dict(tmp_path, stream):
    records = trusted_records(stream)
    records[2] = [1, 2, 3]
    path = write_stream(tmp_path / stream.name, records)
    with pytest.raises(ValueError, match=r"record 2 is a list, expected a dict"):
        list(iter_records(path))


def test_record_lacks_keys(tmp_path, stream):
    records = trusted_records(stream)
    del records[3]["histogram"]
    path = write_stream(tmp_path / stream.name, records)
    with pytest.raises(ValueError, match=r"record 3 lacks keys \['histogram'\]"):
        list(iter_records(path))


def test_camera_record_lacks_keys(tmp_path, stream):
    records = trusted_records(stream)
    del records[1]["tracking_realsense_data"]["aligned_rgb_image"]
    path = write_stream(tmp_path / stream.name, records)
    with pytest.raises(ValueError, match=r"record 1 \(tracking_realsense_data\) lacks keys \['aligned_rgb_image'\]"):
        list(iter_records(path))


def test_iter_must_be_an_integer(tmp_path, stream):
    records = trusted_records(stream)
    records[1]["iter"] = "zero"
    path = write_stream(tmp_path / stream.name, records)
    with pytest.raises(ValueError, match=r"record 1: `iter` must be an integer"):
        list(iter_records(path))
