#!/usr/bin/env python
"""Benchmark the tracking-pose stage; prints figures, asserts nothing.

    python scripts/bench_poses.py                       # 20 locations, scales 1.0 0.5 0.35
    python scripts/bench_poses.py --locations 50 --scales 0.5

The rig renders tracking frames (lights on, plus a few lights off) at each
frame scale (1.0 = 1280x720); then:
- detector comparison: pyapriltags against cv2.aruco (DICT_APRILTAG_36h11,
  sub-pixel corners), each with and without the border-band corner
  refinement: detection rate over the tags the frame shows (whole black
  square inside the image, not covered by a nearer tag), centre error
  against the projected truth, radial corner bias (negative: square too
  small), false positives, time per frame on one thread;
- throughput: frames per second of detection + refinement + every PnP
  (`estimate.observe_frame`), pinned to one core and to two
  (os.sched_setaffinity + cv2.setNumThreads + the AprilTag threads);
- accuracy of the whole per-set estimate (`estimate_frames`, the frames as
  one set) against the rig's truth: per static tag the filtered mean's error,
  per location the object tag's error, in mm; for the default pipeline, for
  it without corner refinement and with the ArUco detector.
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

from denali_pipe import geometry as geo
from denali_pipe.poses.detect import TagDetector, quad_centre
from denali_pipe.poses.estimate import EXPECTED_TAG_IDS, estimate_frames, observe_frame
from denali_pipe.poses.filtering import filter_estimates, summarise
from denali_pipe.poses.pnp import Intrinsics
from denali_pipe.rig.frames import frame_tags, render_frame

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


def _worker_init(cpus_queue, scale: float) -> None:
    _pin([cpus_queue.get()])
    cv2.setNumThreads(1)
    cam = geo.TRACKING_CAMERA.scaled(scale)
    _WORKER.update(det=TagDetector("apriltag", nthreads=1), intr=intrinsics(cam))


def _worker_frame(item) -> int:
    k, bgr = item
    observe_frame(k, bgr, _WORKER["det"], _WORKER["intr"])
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
    with ctx.Pool(2, initializer=_worker_init, initargs=(q, scale)) as pool:
        pool.map(_worker_frame, items[:2], chunksize=1)  # warm up
        t0 = time.perf_counter()
        pool.map(_worker_frame, items, chunksize=1)
        return len(items) / (time.perf_counter() - t0)


def throughput(scale: float, lit: list, cpus: list[int]) -> None:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    intr = intrinsics(cam)
    line = []
    for n in ([1, 2] if len(cpus) >= 2 else [1]):
        _pin(cpus[:n])
        cv2.setNumThreads(n)
        det = TagDetector("apriltag", nthreads=n)
        observe_frame(lit[0][0], lit[0][1], det, intr)  # warm up
        t0 = time.perf_counter()
        for k, bgr, _ in lit:
            observe_frame(k, bgr, det, intr)
        dt = time.perf_counter() - t0
        t0 = time.perf_counter()
        for _, bgr, _ in lit:
            det.detect(bgr)
        dd = time.perf_counter() - t0
        line.append(f"{n} core{'s' if n > 1 else ''}, {n} thread{'s' if n > 1 else ''}: {len(lit) / dt:5.1f} fps ({1e3 * dt / len(lit):5.1f} ms/frame; detection+refinement {1e3 * dd / len(lit):5.1f})")
    _pin(cpus)
    if len(cpus) >= 2:
        line.append(f"2 cores, 2 single-thread processes: {two_processes(scale, lit, cpus):5.1f} fps")
    print(f"  scale {scale} ({cam.width}x{cam.height}):\n    " + "\n    ".join(line))


def accuracy(scale: float, lit: list) -> None:
    cam = geo.TRACKING_CAMERA.scaled(scale)
    intr = intrinsics(cam)
    frames = [(k, bgr) for k, bgr, _ in lit]
    print(f"\n  accuracy at scale {scale}, {len(frames)} frames as one set (errors in mm)")
    for name, v in (("apriltag+refine (default)", VARIANTS["apriltag+refine"]), ("apriltag, no refinement", VARIANTS["apriltag"]), ("aruco+refine", VARIANTS["aruco+refine"])):
        det = TagDetector(v["kind"], refine=v["refine"])
        t0 = time.perf_counter()
        df = estimate_frames(frames, intr, set_name="bench", light="lighton", detector=det)
        dt = time.perf_counter() - t0
        filt = filter_estimates(df)
        s = summarise(filt[filt["tag_id"] != geo.OBJECT_TAG_ID], "tag_id", expected=sorted(geo.STATIC_TAGS)).set_index("tag_id")
        errs = {}
        for tid, p in geo.STATIC_TAGS.items():
            m = s.loc[tid, ["x_mean", "y_mean", "z_mean"]].to_numpy(float)
            errs[tid] = np.linalg.norm(m - p.t) * 1e3 if np.all(np.isfinite(m)) else np.nan
        obj = df[(df["tag_id"] == geo.OBJECT_TAG_ID) & (df["status"] == "ok")]
        oerr = np.linalg.norm(obj[["x", "y", "z"]].to_numpy() - geo.tag1_position(obj["location"].to_numpy()), axis=1) * 1e3
        single = np.linalg.norm(obj[["single_x", "single_y", "single_z"]].to_numpy() - geo.tag1_position(obj["location"].to_numpy()), axis=1) * 1e3
        cam_err = np.linalg.norm(df.drop_duplicates("location")[["cam_x", "cam_y", "cam_z"]].to_numpy() - cam.position, axis=1) * 1e3
        flips = int((df["ippe_solution"] == 1).sum())
        print(f"  {name:26s} static tags: max {np.nanmax(list(errs.values())):5.2f}  " + " ".join(f"{t}:{e:.2f}" for t, e in errs.items()))
        print(
            f"  {'':26s} object tag: mean {oerr.mean():5.2f} max {oerr.max():5.2f} (n={len(oerr)}/{len(frames)}); "
            f"its single-tag PnP: mean {single.mean():5.1f} max {single.max():5.1f}; camera: mean {np.nanmean(cam_err):4.2f} max {np.nanmax(cam_err):4.2f}; "
            f"IPPE flips {flips}; gantry plane z err {1e3 * (df.attrs['planes']['1']['point'][2] - geo.GANTRY_ORIGIN[2]):+.2f}; {1e3 * dt / len(frames):.0f} ms/frame"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--locations", type=int, default=20, help="gantry locations (frames) per scale")
    ap.add_argument("--dark", type=int, default=5, help="lights-off frames per scale")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 0.5, 0.35])
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
    print("\n== throughput: detection + refinement + board/wall/single-tag PnP per frame ==")
    for s in args.scales:
        throughput(s, data[s][0], cpus)
    cv2.setNumThreads(len(cpus))
    print("\n== accuracy against the rig's truth ==")
    for s in args.scales:
        accuracy(s, data[s][0])
    print(f"\n(expected tags per frame: {list(EXPECTED_TAG_IDS)})")


if __name__ == "__main__":
    main()
