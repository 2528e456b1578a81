"""The Zarr v3 capture store (`io/store.py`): layout, codecs, attributes, the
lazy reader, atomic writes, checks and streaming memory."""

from __future__ import annotations

import json
import re
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
import zarr

from denali_pipe.core.capture_sets import parse_set_name
from denali_pipe.io.store import MODALITIES, STORE_VERSION, CaptureStore, StoreWriter, jsonable, open_set

CS = parse_set_name("A_4inch_3x3_lighton")
SHAPES = {"tracking_rgb": (18, 32), "tracking_depth": (18, 32), "colocated_rgb": (12, 21), "colocated_depth": (12, 21)}


def fake_location(k: int, repeats: int = 3, n: int = 3, shapes=SHAPES) -> tuple[np.ndarray, dict]:
    rng = np.random.default_rng(k)
    hist = rng.poisson(50, (repeats, n, n, 128)).astype(np.int32)
    frames = {}
    for m, (h, w) in shapes.items():
        if m.endswith("_rgb"):
            frames[m] = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        else:
            frames[m] = rng.integers(0, 5000, (h, w), dtype=np.uint16)
    return hist, frames


def write_fake(out: Path, locations, cs=CS, **kw) -> dict[int, tuple]:
    data = {k: fake_location(k, n=cs.n_zones) for k in locations}
    md = {"object": cs.object, "locations": list(locations), "grid": np.array([10, 10]), "gain": np.float32(0.5)}
    with StoreWriter(out, cs, repeats=3, metadata=md, source_format="release", **kw) as w:
        w.add_source("x/metadata.json", "metadata", 10, "ab" * 32)
        for k, (hist, frames) in data.items():
            w.write_location(k, hist, frames)
    return data


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    out = tmp_path_factory.mktemp("store") / f"{CS.name}.zarr"
    data = write_fake(out, [0, 7, 42, 99])
    return out, data


# --- layout --------------------------------------------------------------------------------


def test_layout_dtypes_chunks_codecs(store):
    out, _ = store
    g = zarr.open_group(out, mode="r")
    assert g.metadata.zarr_format == 3
    assert sorted(g.array_keys()) == sorted(["location", "histogram", *MODALITIES])
    h = g["histogram"]
    assert h.shape == (4, 3, 3, 3, 128) and h.dtype == np.int32 and h.chunks == (1, 3, 3, 3, 128)
    assert g["location"].dtype == np.int16
    for m, (hh, ww) in SHAPES.items():
        a = g[m]
        rgb = m.endswith("_rgb")
        assert a.dtype == (np.uint8 if rgb else np.uint16)
        assert a.shape == ((4, hh, ww, 3) if rgb else (4, hh, ww))
        assert a.chunks == (1, *a.shape[1:])  # one frame per chunk
    for name, shuffle in [("histogram", "shuffle"), ("tracking_depth", "bitshuffle"), ("tracking_rgb", "noshuffle")]:
        (codec,) = g[name].compressors
        cfg = codec.to_dict()["configuration"]
        assert (cfg["cname"], cfg["clevel"], cfg["shuffle"]) == ("zstd", 1, shuffle), name
    assert g["histogram"].metadata.dimension_names == ("location", "repeat", "zone_row", "zone_col", "bin")


def test_attributes(store):
    out, _ = store
    attrs = json.loads((out / "zarr.json").read_text())["attributes"]
    assert attrs["denali_store"] == STORE_VERSION
    assert (attrs["set"], attrs["object"], attrs["size"], attrs["resolution"], attrs["light"]) == (
        CS.name, "A", "4inch", "3x3", "lighton")  # fmt: skip
    assert (attrs["n_zones"], attrs["repeats"], attrs["n_bins"]) == (3, 3, 128)
    assert attrs["modalities"] == list(MODALITIES)
    assert attrs["frames"] == {"color_order": "BGR", "depth_unit": "mm"}
    assert attrs["metadata"] == {"object": "A", "locations": [0, 7, 42, 99], "grid": [10, 10], "gain": 0.5}
    assert attrs["source_format"] == "release"
    assert attrs["sources"] == [{"path": "x/metadata.json", "modality": "metadata", "bytes": 10, "sha256": "ab" * 32}]


