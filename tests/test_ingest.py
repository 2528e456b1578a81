"""Ingestion of one capture set (`ingest.py`): exact round trips from the
release layout and from pickle streams, index rows, checksums, and one test
per bad input, each leaving no store, no temporary folder and the raw input
untouched."""

from __future__ import annotations

import copy
import hashlib
import json
import pickle
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, parse_set_name
from denali_pipe.ingest.capture_set import INDEX_COLUMNS, ingest_pickle, ingest_release, ingest_set
from denali_pipe.io.pickle_stream import UnsafePickleError
from denali_pipe.io.release import FRAME_DIRS, location_span
from denali_pipe.io.store import open_set
from denali_pipe.rig import capture

N_LOCATIONS, REPEATS, SCALE = 3, 3, 0.25
OBJECT_SETS = ["A_8inch_3x3_lighton", "A_8inch_8x8_lightoff"]
BACKGROUND_SET = "NOOBJECT_8inch_3x3_lightoff"
GOOD = "A_8inch_3x3_lighton"


# --- fixtures and helpers -------------------------------------------------------------------


@pytest.fixture(scope="module")
def spec(catalogue):
    return catalogue["A"]


@pytest.fixture(scope="module")
def raw(tmp_path_factory, demo_config, spec) -> dict[str, Path]:
    """Rig output: release folders of OBJECT_SETS and BACKGROUND_SET, pickle
    streams of OBJECT_SETS (same config, so the same histograms and frames)."""
    cfg = copy.deepcopy(demo_config)
    cfg["rig"].update(n_locations=N_LOCATIONS, repeats=REPEATS, frames={"tracking_scale": SCALE, "colocated_scale": SCALE})
    rel, pkl = tmp_path_factory.mktemp("release"), tmp_path_factory.mktemp("pickle")
    sets = [parse_set_name(n) for n in OBJECT_SETS]
    capture.synth_sets(sets, spec, cfg, geo.TimeAxis.from_config(cfg["sensor"]["time_axis"]), [rel / f"{n}{FOLDER_SUFFIX}" for n in OBJECT_SETS], "release")
    capture.synth_sets(sets, spec, cfg, geo.TimeAxis.from_config(cfg["sensor"]["time_axis"]), [pkl / f"{n}{PICKLE_SUFFIX}" for n in OBJECT_SETS], "pickle")
    capture.synth_sets(
        [parse_set_name(BACKGROUND_SET)], None, cfg, geo.TimeAxis.from_config(cfg["sensor"]["time_axis"]), [rel / f"{BACKGROUND_SET}{FOLDER_SUFFIX}"], "release"
    )
    out = {n: rel / f"{n}{FOLDER_SUFFIX}" for n in [*OBJECT_SETS, BACKGROUND_SET]}
    out |= {f"{n}.pkl": pkl / f"{n}{PICKLE_SUFFIX}" for n in OBJECT_SETS}
    return out


@pytest.fixture(scope="module")
def stores(raw, spec, tmp_path_factory) -> dict[str, tuple[Path, pd.DataFrame]]:
    """Every raw set ingested once: name -> (store path, index rows)."""
    out = tmp_path_factory.mktemp("stores")
    result = {}
    for name in OBJECT_SETS:
        result[name] = (out / f"{name}.zarr", ingest_release(raw[name], out / f"{name}.zarr", spec))
        p = out / "pkl" / f"{name}.zarr"
        result[f"{name}.pkl"] = (p, ingest_pickle(raw[f"{name}.pkl"], p, spec))
    p = out / f"{BACKGROUND_SET}.zarr"
    result[BACKGROUND_SET] = (p, ingest_release(raw[BACKGROUND_SET], p, None))
    return result


def snapshot(root: Path) -> dict[str, bytes]:
    if root.is_file():
        return {root.name: root.read_bytes()}
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def expect_failure(source: Path, spec, *parts: str, error=ValueError) -> str:
    """Ingest `source` into a fresh output folder; it must raise `error` whose
    message contains every regex in `parts`, leave no store and no temporary
    folder, and leave the raw input byte-identical. Returns the message."""
    before = snapshot(source)
    out_dir = source.parent / "out"
    out_dir.mkdir(exist_ok=True)
    out = out_dir / f"{source.name.split('_NLOSdata')[0].removesuffix('_short')}.zarr"
    with pytest.raises(error) as e:
        ingest_set(source, out, spec)
    msg = str(e.value)
    for part in parts:
        assert re.search(part, msg), f"{part!r} not in {msg!r}"
    assert not out.exists()
    assert list(out_dir.iterdir()) == []  # no temporary folder either
    assert snapshot(source) == before  # raw input untouched
    return msg


