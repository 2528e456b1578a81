#!/usr/bin/env python
"""Benchmark the tracking-pose stage; prints figures, asserts nothing.

    python scripts/bench_poses.py                       # 20 locations, scales 1.0 0.5 0.35
    python scripts/bench_poses.py --locations 25 --sets 4 --scales 0.5   # the demo's calibration
    python scripts/bench_poses.py --poses-json PATH     # the release scene from another poses.json

The rig renders tracking frames (lights on, plus a few lights off) at each
frame scale (1.0 = 1280x720); then:
- detector comparison: pyapriltags against cv2.aruco (DICT_APRILTAG_36h11,
  sub-pixel corners), each with and without the border-band corner
  refinement: detection rate over the tags the frame shows (whole black
  square inside the image, not covered by a nearer tag), centre error
  against the projected truth, radial corner bias (negative: square too
  small), false positives, time per frame on one thread;
- throughput: frames per second of detection + refinement
  (`estimate.observe_frame`), pinned to one core and to two
  (os.sched_setaffinity + cv2.setNumThreads + the AprilTag threads), and of
  the whole per-set estimate (`estimate_frames`: layout, template fits, PnP);
- accuracy against the rig's truth on both scenes, our design drawing and a
  release's poses.json (`rig.scene_poses`; skipped when the file is absent):
  `--sets` capture sets of `--locations` frames each (own gantry offsets and
  noise), each estimated on its own (`estimate_frames`) and pooled by
  `calibrate`, as the workflow calibrates from the background sets; per
  static tag Table 6's mean against the truth, per gantry location the
  calibrated object-tag position against the true one (mean over the sets),
  in mm.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import cv2
import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.poses.calibrate import calibrate
from denali_pipe.poses.detect import TagDetector, quad_centre
from denali_pipe.poses.estimate import EXPECTED_TAG_IDS, estimate_frames, observe_frame
from denali_pipe.poses.pnp import Intrinsics
from denali_pipe.report.table6 import table6
from denali_pipe.rig.frames import frame_tags, render_frame
from denali_pipe.rig.nuisances import gantry_offset
from denali_pipe.rig.tracked_scene import TrackedScene, tracked_scene

RELEASE_POSES = Path(__file__).resolve().parents[2] / "shared" / "denali-assets" / "poses.json"
GANTRY = {"gantry_repeatability_m": 0.001}  # rig.nuisances' default

VARIANTS = {
    "apriltag": dict(kind="apriltag", refine=False),
    "apriltag+refine": dict(kind="apriltag", refine=True),
    "aruco": dict(kind="aruco", refine=False),
    "aruco+refine": dict(kind="aruco", refine=True),
}


def intrinsics(cam: geo.Camera) -> Intrinsics:
    return cam.intrinsics


def visible(cam: geo.Camera, tags: dict[int, geo.Pose], margin: float = 3.0) -> set[int]:
    """Tags whose black square lies inside the image (with `margin` px), facing
    the camera and not overlapped by a nearer tag's printed square."""
    out = set()
    for tid, p in tags.items():
        uv, z = cam.project(p.apply(geo.tag_corners_local()))
        facing = (cam.position - p.t) @ (-p.R[:, 2]) > 0
        inside = (uv >= margin).all() and (uv[:, 0] <= cam.width - 1 - margin).all() and (uv[:, 1] <= cam.height - 1 - margin).all()
        if not (facing and (z > 0).all() and inside):
            continue
        hidden = False
        for other, q in tags.items():
            if other == tid:
                continue
            uq, zq = cam.project(q.apply(geo.tag_corners_local(0.08)))
            if (zq > 0).all() and zq.mean() < z.mean():
                area, _ = cv2.intersectConvexConvex(uv.astype(np.float32), uq.astype(np.float32))
                hidden |= area > 0
        if not hidden:
            out.add(tid)
    return out


def render(scale: float, locations: list[int], light: bool) -> list[tuple[int, np.ndarray, dict]]:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    out = []
    for k in locations:
        tags = frame_tags(k, "tracking")
        bgr, _ = render_frame(cam, tags, light, np.random.default_rng(1000 + k))
        out.append((k, bgr, tags))
    return out


def radial_bias(c: np.ndarray, t: np.ndarray) -> float:
    m = t.mean(axis=0)
    o = (t - m) / np.linalg.norm(t - m, axis=1, keepdims=True)
    return float(np.mean(np.sum((c - t) * o, axis=1)))