# --- reader --------------------------------------------------------------------------------


def test_reader_round_trip(store):
    out, data = store
    s = open_set(out)
    assert isinstance(s, CaptureStore)
    assert s.name == CS.name and s.capture_set == CS and len(s) == 4
    assert s.locations.tolist() == [0, 7, 42, 99]
    assert (s.n_zones, s.repeats, s.modalities) == (3, 3, MODALITIES)
    assert s.metadata["locations"] == [0, 7, 42, 99]
    assert s.sources[0]["path"] == "x/metadata.json"
    assert isinstance(s.histograms, zarr.Array)  # lazy
    for i, k in enumerate(s.locations):
        assert np.array_equal(s.histogram(i), data[k][0])
        assert s.index_of(k) == i
    assert [k for k, _ in s.iter_histograms()] == [0, 7, 42, 99]
    for m in MODALITIES:
        got = list(s.iter_frames(m))
        assert [k for k, _ in got] == [0, 7, 42, 99]
        for k, frame in got:
            assert frame.dtype == data[k][1][m].dtype and np.array_equal(frame, data[k][1][m])
        assert np.array_equal(s.frame(m, 2), data[42][1][m])
    assert s.stored_bytes() > sum(s.stored_bytes(a) for a in ("histogram", *MODALITIES)) > 0


def test_reader_errors(store, tmp_path):
    out, _ = store
    s = open_set(out)
    with pytest.raises(KeyError, match="no gantry location 5"):
        s.index_of(5)
    with pytest.raises(IndexError, match="position 4 out of range"):
        s.histogram(4)
    with pytest.raises(KeyError, match="no 'depth' frames"):
        s.frames("depth")
    with pytest.raises(FileNotFoundError, match="missing.zarr: no such capture store"):
        open_set(tmp_path / "missing.zarr")
    (tmp_path / "empty.zarr").mkdir()
    with pytest.raises(ValueError, match="empty.zarr: not a Zarr v3 capture store"):
        open_set(tmp_path / "empty.zarr")
    zarr.open_group(tmp_path / "other.zarr", mode="w", zarr_format=3).attrs["x"] = 1
    with pytest.raises(ValueError, match="other.zarr: not a denali capture store"):
        open_set(tmp_path / "other.zarr")


def test_histogram_only_store(tmp_path):
    out = tmp_path / f"{CS.name}.zarr"
    with StoreWriter(out, CS, metadata={}, source_format="pickle") as w:  # repeats from the first histogram
        w.write_location(3, fake_location(3, repeats=2)[0])
    s = open_set(out)
    assert s.modalities == () and s.repeats == 2 and s.histogram(0).shape == (2, 3, 3, 128)


def test_grows_past_initial_capacity(tmp_path):
    out = tmp_path / f"{CS.name}.zarr"
    small = {"tracking_rgb": (4, 5), "tracking_depth": (4, 5)}
    with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release") as w:
        for k in range(40):
            w.write_location(k, *fake_location(k, shapes=small))
    s = open_set(out)
    assert len(s) == 40 and s.histograms.shape[0] == 40 and s.frames("tracking_rgb").shape == (40, 4, 5, 3)
    assert np.array_equal(s.histogram(39), fake_location(39, shapes=small)[0])
    assert s.histograms.nchunks_initialized == 40  # trimmed: no chunk beyond the last location


# --- checks and atomicity --------------------------------------------------------------------


def _bad_write(out: Path, action) -> Exception:
    with pytest.raises(ValueError) as e:
        with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release", frame_shapes={"tracking_rgb": (18, 32)}) as w:
            w.write_location(0, *fake_location(0))
            action(w)
    assert not out.exists()
    assert leftovers(out.parent) == []  # no temporary folder either
    return e.value


