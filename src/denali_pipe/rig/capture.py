"""Synthesise capture sets in the release layout or as raw pickle streams.

Release layout (what the real rig's converter writes), `rig.layout: full`:

    <set>_NLOSdata/
      spad_histogram/NNN.npy     (repeats, n, n, 128) int32, NNN = gantry location
      tracking_rgb/NNN.png       BGR uint8
      tracking_depth/NNN.png     uint16, mm
      colocated_rgb/NNN.png      BGR uint8
      colocated_depth/NNN.png    uint16, mm
      metadata.json              the capture's metadata record
      rig_truth.json             every true parameter (validation only)

`rig.layout: public` writes what the published release holds instead:
spad_histogram/ and tracking_rgb/ only, the tracking frames at the real
camera's 1280x720 whatever `rig.frames` says, no metadata.json (and
rig_truth.json, which no stage reads).

Pickle stream `<set>_short_NLOSdata.pkl`: the metadata record, then one
record per location {iter, histogram, spad_realsense_data,
tracking_realsense_data}, as the capture script writes it; the rig's truth
goes beside it as `<set>_rig_truth.json`.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
from contextlib import ExitStack
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.atomic import atomic_dir, atomic_file
from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, CaptureSet
from denali_pipe.core.objects import BACKGROUND_SIZE, ObjectSpec
from denali_pipe.core.seeds import rng_for
from denali_pipe.io.release import FRAME_DIRS, HISTOGRAM_DIR, METADATA_FILE, PUBLIC_FRAME_DIRS
from denali_pipe.rig.frames import frame_tags, render_frame
from denali_pipe.rig.histograms import Photometry, Scatterer, counts_from_transport, sample_counts, transport
from denali_pipe.rig.nuisances import SetNuisance, capture_conditions, draw_set, gantry_offset
from denali_pipe.rig.scene import mount_scatterer, object_scatterer
from denali_pipe.rig.tracked_scene import TrackedScene, tracked_scene

# Fast, lossless (ingest recompresses anyway): the frames' sensor noise leaves
# little for deflate's string matching, and run-length matching alone is 30 %
# faster and 10 % smaller than zlib level 1's default (640x360 RGB: 15 against
# 21 ms, 417 against 467 kB).
PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE]
TRUTH_FILE = "rig_truth.json"


def _cameras(rig_cfg: dict) -> dict[str, geo.Camera]:
    """The cameras whose frames the layout holds: both RealSenses at the
    configured fractions of their real size (`full`), or the tracking camera
    alone at its real size (`public`, as the published release)."""
    if rig_cfg["layout"] == "public":
        return {"tracking": geo.TRACKING_CAMERA}
    frames = rig_cfg["frames"]
    return {
        "tracking": geo.TRACKING_CAMERA.scaled(frames["tracking_scale"]),
        "colocated": geo.COLOCATED_CAMERA.scaled(frames["colocated_scale"]),
    }


def _camera_record(cam: geo.Camera) -> dict:
    return {**cam.intrinsics.to_dict(), "R_world_to_camera": cam.R_wc.tolist(), "t_world_to_camera": cam.t_wc.tolist()}


def metadata_record(cs: CaptureSet, locations: np.ndarray, rig_cfg: dict, axis: geo.TimeAxis) -> dict:
    """The capture's metadata record (the fields the real capture script writes,
    plus the firmware and camera settings and the bins' width on `axis`). No
    wall-clock time, so reruns are byte-identical."""
    fw = geo.FIRMWARE[cs.resolution]
    return {
        "object": cs.object,
        "size": cs.size,
        "light": cs.light,
        "spad_res": cs.resolution,
        "range": "short",
        "samples": rig_cfg["repeats"],
        "grid": list(geo.GRID_SHAPE),
        "locations": [int(k) for k in locations],
        "n_bins": geo.N_BINS,
        "bin_width_opl_m": axis.bin_width_opl,
        "spad_map": fw.spad_map,
        "period_ms": fw.period_ms,
        "kilo_iterations": fw.kilo_iterations,
        **{f"{name}_camera": cam.intrinsics.to_dict() for name, cam in _cameras(rig_cfg).items()},
        "source": "denali-pipe synthetic rig",
    }


def truth_record(cs: CaptureSet, spec: ObjectSpec | None, locations: np.ndarray, config: dict, scene: TrackedScene) -> dict:
    """Every true parameter of the set, the nuisances drawn included, and the
    tracked scene its frames show. For validation only: no stage reads it."""
    rig = config["rig"]
    nuisance = draw_set(rig["nuisances"], config["seed"], cs.name)
    return {
        "set": cs.name,
        "seed": config["seed"],
        "object": None if spec is None else spec.to_dict(),
        "material": None if spec is None else dataclasses.asdict(spec.material_params),
        "mount_post": cs.object != "NOOBJECTMOUNT",
        "photometry": rig["photometry"],
        "nuisances": {"config": rig["nuisances"], "set": nuisance.to_dict()},
        "firmware": dataclasses.asdict(geo.FIRMWARE[cs.resolution]),
        "sensor": {"position": geo.SENSOR_POSITION.tolist(), "forward": geo.SENSOR_FORWARD.tolist(), "fov_deg": list(geo.SENSOR_FOV_DEG)},
        "wall": {"centre": geo.WALL.centre.tolist(), "size": list(geo.WALL.size), "normal": geo.WALL.normal.tolist()},
        "cameras": {name: _camera_record(cam) for name, cam in _cameras(rig).items()},
        "scene": scene.to_dict(),
        "static_tags": {str(i): p.to_dict() for i, p in scene.static_tags.items()},
        "locations": {str(int(k)): _location_truth(cs, int(k), nuisance, config, scene) for k in locations},
    }


def _location_truth(cs: CaptureSet, k: int, nuisance: SetNuisance, config: dict, scene: TrackedScene) -> dict:
    nuisances, seed = config["rig"]["nuisances"], config["seed"]
    subcaptures = geo.FIRMWARE[cs.resolution].subcaptures
    offset = gantry_offset(nuisances, seed, cs.name, k)
    obj = nuisance.object_pose(scene.tag1_pose(k), offset)
    return {
        "tag1": frame_tags(k, "tracking", tuple(offset), scene)[geo.OBJECT_TAG_ID].to_dict(),
        "object": obj.to_dict(),
        "gantry_offset_m": offset.tolist(),
        "time_shift_bins": [
            list(capture_conditions(nuisances, seed, cs.name, k, r, nuisance, subcaptures).time_shift_bins) for r in range(config["rig"]["repeats"])
        ],
        "wall_distance_m": float(geo.wall_distance(obj.t)),
    }


def _scene(cs: CaptureSet, spec: ObjectSpec | None, tag1: geo.Pose, offset: np.ndarray, nuisance: SetNuisance) -> list[Scatterer]:
    """The hidden scene of set `cs` at the gantry location where tag 1 sits at
    `tag1`, the carriage moved by `offset` (m)."""
    obj = nuisance.object_pose(tag1, offset)
    scene = [] if cs.object == "NOOBJECTMOUNT" else [mount_scatterer(obj.t)]
    if spec is not None:
        scene.append(object_scatterer(spec, cs.size, obj))
    return scene


def _record(cs: CaptureSet, spec: ObjectSpec | None, k: int, nuisance: SetNuisance, config: dict, phot: Photometry, scene: TrackedScene) -> dict:
    """One location of one set: the histograms of every repeat and both cameras' RGB-D frames."""
    rig, seed = config["rig"], config["seed"]
    offset = gantry_offset(rig["nuisances"], seed, cs.name, k)
    light = transport(cs.resolution, _scene(cs, spec, scene.tag1_pose(k), offset, nuisance), phot)
    hist = np.stack(
        [
            sample_counts(
                counts_from_transport(
                    cs.resolution,
                    cs.light_on,
                    light,
                    phot,
                    capture_conditions(rig["nuisances"], seed, cs.name, k, r, nuisance, geo.FIRMWARE[cs.resolution].subcaptures),
                ),
                phot,
                rng_for(seed, cs.name, k, r),
            )
            for r in range(rig["repeats"])
        ]
    )
    frames = {
        name: render_frame(cam, frame_tags(k, name, tuple(offset), scene), cs.light_on, rng_for(seed, cs.name, k, name), scene=scene)
        for name, cam in _cameras(rig).items()
    }
    return {"iter": k, "histogram": hist, "frames": frames}