@pytest.fixture
def good_copy(raw, tmp_path) -> Path:
    """A private copy of the good release set, to corrupt."""
    dst = tmp_path / raw[GOOD].name
    shutil.copytree(raw[GOOD], dst)
    return dst


@pytest.fixture
def good_stream(raw, tmp_path) -> tuple[Path, list]:
    """A private path for a pickle stream of GOOD and its records (to alter and write)."""
    src = raw[f"{GOOD}.pkl"]
    records = []
    with open(src, "rb") as f:
        while f.peek(1):
            records.append(pickle.load(f))  # our own rig's output: trusted
    return tmp_path / src.name, records


def write_stream(path: Path, records: list) -> Path:
    with open(path, "wb") as f:
        for r in records:
            pickle.dump(r, f, protocol=4)
    return path


def edit_metadata(set_dir: Path, **changes) -> None:
    p = set_dir / "metadata.json"
    md = json.loads(p.read_text())
    md.update(changes)
    p.write_text(json.dumps(md))


# --- round trips -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", [*OBJECT_SETS, BACKGROUND_SET])
def test_release_round_trip_is_exact(raw, stores, name):
    set_dir = raw[name]
    s = open_set(stores[name][0])
    assert s.name == name
    assert s.locations.tolist() == [int(k) for k in geo.select_locations(N_LOCATIONS)]
    assert s.modalities == FRAME_DIRS
    for i, k in enumerate(s.locations):
        h = np.load(set_dir / "spad_histogram" / f"{k:03d}.npy")
        got = s.histogram(i)
        assert got.dtype == np.int32 and np.array_equal(got, h)
        for m in FRAME_DIRS:
            png = cv2.imread(str(set_dir / m / f"{k:03d}.png"), cv2.IMREAD_UNCHANGED)
            frame = s.frame(m, i)
            assert frame.dtype == png.dtype and np.array_equal(frame, png), (name, k, m)
    assert s.metadata == json.loads((set_dir / "metadata.json").read_text())


