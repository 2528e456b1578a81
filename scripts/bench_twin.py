#!/usr/bin/env python
"""Benchmark the digital twin's renderers; prints figures, asserts nothing.

    python scripts/bench_twin.py                          # the demo config's benchmark, nominal scene
    python scripts/bench_twin.py --scene results/calibration/scene.json --n-scenes 8
    python scripts/bench_twin.py --samples 20 40 60 120   # analytic quadrature sweep only

Without --scene the calibrated scene is the rig's design geometry
(`twin.layout.nominal_scene`) at the demo's gantry locations. Prints the
benchmark summary (`twin.benchmark.run_benchmark`, as `denali
render-benchmark` writes it) and the per-scene rows, writes them as CSV with
--out, and reports the peak resident memory of the process. `--samples`
instead compares the analytic renderer at several quadrature densities with
the reference on the same scenes.
"""

from __future__ import annotations

import argparse
import json
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from denali_pipe.core.capture_sets import select_objects
from denali_pipe.core.geometry import TimeAxis, select_locations
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import load_catalogue
from denali_pipe.twin.benchmark import benchmark_scenes, nl2, run_benchmark
from denali_pipe.twin.layout import load_calibration, nominal_scene, twin_scene, zone_footprint

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    cfg = yaml.safe_load((REPO / "config/config.yaml").read_text())
    p = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    p.add_argument("--scene", help="a scene.json (default: the design geometry at the demo's locations)")
    p.add_argument("--n-scenes", type=int, default=cfg["twin"]["benchmark"]["n_scenes"])
    p.add_argument("--paper-spp", type=int, default=cfg["twin"]["benchmark"]["paper_spp"])
    p.add_argument("--reference-spp", type=int, default=cfg["twin"]["benchmark"]["reference_spp"])
    p.add_argument("--footprint-spp", type=int, nargs="+", default=cfg["twin"]["benchmark"]["footprint_spp"])
    p.add_argument("--samples", type=int, nargs="+", help="sweep the analytic renderer's quadrature instead")
    p.add_argument("--out", help="write <out>.csv (summary) and <out>_scenes.csv (per scene)")
    args = p.parse_args()

    scene = Path(args.scene) if args.scene else Path(tempfile.mkdtemp()) / "scene.json"
    if not args.scene:
        scene.write_text(json.dumps(nominal_scene(select_locations(cfg["rig"]["n_locations"]))))
    cal = load_calibration(scene)
    specs = select_objects(load_catalogue(REPO / cfg["objects_sheet"]), cfg["objects"])
    settings = dict(cfg["twin"])
    settings["benchmark"] = {"n_scenes": args.n_scenes, "reference_spp": args.reference_spp, "paper_spp": args.paper_spp, "footprint_spp": args.footprint_spp}
    pd.set_option("display.width", 250)
    if args.samples:
        sweep(cal, specs, cfg, settings, args.samples)
    else:
        t0 = time.perf_counter()
        summary, per_scene = run_benchmark(cal, specs, cfg["sizes"], settings, TimeAxis.from_config(cfg["sensor"]["time_axis"]), cfg["seed"])
        print(summary.to_string(index=False))
        print(per_scene.to_string(index=False))
        print(f"total {time.perf_counter() - t0:.0f} s")
        if args.out:
            summary.to_csv(f"{args.out}.csv", index=False)
            per_scene.to_csv(f"{args.out}_scenes.csv", index=False)
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


def sweep(cal, specs, cfg, settings, samples: list[int]) -> None:
    """Analytic error and time against the footprint reference per quadrature density."""
    from denali_pipe.twin.analytic import AnalyticRenderer
    from denali_pipe.twin.mitransient import MitransientRenderer

    scenes = benchmark_scenes(specs, cfg["sizes"], cal.locations, settings["benchmark"]["n_scenes"], cfg["seed"])
    axis = TimeAxis.from_config(cfg["sensor"]["time_axis"])
    rows = []
    for sc in scenes:
        twin = twin_scene(cal, object_mesh(sc.spec, sc.size), settings, axis, relays=(zone_footprint(cal),))  # the centre zone
        ref = (
            MitransientRenderer(twin, settings["benchmark"]["reference_spp"], settings["mitransient"]["max_depth"], 1).render(sc.location).mean(axis=(0, 1, 2))
        )
        for n in samples:
            r = AnalyticRenderer(twin, n)
            r.render(sc.location)
            t0 = time.perf_counter()
            h = r.render(sc.location).mean(axis=(0, 1, 2))
            rows.append({"samples": n, "scene": sc.label, "points": len(r.points), "ms": 1000 * (time.perf_counter() - t0), "error_nl2": nl2(h, ref)})
    df = pd.DataFrame(rows)
    print(
        df.groupby("samples").agg(points=("points", "mean"), ms=("ms", "median"), error_mean=("error_nl2", "mean"), error_max=("error_nl2", "max")).to_string()
    )
    print(f"max error over scenes: {df.error_nl2.max():.4f}; mean {np.mean(df.error_nl2):.4f}")


if __name__ == "__main__":
    main()