def synth_sets(sets: list[CaptureSet], spec: ObjectSpec | None, config: dict, axis: geo.TimeAxis, outs: list[Path], fmt: str) -> None:
    """Write capture sets of one object and size (any resolutions and lightings)
    to `outs`: release folders in `rig.layout` (fmt `release`) or pickle
    streams (fmt `pickle`, layout `full` only), histograms on `axis`.
    Each output is written atomically. Every set is its own mounting and
    session (`rig.nuisances`), so each computes its own light transport."""
    if len({(s.object, s.size) for s in sets}) != 1:
        raise ValueError(f"synth_sets takes sets of one object and size, got {[s.name for s in sets]}")
    if len(outs) != len(sets):
        raise ValueError(f"synth_sets: {len(sets)} sets but {len(outs)} outputs")
    suffix = {"release": FOLDER_SUFFIX, "pickle": PICKLE_SUFFIX}[fmt]
    layout = config["rig"]["layout"]
    if fmt == "pickle" and layout != "full":
        raise ValueError(f"rig.layout {layout!r} is a release-folder layout: a pickle stream holds both cameras' frames (use layout full)")
    for cs, out in zip(sets, outs):
        if Path(out).name != cs.name + suffix:
            raise ValueError(f"output {out} of capture set {cs.name}: a {fmt} output is named {cs.name}{suffix}")
        if cs.is_background and cs.size != BACKGROUND_SIZE:
            raise ValueError(f"capture set {cs.name}: background sets are captured at {BACKGROUND_SIZE} only")
    locations = geo.select_locations(config["rig"]["n_locations"])
    writer = {"release": partial(_ReleaseWriter, layout=layout), "pickle": _PickleWriter}[fmt]
    nuisances = {cs.name: draw_set(config["rig"]["nuisances"], config["seed"], cs.name) for cs in sets}
    scene = tracked_scene(config["rig"]["scene_poses"])
    phot = Photometry.from_config(config["rig"]["photometry"], axis)
    with ExitStack() as stack:
        writers = [stack.enter_context(writer(out, metadata_record(cs, locations, config["rig"], axis))) for cs, out in zip(sets, outs)]
        for k in map(int, locations):
            for cs, w in zip(sets, writers):
                w.add(_record(cs, spec, k, nuisances[cs.name], config, phot, scene))
        for cs, w in zip(sets, writers):
            w.finish(truth_record(cs, spec, locations, config, scene))