WRITER_CASES = [
    ("duplicate", lambda w: w.write_location(0, *fake_location(0)), "location 0: duplicated location"),
    (
        "shape",
        lambda w: w.write_location(1, np.zeros((3, 8, 8, 128), np.int32), fake_location(1)[1]),
        r"histogram shape \(3, 8, 8, 128\), expected \(3, 3, 3, 128\)",
    ),
    ("dtype", lambda w: w.write_location(1, fake_location(1)[0].astype(float), fake_location(1)[1]), "histogram dtype float64, expected int32"),
    (
        "frame size",
        lambda w: w.write_location(1, fake_location(1)[0], fake_location(1, shapes={**SHAPES, "tracking_depth": (9, 9)})[1]),
        r"tracking_depth frame is 9x9 \(WxH\), expected 32x18",
    ),
    (
        "frame dtype",
        lambda w: w.write_location(1, fake_location(1)[0], {**fake_location(1)[1], "colocated_depth": np.zeros((12, 21), np.float32)}),
        r"colocated_depth frame \(12, 21\) float32",
    ),
    ("modalities", lambda w: w.write_location(1, fake_location(1)[0], {"tracking_rgb": fake_location(1)[1]["tracking_rgb"]}), "but earlier locations had"),
    ("unknown", lambda w: w.write_location(1, fake_location(1)[0], {**fake_location(1)[1], "thermal": np.zeros(3)}), "unknown frame modalities"),
    ("error in block", lambda w: (_ for _ in ()).throw(ValueError("boom")), "boom"),
]


@pytest.mark.parametrize("case, action, message", WRITER_CASES, ids=[c[0] for c in WRITER_CASES])
def test_writer_refuses_and_leaves_nothing(tmp_path, case, action, message):
    err = _bad_write(tmp_path / f"{CS.name}.zarr", action)
    assert re.search(message, str(err)), str(err)


def test_writer_refuses_wrong_first_frame_size(tmp_path):
    out = tmp_path / f"{CS.name}.zarr"
    with pytest.raises(ValueError, match=r"tracking_rgb frame is 32x18 \(WxH\), expected 64x36"):
        with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release", frame_shapes={"tracking_rgb": (36, 64)}) as w:
            w.write_location(0, *fake_location(0))
    assert leftovers(tmp_path) == []


def test_no_locations_is_an_error(tmp_path):
    out = tmp_path / f"{CS.name}.zarr"
    with pytest.raises(ValueError, match="no locations were written"):
        with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release"):
            pass
    assert leftovers(tmp_path) == []


def test_failed_rewrite_keeps_the_old_store(tmp_path):
    out = tmp_path / f"{CS.name}.zarr"
    write_fake(out, [1, 2])
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(RuntimeError):
        with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release") as w:
            w.write_location(5, *fake_location(5))
            raise RuntimeError("interrupted")
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert leftovers(tmp_path) == [out.name]
    write_fake(out, [3])  # a successful rewrite replaces it
    assert open_set(out).locations.tolist() == [3]
    assert leftovers(tmp_path) == [out.name]


def test_jsonable():
    md = {"a": np.int64(3), "b": np.arange(3), "c": (1.5, np.float32(2)), "d": {"e": float("nan")}, 4: np.bool_(True)}
    assert jsonable(md) == {"a": 3, "b": [0, 1, 2], "c": [1.5, 2.0], "d": {"e": "nan"}, "4": True}
    with pytest.raises(ValueError, match=r"md\.x: a set cannot go into JSON"):
        jsonable({"x": {1}}, "md")


# --- streaming ----------------------------------------------------------------------------------


def test_peak_memory_does_not_grow_with_locations(tmp_path):
    shapes = {"tracking_rgb": (120, 160), "tracking_depth": (120, 160)}
    one = fake_location(0, shapes=shapes)

    def peak(n: int) -> int:
        out = tmp_path / f"{n}" / f"{CS.name}.zarr"
        tracemalloc.start()
        with StoreWriter(out, CS, repeats=3, metadata={}, source_format="release") as w:
            for k in range(n):
                w.write_location(k, *one)
        p = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return p

    frame_bytes = sum(f.nbytes for f in one[1].values())
    small, large = peak(5), peak(60)
    assert large < small + 4 * frame_bytes, (small, large)  # 60 locations would be 12x the frames