def test_sources_and_checksums(raw, stores):
    set_dir = raw[GOOD]
    s = open_set(stores[GOOD][0])
    files = {p.relative_to(set_dir.parent).as_posix(): p for p in set_dir.rglob("*") if p.is_file() and p.name != "rig_truth.json"}
    assert sorted(src["path"] for src in s.sources) == sorted(files)
    for src in s.sources:
        data = files[src["path"]].read_bytes()
        assert src["sha256"] == hashlib.sha256(data).hexdigest() and src["bytes"] == len(data)
    assert {src["modality"] for src in s.sources} == {"metadata", "histogram", *FRAME_DIRS}
    assert s.attrs["source_format"] == "release"
    pkl = open_set(stores[f"{GOOD}.pkl"][0])
    data = raw[f"{GOOD}.pkl"].read_bytes()
    assert pkl.sources == [{"path": raw[f"{GOOD}.pkl"].name, "modality": "pickle", "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}]


@pytest.mark.parametrize("name", OBJECT_SETS)
def test_pickle_ingest_equals_release_ingest(stores, name):
    rel, pkl = open_set(stores[name][0]), open_set(stores[f"{name}.pkl"][0])
    assert pkl.locations.tolist() == rel.locations.tolist()
    assert np.array_equal(pkl.histograms[:], rel.histograms[:])
    for m in FRAME_DIRS:
        assert np.array_equal(pkl.frames(m)[:], rel.frames(m)[:]), m
    assert pkl.metadata == rel.metadata
    pd.testing.assert_frame_equal(stores[f"{name}.pkl"][1], stores[name][1])


def test_index_rows(raw, stores, spec):
    df = stores[GOOD][1]
    assert list(df.columns) == list(INDEX_COLUMNS)
    locations = [int(k) for k in geo.select_locations(N_LOCATIONS)]
    assert len(df) == N_LOCATIONS * REPEATS
    assert df["location"].tolist() == [k for k in locations for _ in range(REPEATS)]
    assert df["repeat"].tolist() == list(range(REPEATS)) * N_LOCATIONS
    cs = parse_set_name(GOOD)
    for col, value in [("set", GOOD), ("object", "A"), ("class", spec.cls), ("type", spec.type), ("size", cs.size),
                       ("resolution", cs.resolution), ("light", cs.light)]:  # fmt: skip
        assert (df[col] == value).all(), col
    row, col = geo.gantry_row_col(df["location"].to_numpy())
    assert df["gantry_row"].tolist() == row.tolist() and df["gantry_col"].tolist() == col.tolist()
    for r in df.itertuples():
        h = np.load(raw[GOOD] / "spad_histogram" / f"{r.location:03d}.npy")
        assert r.total_counts == int(h[r.repeat].sum(dtype=np.int64))
    for c in ("location", "repeat", "gantry_row", "gantry_col", "total_counts"):
        assert df[c].dtype == np.int64


def test_background_index_rows(stores):
    df = stores[BACKGROUND_SET][1]
    assert (df["class"] == "none").all() and (df["type"] == "background").all()
    assert (df["object"] == "NOOBJECT").all() and (df["size"] == "8inch").all()
    assert (df["total_counts"] > 0).all()


def test_integral_float_histograms_are_accepted(good_copy, spec, tmp_path):
    p = good_copy / "spad_histogram" / "050.npy"
    h = np.load(p)
    np.save(p, h.astype(np.float64))
    ingest_release(good_copy, tmp_path / "f.zarr", spec)
    s = open_set(tmp_path / "f.zarr")
    assert s.histograms.dtype == np.int32 and np.array_equal(s.histogram(s.index_of(50)), h)


def test_metadata_without_camera_sizes_uses_first_frame(good_copy, spec, tmp_path):
    md = json.loads((good_copy / "metadata.json").read_text())
    del md["tracking_camera"], md["colocated_camera"]
    (good_copy / "metadata.json").write_text(json.dumps(md))
    ingest_release(good_copy, tmp_path / "ok.zarr", spec)
    p = good_copy / "tracking_depth" / "099.png"
    cv2.imwrite(str(p), np.zeros((10, 12), np.uint16))
    expect_failure(good_copy, spec, re.escape(str(p)), r"tracking_depth frame: size 12x10 \(WxH\), expected 320x180, the first frame's size")


def test_pickle_in_the_capture_scripts_format(good_stream, stores, spec, tmp_path):
    """The real script wraps its metadata ({"metadata": {...}}), lists no
    locations and states camera sizes in realsense_configs."""
    path, records = good_stream
    md = records[0]
    cams = {f"{cam}_realsense": {"color_width": md[f"{cam}_camera"]["width"], "color_height": md[f"{cam}_camera"]["height"]}
            for cam in ("tracking", "colocated")}  # fmt: skip
    records[0] = {"metadata": {"object": f"{GOOD}_short", "start_time": "2025-01-01T00:00:00", "samples_per_capture": 3,
                               "light_mode": "lighton", "spad_res": "ID6", "realsense_configs": cams}}  # fmt: skip
    write_stream(path, records)
    ingest_pickle(path, tmp_path / "real.zarr", spec)
    s, ref = open_set(tmp_path / "real.zarr"), open_set(stores[GOOD][0])
    assert s.metadata == records[0]["metadata"]
    assert np.array_equal(s.histograms[:], ref.histograms[:]) and s.locations.tolist() == ref.locations.tolist()
    records[2]["tracking_realsense_data"]["aligned_rgb_image"] = records[2]["tracking_realsense_data"]["aligned_rgb_image"][:-1]
    write_stream(path, records)
    expect_failure(path, spec, GOOD, r"size 320x179 \(WxH\), expected 320x180, the metadata's camera size")
    records[0]["metadata"]["spad_res"] = "ID15"
    write_stream(path, records)
    expect_failure(path, spec, GOOD, r"`spad_res` is 'ID15' \(the SPAD map of 8x8\) but the set name says '3x3'")


def test_ingest_set_dispatches_on_the_path(raw, spec, tmp_path):
    before = snapshot(raw[GOOD]), snapshot(raw[f"{GOOD}.pkl"])
    ingest_set(raw[f"{GOOD}.pkl"], tmp_path / "a.zarr", spec)
    ingest_set(raw[GOOD], tmp_path / "b.zarr", spec)
    assert np.array_equal(open_set(tmp_path / "a.zarr").histograms[:], open_set(tmp_path / "b.zarr").histograms[:])
    assert (snapshot(raw[GOOD]), snapshot(raw[f"{GOOD}.pkl"])) == before  # raw input is only read
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.zarr", "b.zarr"]  # no temporary folders
    with pytest.raises(FileNotFoundError, match="no such capture set folder or capture stream"):
        ingest_set(tmp_path / f"{GOOD}_NLOSdata", tmp_path / "c.zarr", spec)


def test_wrong_spec(raw, catalogue, good_copy):
    expect_failure(good_copy, None, GOOD, "an object spec for 'A' is required")
    expect_failure(good_copy, catalogue["1"], GOOD, "object spec is for '1', expected 'A'")


# --- bad release input: one test per case ----------------------------------------------------------


def test_truncated_npy(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    p.write_bytes(p.read_bytes()[:-100])
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "truncated or unreadable .npy")


def test_histogram_wrong_shape(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    np.save(p, np.zeros((3, 8, 8, 128), np.int32))
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"expected shape \(repeats, 3, 3, 128\) for a 3x3 set, found \(3, 8, 8, 128\)")


def test_histogram_wrong_repeats(good_copy, spec):
    p = good_copy / "spad_histogram" / "099.npy"
    np.save(p, np.load(p)[:2])
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"expected 3 repeats .* found shape \(2, 3, 3, 128\)")


def test_histogram_wrong_dtype(good_copy, spec):
    p = good_copy / "spad_histogram" / "000.npy"
    np.save(p, np.load(p).astype(np.complex64))
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "expected integer counts, found dtype complex64")


