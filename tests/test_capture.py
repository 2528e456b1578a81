"""The synthetic capture rig's writers (`rig/capture.py`): release layout,
pickle stream, determinism, noise, backgrounds and atomic outputs."""

from __future__ import annotations

import copy
import json
import pickle
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import ASSETS, REPO

from denali_pipe.core import geometry as geo
from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, parse_set_name
from denali_pipe.core.objects import load_catalogue
from denali_pipe.rig import capture

N_LOCATIONS = 3
REPEATS = 2
SCALE = 0.25
OBJECT_SETS = [f"A_8inch_{res}_{light}" for res in ("3x3", "8x8") for light in ("lighton", "lightoff")]
FRAME_DIRS = ("tracking_rgb", "tracking_depth", "colocated_rgb", "colocated_depth")  # the release layout
FLOOR_BINS = slice(0, 20)  # sensor-relative OPL < 0.47 m: before any wall return, floor only


# --- helpers ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_config(demo_config):
    cfg = copy.deepcopy(demo_config)
    cfg["rig"]["n_locations"] = N_LOCATIONS
    cfg["rig"]["repeats"] = REPEATS
    cfg["rig"]["frames"] = {"tracking_scale": SCALE, "colocated_scale": SCALE}
    return cfg


def synth(names, spec, config, out_dir: Path, fmt="release") -> list[Path]:
    """Run `synth_sets` for set names into `out_dir`; returns the output paths."""
    suffix = FOLDER_SUFFIX if fmt == "release" else PICKLE_SUFFIX
    outs = [out_dir / f"{n}{suffix}" for n in names]
    capture.synth_sets([parse_set_name(n) for n in names], spec, config, geo.TimeAxis.from_config(config["sensor"]["time_axis"]), outs, fmt)
    return outs


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file below `root` (relative path -> bytes)."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def hidden_entries(root: Path) -> list[str]:
    """Temporary (dot-named) files or folders anywhere below `root`."""
    return [str(p) for p in root.rglob(".*")]


def read_pickle_stream(path: Path) -> list:
    items = []
    with open(path, "rb") as f:
        while True:
            try:
                items.append(pickle.load(f))
            except EOFError:
                return items


def grey(bgr: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)


@pytest.fixture(scope="module")
def release_run(tmp_path_factory, catalogue, small_config):
    """A's 8inch sets, both resolutions and lightings, in the release layout."""
    out = tmp_path_factory.mktemp("release")
    return out, synth(OBJECT_SETS, catalogue["A"], small_config, out)


@pytest.fixture(scope="module")
def release_sets(release_run) -> dict[str, Path]:
    _, outs = release_run
    return {o.name.removesuffix(FOLDER_SUFFIX): o for o in outs}


def load_hists(set_dir: Path) -> dict[int, np.ndarray]:
    return {int(p.stem): np.load(p) for p in sorted((set_dir / "spad_histogram").iterdir())}


# --- release layout -------------------------------------------------------------------


def test_release_layout_exact(release_run, small_config):
    out, outs = release_run
    locations = geo.select_locations(N_LOCATIONS)
    stems = {f"{k:03d}" for k in locations}
    # exactly the four set folders, nothing else (no temporary folders)
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{n}{FOLDER_SUFFIX}" for n in OBJECT_SETS)
    assert hidden_entries(out) == []
    for set_dir in outs:
        assert set_dir.is_dir()
        expected = {"spad_histogram", *FRAME_DIRS, "metadata.json", "rig_truth.json"}
        assert {p.name for p in set_dir.iterdir()} == expected
        assert {p.name for p in (set_dir / "spad_histogram").iterdir()} == {f"{s}.npy" for s in stems}
        for mod in FRAME_DIRS:
            assert {p.name for p in (set_dir / mod).iterdir()} == {f"{s}.png" for s in stems}


def test_release_histograms(release_sets):
    for name, set_dir in release_sets.items():
        n = parse_set_name(name).n_zones
        hists = load_hists(set_dir)
        assert sorted(hists) == [int(k) for k in geo.select_locations(N_LOCATIONS)]
        for k, h in hists.items():
            assert h.shape == (REPEATS, n, n, geo.N_BINS), (name, k)
            assert h.dtype == np.int32
            assert (h >= 0).all()
            assert h.sum() > 0