def compare_detectors(scale: float, lit: list, dark: list) -> None:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    print(f"\n  detectors at scale {scale} ({cam.width}x{cam.height}), {len(lit)} lit + {len(dark)} dark frames, 1 thread")
    print(f"  {'detector':16s} {'rate':>6s} {'dark':>6s} {'centre px med/p95':>18s} {'radial px':>10s} {'false+':>6s} {'ms/frame':>9s}")
    for name, v in VARIANTS.items():
        det = TagDetector(v["kind"], refine=v["refine"], nthreads=1)
        shown = found = fp = 0
        cerr, rad, times = [], [], []
        for _, bgr, tags in lit:
            vis = visible(cam, tags)
            t0 = time.perf_counter()
            dets = det.detect(bgr)
            times.append(time.perf_counter() - t0)
            ids = {d.tag_id for d in dets}
            shown += len(vis)
            found += len(vis & ids)
            fp += len(ids - set(tags))
            for d in dets:
                if d.tag_id in tags:
                    truth = cam.project(tags[d.tag_id].apply(geo.tag_corners_local()))[0]
                    cerr.append(np.linalg.norm(d.centre - quad_centre(truth)))
                    rad.append(radial_bias(d.corners, truth))
        dshown = dfound = 0
        for _, bgr, tags in dark:
            vis = visible(cam, tags)
            ids = {d.tag_id for d in det.detect(bgr)}
            dshown += len(vis)
            dfound += len(vis & ids)
            fp += len(ids - set(tags))
        print(
            f"  {name:16s} {found / max(shown, 1):6.1%} {dfound / max(dshown, 1):6.1%} "
            f"{np.median(cerr):8.3f} / {np.percentile(cerr, 95):6.3f} {np.mean(rad):+10.3f} {fp:6d} {1e3 * np.median(times):9.1f}"
        )


def _pin(cpus: list[int]) -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, set(cpus))


_WORKER: dict = {}


def _worker_init(cpus_queue) -> None:
    _pin([cpus_queue.get()])
    cv2.setNumThreads(1)
    _WORKER.update(det=TagDetector("apriltag", nthreads=1))


def _worker_frame(item) -> int:
    k, bgr = item
    observe_frame(k, bgr, _WORKER["det"])
    return k


def two_processes(scale: float, lit: list, cpus: list[int]) -> float:
    """Frames per second of two single-threaded worker processes, one per core
    (how Snakemake runs two per-set jobs side by side)."""
    import multiprocessing as mp

    ctx = mp.get_context("spawn")  # fork after OpenCV threads ran can deadlock
    q = ctx.Queue()
    for c in cpus[:2]:
        q.put(c)
    items = [(k, bgr) for k, bgr, _ in lit] * 2
    with ctx.Pool(2, initializer=_worker_init, initargs=(q,)) as pool:
        pool.map(_worker_frame, items[:2], chunksize=1)  # warm up
        t0 = time.perf_counter()
        pool.map(_worker_frame, items, chunksize=1)
        return len(items) / (time.perf_counter() - t0)


def throughput(scale: float, lit: list, cpus: list[int]) -> None:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    intr = intrinsics(cam)
    line = []
    for n in [1, 2] if len(cpus) >= 2 else [1]:
        _pin(cpus[:n])
        cv2.setNumThreads(n)
        det = TagDetector("apriltag", nthreads=n)
        observe_frame(lit[0][0], lit[0][1], det)  # warm up
        t0 = time.perf_counter()
        for k, bgr, _ in lit:
            observe_frame(k, bgr, det)
        dd = time.perf_counter() - t0
        t0 = time.perf_counter()
        estimate_frames([(k, bgr) for k, bgr, _ in lit], intr, detector=det)
        dt = time.perf_counter() - t0
        line.append(
            f"{n} core{'s' if n > 1 else ''}, {n} thread{'s' if n > 1 else ''}: {len(lit) / dt:5.1f} fps ({1e3 * dt / len(lit):5.1f} ms/frame; detection+refinement {1e3 * dd / len(lit):5.1f})"
        )
    _pin(cpus)
    if len(cpus) >= 2:
        line.append(f"2 cores, 2 single-thread processes: {two_processes(scale, lit, cpus):5.1f} fps")
    print(f"  scale {scale} ({cam.width}x{cam.height}):\n    " + "\n    ".join(line))