def test_histogram_negative_counts(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    h = np.load(p)
    h[1, 0, 0, 5] = -3
    np.save(p, h)
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"1 negative counts \(minimum -3\)")


def test_histogram_nan(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    h = np.load(p).astype(np.float32)
    h[0, 1, 1, 10] = np.nan
    np.save(p, h)
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "float counts with 1 NaN and 0 infinite values")


def test_histogram_non_integral_float(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    h = np.load(p).astype(np.float64)
    h[0, 0, 0, 0] += 0.5
    np.save(p, h)
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "float counts that are not integral")


def test_histogram_exceeds_int32(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    h = np.load(p).astype(np.int64)
    h[0, 0, 0, 0] = 2**31
    np.save(p, h)
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "exceed int32")


def test_missing_histogram_file(good_copy, spec):
    p = good_copy / "spad_histogram" / "050.npy"
    p.unlink()
    expect_failure(
        good_copy,
        spec,
        re.escape(str(p)),
        GOOD,
        r"missing location file\(s\) for location\(s\) \[50\]: spad_histogram/ holds \d+ location\(s\) \(.*\), metadata.json lists",
    )


def test_unlisted_histogram_file(good_copy, spec):
    shutil.copy(good_copy / "spad_histogram" / "050.npy", good_copy / "spad_histogram" / "051.npy")
    expect_failure(
        good_copy,
        spec,
        "051.npy",
        GOOD,
        r"location\(s\) \[51\] in spad_histogram/ are not among the set's locations: spad_histogram/ holds .*, metadata.json lists",
    )


def test_missing_frame_png(good_copy, spec):
    p = good_copy / "colocated_depth" / "099.png"
    p.unlink()
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"missing location file\(s\) for location\(s\) \[99\]")


def test_unreadable_png(good_copy, spec):
    p = good_copy / "tracking_rgb" / "050.png"
    p.write_bytes(p.read_bytes()[:200])
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "unreadable PNG")


def test_frame_wrong_size(good_copy, spec):
    p = good_copy / "tracking_rgb" / "050.png"
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(p), img[:-2])
    h, w = img.shape[:2]
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, rf"tracking_rgb frame: size {w}x{h - 2} \(WxH\), expected {w}x{h}, the metadata's camera size")


def test_frame_wrong_channels(good_copy, spec):
    p = good_copy / "colocated_rgb" / "000.png"
    cv2.imwrite(str(p), cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2GRAY))
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"expected a \(H, W, 3\) BGR uint8 image, found shape \(\d+, \d+\) dtype uint8")