def test_release_frames(release_sets):
    cams = {
        "tracking": geo.TRACKING_CAMERA.scaled(SCALE),
        "colocated": geo.COLOCATED_CAMERA.scaled(SCALE),
    }
    for set_dir in release_sets.values():
        for cam_name, cam in cams.items():
            for p in sorted((set_dir / f"{cam_name}_rgb").iterdir()):
                rgb = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
                assert rgb is not None, p
                assert rgb.dtype == np.uint8 and rgb.shape == (cam.height, cam.width, 3), (p, rgb.shape)
            for p in sorted((set_dir / f"{cam_name}_depth").iterdir()):
                depth = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
                assert depth is not None, p
                assert depth.dtype == np.uint16 and depth.shape == (cam.height, cam.width), (p, depth.shape)
                assert (depth > 0).any()  # the tables and the wall are within range


def test_tracking_frame_size_is_the_scaled_camera(release_sets):
    # the scaled real tracking camera (1280x720) at 0.25
    p = next(iter(sorted((release_sets["A_8inch_3x3_lighton"] / "tracking_rgb").iterdir())))
    assert cv2.imread(str(p), cv2.IMREAD_UNCHANGED).shape == (180, 320, 3)


def test_release_metadata(release_sets, small_config):
    locations = [int(k) for k in geo.select_locations(N_LOCATIONS)]
    for name, set_dir in release_sets.items():
        cs = parse_set_name(name)
        md = json.loads((set_dir / "metadata.json").read_text())
        fw = geo.FIRMWARE[cs.resolution]
        assert md["object"] == "A"
        assert md["size"] == "8inch"
        assert md["light"] == cs.light
        assert md["spad_res"] == cs.resolution
        assert md["range"] == "short"
        assert md["samples"] == REPEATS
        assert md["grid"] == list(geo.GRID_SHAPE)
        assert md["locations"] == locations
        assert md["kilo_iterations"] == fw.kilo_iterations
        assert md["spad_map"] == fw.spad_map
        assert md["period_ms"] == fw.period_ms
        assert md["n_bins"] == geo.N_BINS
        tracking = geo.TRACKING_CAMERA.scaled(SCALE)
        assert (md["tracking_camera"]["width"], md["tracking_camera"]["height"]) == (tracking.width, tracking.height)
        colocated = geo.COLOCATED_CAMERA.scaled(SCALE)
        assert (md["colocated_camera"]["width"], md["colocated_camera"]["height"]) == (colocated.width, colocated.height)


def test_release_truth(release_sets, small_config, catalogue):
    for name, set_dir in release_sets.items():
        truth = json.loads((set_dir / "rig_truth.json").read_text())
        assert truth["set"] == name
        assert truth["seed"] == small_config["seed"]
        assert truth["object"] == catalogue["A"].to_dict()
        assert truth["mount_post"] is True
        assert truth["photometry"] == small_config["rig"]["photometry"]
        assert sorted(truth["locations"], key=int) == [str(int(k)) for k in geo.select_locations(N_LOCATIONS)]
        assert truth["scene"]["source"] == "design"
        assert truth["static_tags"] == {str(i): p.to_dict() for i, p in geo.STATIC_TAGS.items()}


@pytest.mark.skipif(not (ASSETS / "poses.json").exists(), reason="the release's poses.json is not present")
def test_release_scene_frames_and_truth(tmp_path, small_config, release_sets):
    """rig.scene_poses puts the tracked tags where a release's poses.json has
    them; the truth records that scene; the hidden object rides on that
    scene's tag 1, so the histograms follow it too."""
    path = ASSETS / "poses.json"
    cfg = copy.deepcopy(small_config)
    cfg["rig"]["scene_poses"] = str(path)
    name = OBJECT_SETS[0]
    (out,) = synth([name], load_catalogue(REPO / "config" / "objects.tsv")["A"], cfg, tmp_path)
    doc = json.loads(path.read_text())
    truth = json.loads((out / "rig_truth.json").read_text())
    assert truth["scene"]["source"] == str(path)
    for i, p in truth["static_tags"].items():
        np.testing.assert_allclose(p["t"], doc["tracking_avgposes"][i]["center"])
    for k, rec in truth["locations"].items():
        np.testing.assert_allclose(np.subtract(rec["tag1"]["t"], rec["gantry_offset_m"]), doc["tracking_tag1_index_avgposes"][k]["center"])
        # the object is mounted on this tag 1: the mount offset, then the carriage's
        tag1 = geo.Pose(np.array(rec["tag1"]["R"]), np.array(rec["tag1"]["t"]))
        np.testing.assert_allclose(rec["object"]["t"], (tag1 @ geo.OBJECT_MOUNT).t, atol=1e-12)
    assert truth["scene"]["tables"]["15"]["normal"][2] < np.cos(np.radians(0.5))  # table 15 tilted
    design = json.loads((release_sets[name] / "rig_truth.json").read_text())
    for k, rec in truth["locations"].items():
        assert rec["gantry_offset_m"] == design["locations"][k]["gantry_offset_m"]
        assert rec["time_shift_bins"] == design["locations"][k]["time_shift_bins"]
    hists, design_hists = load_hists(out), load_hists(release_sets[name])
    assert any(not np.array_equal(h, design_hists[k]) for k, h in hists.items())
    assert not np.array_equal(cv2.imread(str(out / "tracking_rgb/000.png")), cv2.imread(str(release_sets[name] / "tracking_rgb/000.png")))


