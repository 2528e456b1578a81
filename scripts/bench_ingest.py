#!/usr/bin/env python
"""Benchmark raw-capture ingestion into Zarr; prints figures, asserts nothing.

    python scripts/bench_ingest.py                 # 100 locations, frames at 0.5 scale
    python scripts/bench_ingest.py --locations 25 --scale 0.35

The synthetic rig writes one capture set (A_8inch_3x3_lighton) in the release
layout and as a pickle stream into a temporary folder; then:
- throughput (MB/s of raw input read) of the histograms alone (the store
  writer fed by the same per-file reads and checks as `ingest_release`, no
  frames), of the full release ingest and of the pickle ingest;
- histogram ingest time against a bare `np.load` of the same files;
- compression per modality: raw bytes (npy/PNG) and uncompressed array
  bytes against the bytes stored;
- peak memory (max RSS) of a child process ingesting one set, for all
  locations and for a quarter of them (streaming: it should not grow), next to
  a child that only imports the modules;
- for reference, other Blosc settings on the same frames.
Raw files are in the page cache (just written), so these are CPU-bound figures.
"""

from __future__ import annotations

import argparse
import copy
import io
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
SET = "A_8inch_3x3_lighton"

CHILD = """
import resource, sys
from pathlib import Path
from denali_pipe.ingest.capture_set import ingest_set
from denali_pipe.core.objects import load_catalogue
spec = load_catalogue(Path(sys.argv[1]))["A"]
if sys.argv[2] != "-":
    ingest_set(Path(sys.argv[2]), Path(sys.argv[3]), spec)
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")]
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, hwm[0].split()[1] if hwm else -1)
"""


def tree_bytes(path: Path) -> int:
    return path.stat().st_size if path.is_file() else sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def timed(fn, repeat: int = 3) -> float:
    """Best wall time of `repeat` runs, s."""
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def synth(tmp: Path, n_locations: int, scale: float):
    from denali_pipe.core.capture_sets import FOLDER_SUFFIX, PICKLE_SUFFIX, parse_set_name
    from denali_pipe.core.geometry import TimeAxis
    from denali_pipe.core.objects import load_catalogue
    from denali_pipe.rig.capture import synth_sets

    with open(REPO / "config" / "config.yaml") as f:
        cfg = yaml.safe_load(f)
    cfg = copy.deepcopy(cfg)
    cfg["rig"].update(n_locations=n_locations, repeats=3, frames={"tracking_scale": scale, "colocated_scale": scale})
    spec = load_catalogue(REPO / "config" / "objects.tsv")["A"]
    cs = parse_set_name(SET)
    rel, pkl = tmp / "raw" / f"{SET}{FOLDER_SUFFIX}", tmp / "raw" / f"{SET}{PICKLE_SUFFIX}"
    t = time.perf_counter()
    axis = TimeAxis.from_config(cfg["sensor"]["time_axis"])
    synth_sets([cs], spec, cfg, axis, [rel], "release")
    synth_sets([cs], spec, cfg, axis, [pkl], "pickle")
    print(f"rig: {n_locations} locations, frames at {scale} scale, release + pickle written in {time.perf_counter() - t:.1f} s")
    return spec, cs, rel, pkl


def subset(rel: Path, dst: Path, n: int) -> Path:
    """A copy (hard links) of a release set keeping its first n locations."""
    from denali_pipe.io.release import METADATA_FILE

    shutil.copytree(rel, dst, copy_function=os.link)
    md = json.loads((rel / METADATA_FILE).read_text())
    keep, drop = md["locations"][:n], md["locations"][n:]
    for k in drop:
        for p in dst.glob(f"*/{k:03d}.*"):
            p.unlink()
    (dst / METADATA_FILE).unlink()
    (dst / METADATA_FILE).write_text(json.dumps({**md, "locations": keep}))
    return dst