def test_depth_wrong_dtype(good_copy, spec):
    p = good_copy / "tracking_depth" / "000.png"
    cv2.imwrite(str(p), (cv2.imread(str(p), cv2.IMREAD_UNCHANGED) // 256).astype(np.uint8))
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, r"expected a \(H, W\) uint16 image, found shape \(\d+, \d+\) dtype uint8")


def test_folder_name_does_not_parse(good_copy, spec):
    bad = good_copy.with_name("A_9inch_3x3_lighton_NLOSdata")
    good_copy.rename(bad)
    expect_failure(bad, spec, re.escape(str(bad)), "capture set folder name does not parse", "<4inch|8inch>")


def test_the_capture_scripts_folder_name_is_refused_with_the_rename(good_copy, spec):
    bad = good_copy.with_name(good_copy.name.replace(FOLDER_SUFFIX, f"_short{FOLDER_SUFFIX}"))
    good_copy.rename(bad)
    expect_failure(
        bad, spec, re.escape(f"{bad}: capture set folder name does not parse: the capture script's `_short` range suffix"), f"rename it to {good_copy.name}"
    )


def test_release_without_metadata_like_the_public_release(good_copy, spec, stores, tmp_path):
    # the public release has no metadata.json and only tracking_rgb frames
    (good_copy / "metadata.json").unlink()
    for m in ("tracking_depth", "colocated_rgb", "colocated_depth"):
        shutil.rmtree(good_copy / m)
    out = tmp_path / "bare.zarr"
    index = ingest_release(good_copy, out, spec)
    full = open_set(stores[GOOD][0])
    bare = open_set(out)
    assert list(bare.locations) == list(full.locations)
    assert np.array_equal(bare.histograms[:], full.histograms[:])
    assert tuple(bare.modalities) == ("tracking_rgb",)
    assert len(index) == len(stores[GOOD][1])


def test_missing_histogram_without_metadata(good_copy, spec):
    (good_copy / "metadata.json").unlink()
    p = good_copy / "tracking_rgb" / "000.png"
    (good_copy / "spad_histogram" / "000.npy").unlink()
    # no metadata.json: spad_histogram/ names the locations, and the message says so (not "metadata.json")
    locations = sorted(int(q.stem) for q in (good_copy / "tracking_rgb").iterdir())
    held = location_span(locations)
    kept = location_span(locations[1:])
    expect_failure(
        good_copy, spec, re.escape(str(p)), GOOD,
        re.escape(f"location(s) [0] in tracking_rgb/ are not among the set's locations: tracking_rgb/ holds {len(locations)} location(s) ({held}), "
                  f"spad_histogram/ (which names the locations: no metadata.json) holds {len(locations) - 1} ({kept})"),
    )  # fmt: skip


def test_missing_frame_without_metadata_names_what_is_there(good_copy, spec):
    (good_copy / "metadata.json").unlink()
    locations = sorted(int(q.stem) for q in (good_copy / "spad_histogram").iterdir())
    p = good_copy / "tracking_rgb" / f"{locations[-1]:03d}.png"
    p.unlink()
    expect_failure(
        good_copy, spec, re.escape(str(p)), GOOD,
        re.escape(f"missing location file(s) for location(s) [{locations[-1]}]: tracking_rgb/ holds {len(locations) - 1} location(s) "
                  f"({location_span(locations[:-1])}), spad_histogram/ (which names the locations: no metadata.json) holds {len(locations)}"),
    )  # fmt: skip


@pytest.mark.parametrize("histogram_dir", [False, True], ids=["empty folder", "empty spad_histogram"])
def test_an_empty_set_folder_is_refused_with_what_a_public_layout_set_holds(tmp_path, spec, histogram_dir):
    empty = tmp_path / f"{GOOD}{FOLDER_SUFFIX}"
    empty.mkdir()
    if histogram_dir:
        (empty / "spad_histogram").mkdir()
    named = re.escape(str(empty / "spad_histogram") if histogram_dir else f"{empty}: no spad_histogram/ folder")
    msg = expect_failure(
        empty, spec, named, r"a public-layout (capture )?set holds spad_histogram/NNN\.npy \(one \(3 repeats, n, n, 128\) count array per gantry location",
        r"tracking_rgb/NNN\.png", r"and no metadata\.json$", error=ValueError if histogram_dir else FileNotFoundError,
    )  # fmt: skip
    assert str(empty / "metadata.json") not in msg  # the public layout has none: no file of that name is cited


def test_metadata_invalid_json(good_copy, spec):
    p = good_copy / "metadata.json"
    p.write_text(p.read_text()[:-20])
    expect_failure(good_copy, spec, re.escape(str(p)), GOOD, "invalid JSON")


def test_metadata_without_locations(good_copy, spec):
    md = json.loads((good_copy / "metadata.json").read_text())
    del md["locations"]
    (good_copy / "metadata.json").write_text(json.dumps(md))
    expect_failure(good_copy, spec, "metadata.json", GOOD, "no `locations` list")


def test_metadata_duplicated_location(good_copy, spec):
    edit_metadata(good_copy, locations=[0, 50, 50, 99])
    expect_failure(good_copy, spec, "metadata.json", GOOD, r"duplicated location\(s\) \[50\]")


def test_metadata_contradicts_set_name(good_copy, spec):
    edit_metadata(good_copy, spad_res="8x8")
    expect_failure(good_copy, spec, "metadata.json", GOOD, "`spad_res` is '8x8' but the set name says '3x3'")


def test_metadata_samples_mismatch(good_copy, spec):
    edit_metadata(good_copy, samples=5)
    expect_failure(good_copy, spec, "000.npy", GOOD, r"expected 5 repeats")


# --- bad pickle input: one test per case -----------------------------------------------------------


def test_pickle_cut_mid_record(good_stream, spec):
    path, records = good_stream
    write_stream(path, records)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 5000])
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 3 is cut or corrupt", "truncated")