# --- determinism --------------------------------------------------------------------


def test_rerun_is_byte_identical(release_run, tmp_path, catalogue, small_config):
    out, _ = release_run
    again = tmp_path / "again"
    synth(OBJECT_SETS, catalogue["A"], small_config, again)
    first, second = snapshot(out), snapshot(again)
    assert sorted(first) == sorted(second)
    different = [rel for rel in first if first[rel] != second[rel]]
    assert different == []


def test_other_seed_changes_histograms(release_sets, tmp_path, catalogue, small_config):
    cfg = copy.deepcopy(small_config)
    cfg["seed"] = small_config["seed"] + 1
    name = "A_8inch_3x3_lighton"
    (out,) = synth([name], catalogue["A"], cfg, tmp_path)
    ref, new = load_hists(release_sets[name]), load_hists(out)
    assert sorted(ref) == sorted(new)
    for k in ref:
        assert not np.array_equal(ref[k], new[k]), k


# --- noise and lighting ----------------------------------------------------------------


def test_repeats_are_independent_draws(release_sets, small_config):
    read_var = small_config["rig"]["photometry"]["read_noise_counts"] ** 2
    for name, set_dir in release_sets.items():
        for k, h in load_hists(set_dir).items():
            assert not np.array_equal(h[0], h[1]), (name, k)
        if parse_set_name(name).resolution == "3x3":
            # independent Poisson + read noise: var(h0 - h1) ~ 2 (mean + read_var);
            # identical or correlated draws would give far less
            for k, h in load_hists(set_dir).items():
                # the floor before the direct return, where each capture's clock drift moves nothing
                d = h[0, ..., :30].astype(float) - h[1, ..., :30]
                expected = 2 * (h[..., :30].mean(0) + read_var).mean()
                assert 0.6 < d.var() / expected < 1.6, (name, k, d.var(), expected)


def _floor(set_dir: Path) -> np.ndarray:
    """Mean floor (early bins) per zone over repeats and locations, (n, n)."""
    h = np.stack(list(load_hists(set_dir).values()))  # (L, R, n, n, B)
    return h[..., FLOOR_BINS].mean(axis=(0, 1, 4))


@pytest.mark.parametrize("res", ["3x3", "8x8"])
def test_lights_on_raise_the_floor(release_sets, res):
    on = _floor(release_sets[f"A_8inch_{res}_lighton"])
    off = _floor(release_sets[f"A_8inch_{res}_lightoff"])
    if res == "3x3":
        # ~1400 vs ~800 counts per bin per zone: every zone
        assert (on > off * 1.3).all(), (on, off)
    else:
        # 8x8: 1000x fewer iterations, a fraction of a count per bin; overall only
        assert on.mean() > off.mean(), (on.mean(), off.mean())


def test_lights_off_tracking_frames_are_dark(release_sets):
    for name, set_dir in release_sets.items():
        for p in sorted((set_dir / "tracking_rgb").iterdir()):
            g = grey(cv2.imread(str(p), cv2.IMREAD_COLOR)).mean()
            if parse_set_name(name).light_on:
                assert g > 60, (p, g)
            else:
                assert g < 30, (p, g)


# --- backgrounds --------------------------------------------------------------------