class _ReleaseWriter:
    """`<set>_NLOSdata/` in the release layout, built in a temporary folder:
    every frame folder and metadata.json (`full`), or only the published
    release's frame folders and no metadata.json (`public`)."""

    def __init__(self, out: Path, metadata: dict, layout: str):
        self.out = out
        self.metadata = metadata if layout == "full" else None
        self.frame_dirs = FRAME_DIRS if layout == "full" else PUBLIC_FRAME_DIRS
        self._ctx = atomic_dir(out)

    def __enter__(self):
        self.tmp = self._ctx.__enter__()
        for sub in (HISTOGRAM_DIR, *self.frame_dirs):
            (self.tmp / sub).mkdir()
        return self

    def add(self, rec: dict) -> None:
        name = f"{rec['iter']:03d}"
        np.save(self.tmp / HISTOGRAM_DIR / f"{name}.npy", rec["histogram"])
        for cam, (rgb, depth) in rec["frames"].items():
            for sub, img in ((f"{cam}_rgb", rgb), (f"{cam}_depth", depth)):
                if sub in self.frame_dirs:
                    cv2.imwrite(str(self.tmp / sub / f"{name}.png"), img, PNG_PARAMS)

    def finish(self, truth: dict) -> None:
        if self.metadata is not None:
            _write_json(self.tmp / METADATA_FILE, self.metadata)
        _write_json(self.tmp / TRUTH_FILE, truth)

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


class _PickleWriter:
    """`<set>_short_NLOSdata.pkl`: the metadata record, then one record per
    location, as the capture script pickles them. The rig's truth goes beside
    it as `<set>_rig_truth.json`; both are published together at exit."""

    def __init__(self, out: Path, metadata: dict):
        self.metadata = metadata
        truth = out.with_name(f"{out.name.removesuffix(PICKLE_SUFFIX)}_{TRUTH_FILE}")
        self._stack = ExitStack()
        self._contexts = (atomic_file(truth), atomic_file(out))  # exited last-first: the stream, then its truth

    def __enter__(self):
        self.truth_tmp, tmp = (self._stack.enter_context(c) for c in self._contexts)
        self.f = self._stack.enter_context(open(tmp, "wb"))
        pickle.dump(self.metadata, self.f, protocol=4)
        return self

    def add(self, rec: dict) -> None:
        record = {"iter": rec["iter"], "histogram": rec["histogram"]}
        for key, cam in (("spad_realsense_data", "colocated"), ("tracking_realsense_data", "tracking")):
            rgb, depth = rec["frames"][cam]
            record[key] = {"aligned_depth_image": depth, "aligned_rgb_image": rgb}
        pickle.dump(record, self.f, protocol=4)

    def finish(self, truth: dict) -> None:
        _write_json(self.truth_tmp, truth)

    def __exit__(self, *exc):
        return self._stack.__exit__(*exc)


def _write_json(path: Path, obj: dict) -> None:
    path.write_text(json.dumps(obj, indent=1, sort_keys=True) + "\n")