def test_pickle_duplicated_location(good_stream, spec):
    path, records = good_stream
    records[3]["iter"] = records[1]["iter"]
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 3: duplicated location 0 \(also record 1\)")


def test_pickle_missing_metadata_record(good_stream, spec):
    path, records = good_stream
    write_stream(path, records[1:])
    expect_failure(path, spec, re.escape(str(path)), GOOD, "record 0 is a location record", "metadata record is missing")


def test_pickle_missing_location_record(good_stream, spec):
    path, records = good_stream
    write_stream(path, records[:-1])
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"missing location records \[99\]")


def test_pickle_unlisted_location(good_stream, spec):
    path, records = good_stream
    records[2]["iter"] = 7
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 2: location 7 is not among the metadata's locations")


def test_pickle_record_not_a_dict(good_stream, spec):
    path, records = good_stream
    records[2] = ("iter", 50)
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 2 is a tuple, expected a dict")


def test_pickle_record_lacks_keys(good_stream, spec):
    path, records = good_stream
    del records[2]["spad_realsense_data"]
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 2 lacks keys \['spad_realsense_data'\]")


def test_pickle_histogram_negative(good_stream, spec):
    path, records = good_stream
    records[1]["histogram"][0, 0, 0, 0] = -1
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, r"record 1 \(location 0\) histogram: 1 negative counts")


def test_pickle_frame_wrong_size(good_stream, spec):
    path, records = good_stream
    d = records[2]["tracking_realsense_data"]
    d["aligned_depth_image"] = d["aligned_depth_image"][:, :-4]
    write_stream(path, records)
    expect_failure(
        path, spec, re.escape(str(path)), GOOD, r"record 2 \(location 50\) tracking_realsense_data.aligned_depth_image: size 316x180 \(WxH\), expected 320x180"
    )


def test_pickle_unsafe_global(good_stream, spec, tmp_path):
    import os

    target = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return os.system, (f"touch {target}",)

    path, records = good_stream
    records[2]["histogram"] = Evil()
    write_stream(path, records)
    expect_failure(path, spec, re.escape(str(path)), GOOD, "record 2", f"global {os.system.__module__}.system", error=UnsafePickleError)
    assert not target.exists()


def test_pickle_name_does_not_parse(good_stream, spec):
    path, records = good_stream
    bad = write_stream(path.with_name("A_8inch_3x3_lighton_NLOSdata.pkl"), records)
    expect_failure(bad, spec, re.escape(str(bad)), "capture stream name does not parse", "_short_NLOSdata.pkl")