@pytest.mark.parametrize("background", ["NOOBJECT", "NOOBJECTMOUNT"])
def test_background_sets(background, tmp_path, small_config):
    name = f"{background}_8inch_3x3_lighton"
    (out,) = synth([name], None, small_config, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == [out.name]
    hists = load_hists(out)
    assert sorted(hists) == [int(k) for k in geo.select_locations(N_LOCATIONS)]
    for h in hists.values():
        assert h.shape == (REPEATS, 3, 3, geo.N_BINS) and h.dtype == np.int32 and (h >= 0).all()
    md = json.loads((out / "metadata.json").read_text())
    assert md["object"] == background and md["size"] == "8inch"
    truth = json.loads((out / "rig_truth.json").read_text())
    assert truth["object"] is None and truth["material"] is None
    assert truth["mount_post"] is (background == "NOOBJECT")
    for mod in FRAME_DIRS:
        assert len(list((out / mod).iterdir())) == N_LOCATIONS


# --- pickle stream --------------------------------------------------------------------


@pytest.fixture(scope="module")
def pickle_run(tmp_path_factory, catalogue, small_config):
    out = tmp_path_factory.mktemp("pickle")
    return out, synth(OBJECT_SETS, catalogue["A"], small_config, out, fmt="pickle")


def test_pickle_stream(pickle_run, release_sets):
    out, outs = pickle_run
    expected_files = {f"{n}{PICKLE_SUFFIX}" for n in OBJECT_SETS} | {f"{n}_rig_truth.json" for n in OBJECT_SETS}
    assert {p.name for p in out.iterdir()} == expected_files
    locations = [int(k) for k in geo.select_locations(N_LOCATIONS)]
    for pkl in outs:
        name = pkl.name.removesuffix(PICKLE_SUFFIX)
        cs = parse_set_name(name)
        items = read_pickle_stream(pkl)
        metadata, records = items[0], items[1:]
        assert metadata == json.loads((release_sets[name] / "metadata.json").read_text())
        assert [r["iter"] for r in records] == locations
        ref = load_hists(release_sets[name])
        for r in records:
            assert set(r) == {"iter", "histogram", "spad_realsense_data", "tracking_realsense_data"}
            h = r["histogram"]
            assert h.dtype == np.int32 and h.shape == (REPEATS, cs.n_zones, cs.n_zones, geo.N_BINS)
            # same seeds as the release run: the same draws
            np.testing.assert_array_equal(h, ref[r["iter"]])
            for key, cam in (("spad_realsense_data", "colocated"), ("tracking_realsense_data", "tracking")):
                assert set(r[key]) == {"aligned_depth_image", "aligned_rgb_image"}
                rgb, depth = r[key]["aligned_rgb_image"], r[key]["aligned_depth_image"]
                assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3
                assert depth.dtype == np.uint16 and depth.shape == rgb.shape[:2]
                stem = f"{r['iter']:03d}.png"
                np.testing.assert_array_equal(rgb, cv2.imread(str(release_sets[name] / f"{cam}_rgb" / stem), cv2.IMREAD_UNCHANGED))
                np.testing.assert_array_equal(depth, cv2.imread(str(release_sets[name] / f"{cam}_depth" / stem), cv2.IMREAD_UNCHANGED))
        truth = json.loads((out / f"{name}_rig_truth.json").read_text())
        assert truth == json.loads((release_sets[name] / "rig_truth.json").read_text())


# --- public layout --------------------------------------------------------------------


def test_public_layout_is_the_published_release(release_sets, tmp_path, catalogue, small_config):
    cfg = copy.deepcopy(small_config)
    cfg["rig"]["layout"] = "public"
    names = ["A_8inch_3x3_lighton", "A_8inch_3x3_lightoff"]
    outs = synth(names, catalogue["A"], cfg, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{n}{FOLDER_SUFFIX}" for n in names)
    stems = [f"{int(k):03d}" for k in geo.select_locations(N_LOCATIONS)]
    for name, set_dir in zip(names, outs):
        # the release's two folders, plus the truth no stage reads; no metadata.json
        assert {p.name for p in set_dir.iterdir()} == {"spad_histogram", "tracking_rgb", "rig_truth.json"}
        assert sorted(p.name for p in (set_dir / "tracking_rgb").iterdir()) == [f"{s}.png" for s in stems]
        for stem in stems:
            # the real 1280x720 whatever rig.frames says (0.25 here)
            assert cv2.imread(str(set_dir / "tracking_rgb" / f"{stem}.png"), cv2.IMREAD_UNCHANGED).shape == (720, 1280, 3)
        # the layout changes what is written, not the physics
        ref = load_hists(release_sets[name])
        for k, h in load_hists(set_dir).items():
            np.testing.assert_array_equal(h, ref[k])
        truth = json.loads((set_dir / "rig_truth.json").read_text())
        assert set(truth["cameras"]) == {"tracking"}


def test_public_layout_is_for_release_folders_only(tmp_path, catalogue, small_config):
    cfg = copy.deepcopy(small_config)
    cfg["rig"]["layout"] = "public"
    with pytest.raises(ValueError, match="rig.layout 'public' is a release-folder layout"):
        synth(["A_8inch_3x3_lighton"], catalogue["A"], cfg, tmp_path, fmt="pickle")
    assert list(tmp_path.iterdir()) == []


# --- atomic outputs -------------------------------------------------------------------


class Boom(RuntimeError):
    pass


def fail_on_call(monkeypatch, attr: str, n: int):
    """Make `denali_pipe.rig.capture.<attr>` raise Boom on its n-th call."""
    real = getattr(capture, attr)
    calls = {"n": 0}

    def wrapped(*a, **kw):
        calls["n"] += 1
        if calls["n"] == n:
            raise Boom(f"{attr} call {n}")
        return real(*a, **kw)

    monkeypatch.setattr(capture, attr, wrapped)
    return calls


@pytest.mark.parametrize("fmt", ["release", "pickle"])
def test_failure_leaves_nothing(fmt, tmp_path, monkeypatch, catalogue, small_config):
    calls = fail_on_call(monkeypatch, "render_frame", 2)
    out = tmp_path / "raw"
    with pytest.raises(Boom):
        synth(OBJECT_SETS, catalogue["A"], small_config, out, fmt=fmt)
    assert calls["n"] == 2
    left = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert left == []  # no output, no temporary folder or file


def test_late_failure_leaves_nothing(tmp_path, monkeypatch, catalogue, small_config):
    """A failure after the last location (while writing the truth records)."""
    fail_on_call(monkeypatch, "truth_record", 2)
    out = tmp_path / "raw"
    with pytest.raises(Boom):
        synth(OBJECT_SETS, catalogue["A"], small_config, out)
    left = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert left == []


def test_failure_keeps_existing_output(tmp_path, monkeypatch, catalogue, small_config):
    out = tmp_path / "raw"
    synth(OBJECT_SETS, catalogue["A"], small_config, out)
    before = snapshot(out)
    cfg = copy.deepcopy(small_config)
    cfg["seed"] += 1  # a rerun that would change every histogram
    fail_on_call(monkeypatch, "render_frame", 2)
    with pytest.raises(Boom):
        synth(OBJECT_SETS, catalogue["A"], cfg, out)
    assert snapshot(out) == before
    assert hidden_entries(out) == []


def test_successful_rerun_replaces_existing_output(tmp_path, catalogue, small_config):
    name = "A_8inch_3x3_lighton"
    (out,) = synth([name], catalogue["A"], small_config, tmp_path)
    (out / "stray.txt").write_text("left over from an older layout")
    cfg = copy.deepcopy(small_config)
    cfg["seed"] += 1
    synth([name], catalogue["A"], cfg, tmp_path)
    assert not (out / "stray.txt").exists()
    assert json.loads((out / "rig_truth.json").read_text())["seed"] == cfg["seed"]
    assert hidden_entries(tmp_path) == []
    assert [p.name for p in tmp_path.iterdir()] == [out.name]


def test_pickle_late_failure_leaves_no_truth_sidecar(tmp_path, monkeypatch, catalogue, small_config):
    """A stream and its truth sidecar are published together: if a later set
    of the same job fails, neither is left behind."""
    fail_on_call(monkeypatch, "truth_record", 2)
    out = tmp_path / "raw"
    with pytest.raises(Boom):
        synth(OBJECT_SETS, catalogue["A"], small_config, out, fmt="pickle")
    left = sorted(p.name for p in out.iterdir()) if out.exists() else []
    assert left == []


def test_pickle_late_failure_keeps_existing_pair(tmp_path, monkeypatch, catalogue, small_config):
    """A failed rerun leaves the previous stream and its truth untouched."""
    out = tmp_path / "raw"
    synth(OBJECT_SETS, catalogue["A"], small_config, out, fmt="pickle")
    before = snapshot(out)
    cfg = copy.deepcopy(small_config)
    cfg["seed"] += 1
    fail_on_call(monkeypatch, "truth_record", 2)
    with pytest.raises(Boom):
        synth(OBJECT_SETS, catalogue["A"], cfg, out, fmt="pickle")
    after = snapshot(out)
    changed = sorted(rel for rel in before if after.get(rel) != before[rel])
    assert changed == []
    assert hidden_entries(out) == []


# --- argument checks --------------------------------------------------------------------


@pytest.mark.parametrize(
    "names",
    [
        ["A_8inch_3x3_lighton", "B_8inch_3x3_lighton"],
        ["A_8inch_3x3_lighton", "A_4inch_3x3_lighton"],
        ["NOOBJECT_8inch_3x3_lighton", "NOOBJECTMOUNT_8inch_3x3_lighton"],
    ],
)
def test_refuses_mixed_objects_or_sizes(names, tmp_path, catalogue, small_config):
    with pytest.raises(ValueError) as e:
        synth(names, catalogue["A"], small_config, tmp_path)
    for n in names:
        assert n in str(e.value)
    assert list(tmp_path.iterdir()) == []