def capture_sets(scene: TrackedScene, scale: float, locations: list[int], n_sets: int) -> tuple[list, dict[int, np.ndarray]]:
    """`n_sets` sets of lit frames of `scene`, each with its own gantry offsets
    and noise: ([(set name, [(location, frame)])], true tag-1 centre per
    location averaged over the sets)."""
    cam = geo.TRACKING_CAMERA.scaled(scale)
    sets, tag1 = [], {k: [] for k in locations}
    for s in range(n_sets):
        name = f"NOOBJECT_8inch_S{s}_lighton"
        frames = []
        for k in locations:
            tags = frame_tags(k, "tracking", tuple(gantry_offset(GANTRY, 0, name, k)), scene)
            tag1[k].append(tags[geo.OBJECT_TAG_ID].t)
            frames.append((k, render_frame(cam, tags, True, np.random.default_rng([s, k]), scene=scene)[0]))
        sets.append((name, frames))
    return sets, {k: np.mean(v, axis=0) for k, v in tag1.items()}


def accuracy(scene: TrackedScene, scale: float, locations: list[int], n_sets: int) -> None:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    sets, tag1 = capture_sets(scene, scale, locations, n_sets)
    t0 = time.process_time()  # CPU time: the machine may be shared
    tables = [estimate_frames(frames, cam.intrinsics, set_name=name, light="lighton") for name, frames in sets]
    dt = time.process_time() - t0
    cal = calibrate(tables)
    t6 = table6(cal.filtered).set_index("tag_id")
    static = {t: 1e3 * np.linalg.norm(t6.loc[t, ["x_mean_cm", "y_mean_cm", "z_mean_cm"]].to_numpy(float) / 100 - p.t) for t, p in scene.static_tags.items()}
    objs = cal.object_positions.set_index("location")
    err = 1e3 * np.array([objs.loc[k, ["x", "y", "z"]].to_numpy(float) - tag1[k] for k in locations])
    norm = np.linalg.norm(err, axis=1)
    worst = max(static, key=static.get)
    print(f"  scale {scale} ({cam.width}x{cam.height}), {n_sets} sets x {len(locations)} locations, {1e3 * dt / (n_sets * len(locations)):.0f} CPU ms/frame")
    print(
        f"    static tags (Table 6 mean): mean {np.mean(list(static.values())):.2f} max {static[worst]:.2f} (tag {worst}); "
        + " ".join(f"{t}:{e:.2f}" for t, e in sorted(static.items()))
    )
    ax = np.abs(err).mean(axis=0)
    print(
        f"    object tag per location: mean |error| x/y/z {ax[0]:.2f}/{ax[1]:.2f}/{ax[2]:.2f}, |error| mean {norm.mean():.2f} max {norm.max():.2f} (location {locations[int(np.argmax(norm))]})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--locations", type=int, default=20, help="gantry locations (frames) per scale and set")
    ap.add_argument("--dark", type=int, default=5, help="lights-off frames per scale")
    ap.add_argument("--sets", type=int, default=4, help="capture sets pooled for the accuracy (the demo calibrates from 4)")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 0.5, 0.35])
    ap.add_argument("--poses-json", type=Path, default=RELEASE_POSES, help="the release scene's poses.json")
    args = ap.parse_args()
    cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    print(f"bench_poses: {args.locations} locations per scale, {len(cpus)} CPUs available, OpenCV {cv2.__version__}")
    locs = [int(k) for k in geo.select_locations(args.locations)]
    data = {}
    for s in args.scales:
        t0 = time.perf_counter()
        data[s] = (render(s, locs, True), render(s, locs[: args.dark], False))
        print(f"  rendered scale {s}: {time.perf_counter() - t0:.1f} s")
    print("\n== detector comparison (rate: of the tags each frame shows; dark: lights-off frames) ==")
    for s in args.scales:
        compare_detectors(s, *data[s])
    print("\n== throughput: the whole per-set estimate (layout, template fits, PnP) and its detection + refinement, per frame ==")
    for s in args.scales:
        throughput(s, data[s][0], cpus)
    cv2.setNumThreads(len(cpus))
    scenes = [("design drawing", tracked_scene(None))]
    if args.poses_json.exists():
        scenes.append((f"release poses ({args.poses_json})", tracked_scene(args.poses_json)))
    else:
        print(f"\n(no {args.poses_json}: the release scene is skipped)")
    for label, scene in scenes:
        print(f"\n== accuracy against the rig's truth: {label} (errors in mm) ==")
        for s in args.scales:
            accuracy(scene, s, locs, args.sets)
    print(f"\n(expected tags per frame: {list(EXPECTED_TAG_IDS)})")


if __name__ == "__main__":
    main()