def child_rss_mb(*args: str) -> tuple[float, float]:
    """(ru_maxrss, VmHWM) of a child process, MB. Through `sh -c`, so that the
    child's ru_maxrss does not inherit this (large) process's high-water mark
    at exec; VmHWM is the peak of the child's own address space."""
    cmd = " ".join(map(shlex.quote, [sys.executable, "-c", CHILD, str(REPO / "config" / "objects.tsv"), *args]))
    out = subprocess.run(["/bin/sh", "-c", f"{cmd}; true"], capture_output=True, text=True, check=True)
    maxrss, hwm = out.stdout.split()[-2:]
    return int(maxrss) / 1024, int(hwm) / 1024  # both KiB on Linux


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--locations", type=int, default=100)
    ap.add_argument("--scale", type=float, default=0.5)
    args = ap.parse_args()

    from denali_pipe.ingest.capture_set import check_histogram, ingest_pickle, ingest_release
    from denali_pipe.io.release import FRAME_DIRS, HISTOGRAM_DIR
    from denali_pipe.io.store import StoreWriter, open_set

    tmp = Path(tempfile.mkdtemp(prefix="denali-bench-ingest-"))
    try:
        spec, cs, rel, pkl = synth(tmp, args.locations, args.scale)
        npys = sorted((rel / HISTOGRAM_DIR).glob("*.npy"))
        hist_raw = sum(p.stat().st_size for p in npys)
        all_raw = sum(tree_bytes(rel / d) for d in (HISTOGRAM_DIR, *FRAME_DIRS)) + tree_bytes(rel / "metadata.json")
        out = tmp / "store"

        # --- throughput -------------------------------------------------------------------
        def bare_load():
            for p in npys:
                np.load(p)

        runs = iter(range(1000))  # a fresh store per timed run: no replacement cost in the timings

        def hist_only():
            dst = out / f"hist{next(runs)}.zarr"
            with StoreWriter(dst, cs, repeats=3, metadata={}, source_format="release") as w:
                for p in npys:
                    data = p.read_bytes()
                    h = check_histogram(np.load(io.BytesIO(data)), str(p), cs, 3)
                    w.write_location(int(p.stem), h)

        t_load, t_hist = timed(bare_load), timed(hist_only)
        t_full = timed(lambda: ingest_release(rel, out / f"full{next(runs)}.zarr", spec))
        t_pkl = timed(lambda: ingest_pickle(pkl, out / f"pkl{next(runs)}.zarr", spec))
        mb = 1e6
        print(f"\nthroughput ({args.locations} locations; best of 3; raw input read per second):")
        print(
            f"  histograms only : {hist_raw / mb:7.2f} MB in {t_hist:6.3f} s = {hist_raw / mb / t_hist:7.1f} MB/s  ({args.locations / t_hist:.0f} locations/s)"
        )
        print(
            f"  bare np.load    : {hist_raw / mb:7.2f} MB in {t_load:6.3f} s = {hist_raw / mb / t_load:7.1f} MB/s"
            f"  -> histogram ingest / np.load = {t_hist / t_load:.1f}x"
        )
        print(f"  release + frames: {all_raw / mb:7.2f} MB in {t_full:6.3f} s = {all_raw / mb / t_full:7.1f} MB/s  ({args.locations / t_full:.0f} locations/s)")
        print(f"  pickle stream   : {tree_bytes(pkl) / mb:7.2f} MB in {t_pkl:6.3f} s = {tree_bytes(pkl) / mb / t_pkl:7.1f} MB/s")

        # --- compression ------------------------------------------------------------------
        s = open_set(next(out.glob("full*.zarr")))
        print("\ncompression (raw = npy/PNG files; array = uncompressed bytes; stored = chunks + metadata on disk):")
        print(f"  {'modality':16s} {'raw MB':>8s} {'array MB':>9s} {'stored MB':>10s} {'raw/stored':>11s} {'array/stored':>13s}")
        for name, folder in [("histogram", HISTOGRAM_DIR), *[(m, m) for m in FRAME_DIRS]]:
            arr = s.histograms if name == "histogram" else s.frames(name)
            raw_b, arr_b, st_b = tree_bytes(rel / folder), arr.nbytes, s.stored_bytes(name)
            print(f"  {name:16s} {raw_b / mb:8.2f} {arr_b / mb:9.2f} {st_b / mb:10.2f} {raw_b / st_b:10.2f}x {arr_b / st_b:12.2f}x")
        print(f"  {'whole set':16s} {all_raw / mb:8.2f} {'':9s} {s.stored_bytes() / mb:10.2f} {all_raw / s.stored_bytes():10.2f}x")
        t_read = timed(lambda: [f for m in FRAME_DIRS for _, f in s.iter_frames(m)], repeat=2)
        frame_bytes = sum(s.frames(m).nbytes for m in FRAME_DIRS)
        t_hread = timed(lambda: s.histograms[:])
        print(
            f"  reading back: all frames (iter_frames) {frame_bytes / mb / t_read:.0f} MB/s of decoded arrays; "
            f"all histograms (histograms[:]) {t_hread * 1e3:.0f} ms per set"
        )

        # --- peak memory ------------------------------------------------------------------
        quarter = subset(rel, tmp / "quarter" / rel.name, max(1, args.locations // 4))
        base = child_rss_mb("-")
        full = child_rss_mb(str(rel), str(out / "child.zarr"))
        part = child_rss_mb(str(quarter), str(out / "child_q.zarr"))
        pk = child_rss_mb(str(pkl), str(out / "child_p.zarr"))
        loc_mb = (all_raw / args.locations) / mb
        print(f"\npeak memory of a child process (getrusage ru_maxrss / VmHWM, MB; one location's raw files are {loc_mb:.2f} MB):")
        for label, (rss, hwm) in [("imports only", base), (f"release ingest, {args.locations} locations", full),
                                  (f"release ingest, {max(1, args.locations // 4)} locations", part),
                                  (f"pickle ingest, {args.locations} locations", pk)]:  # fmt: skip
            print(f"  {label:32s}: {rss:6.0f} / {hwm:6.0f}")

        # --- other codec settings, for reference ------------------------------------------
        from numcodecs import Blosc

        print("\nother Blosc settings on this set's frames (zstd; ratio = array bytes / compressed, encode MB/s):")
        for m in FRAME_DIRS:
            frames = [f for _, f in s.iter_frames(m)]
            nbytes = sum(f.nbytes for f in frames)
            cells = []
            for label, shuffle, level in [("noshuffle", Blosc.NOSHUFFLE, 1), ("shuffle", Blosc.SHUFFLE, 1),
                                          ("bitshuffle", Blosc.BITSHUFFLE, 1), ("shuffle L3", Blosc.SHUFFLE, 3)]:  # fmt: skip
                codec = Blosc(cname="zstd", clevel=level, shuffle=shuffle)
                t = time.perf_counter()
                size = sum(len(codec.encode(f)) for f in frames)
                cells.append(f"{label} {nbytes / size:4.2f}x {nbytes / mb / (time.perf_counter() - t):5.0f}")
            print(f"  {m:16s} " + " | ".join(cells))
        print(f"\n(cores: {os.cpu_count()})")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
