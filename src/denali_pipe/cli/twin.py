"""`denali` verbs of digital twins, the renderers' benchmark and Fig 18 (rules/twin.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis, json_arg, require_keys

log = logging.getLogger("denali")


def cmd_twin(args: argparse.Namespace) -> None:
    from denali_pipe.core.objects import spec_from_dict
    from denali_pipe.twin.render import render_twin

    require_keys(args.config, {"seed", "resolutions", "twin"})
    calibration = Path(args.calibration) if args.calibration else None
    render_twin(spec_from_dict(args.object), args.size, Path(args.scene), args.config, args.time_axis, Path(args.out), calibration)
    log.info("wrote %s", args.out)


def cmd_twin_calibration(args: argparse.Namespace) -> None:
    import time

    from denali_pipe.core.objects import spec_from_dict
    from denali_pipe.report.twin_calibration import plot_calibration
    from denali_pipe.transforms.sim_to_real import read_real, split_pairs
    from denali_pipe.twin.calibrate import Captures, calibrate, write_calibration
    from denali_pipe.twin.layout import load_calibration

    require_keys(args.config, {"seed", "fit", "twin"})
    t0 = time.perf_counter()
    real, keys, crop = read_real([Path(p) for p in args.features])
    split = split_pairs(keys, args.config["seed"], args.config["fit"]["test_fraction"])
    train = Captures(real, keys, crop).subset(split.train)
    specs = {d["name"]: spec_from_dict(d) for d in args.objects}
    settings = args.config["twin"]
    result, problem, held = calibrate(load_calibration(Path(args.scene)), specs, train, settings, args.time_axis, args.config["seed"])
    record = {
        "n_captures": len(problem.y),
        "n_validation": len(held.y),
        "n_test_excluded": int(len(split.test)),
        "crop_start": crop,
        "config": args.config,
        "seconds": time.perf_counter() - t0,
    }
    write_calibration(Path(args.out), result, settings, record)
    if result.at_bound:
        log.warning(
            "twin calibration: %d coordinates at or near the edge of their range (%s): the twin's geometry cannot follow the captures there",
            len(result.at_bound),
            ", ".join(result.at_bound),
        )
    if result.not_identified:
        log.warning(
            "twin calibration: the captures do not identify %d coordinates: %s",
            len(result.not_identified),
            "; ".join(f"{k}: {why}" for k, why in result.not_identified.items()),
        )
    plot_calibration(result, held, Path(args.png))
    log.info("wrote %s and %s (%.1f s): residual before %s, after %s", args.out, args.png, record["seconds"], result.before, result.after)


def cmd_render_benchmark(args: argparse.Namespace) -> None:
    from denali_pipe.core.objects import spec_from_dict
    from denali_pipe.report.render_benchmark import plot_render_benchmark
    from denali_pipe.twin.benchmark import run_benchmark
    from denali_pipe.twin.layout import load_calibration

    require_keys(args.config, {"seed", "sizes", "twin"})
    specs = [spec_from_dict(d) for d in args.objects]
    summary, _ = run_benchmark(load_calibration(Path(args.scene)), specs, args.config["sizes"], args.config["twin"], args.time_axis, args.config["seed"])
    plot_render_benchmark(summary, Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, summary.to_string(index=False))


def cmd_fig18(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.report.fig18 import fig18

    if not len(args.sets) == len(args.backgrounds) == len(args.twins):
        raise ValueError(f"fig18: {len(args.sets)} sets, {len(args.backgrounds)} backgrounds and {len(args.twins)} twins; expected one of each per row")
    captures = [(Path(a), Path(b), Path(c)) for a, b, c in zip(args.sets, args.backgrounds, args.twins)]
    crop = json.loads(Path(args.crop).read_text())["crop_start"]
    fig18(captures, Path(args.scene), Path(args.calibration), crop, args.config, args.time_axis, Path(args.out))
    log.info("wrote %s", args.out)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("twin", help="render one object and size's digital twin at every calibrated location")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--object", type=json_arg, required=True, help="the object's sheet row as JSON")
    s.add_argument("--size", required=True, choices=["4inch", "8inch"], help="object size")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "twin": {...}}')
    s.add_argument("--calibration", help="results/twin_calibration.json: render the calibrated twin (footprints, time offset, lobe)")
    add_time_axis(s)
    s.add_argument("--out", required=True, help="output results/twin/<object>_<size>.zarr")
    s.set_defaults(func=cmd_twin)

    s = sub.add_parser("twin-calibration", help="fit the twin's zone footprints, time offset and lobe to the training captures")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--objects", type=json_arg, required=True, help="JSON list of the objects' sheet rows")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "fit": {"test_fraction": ...}, "twin": {...}}')
    add_time_axis(s)
    s.add_argument("--out", required=True, help="output results/twin_calibration.json")
    s.add_argument("--png", required=True, help="the figure of real against twin per zone, before and after (CSV beside it)")
    s.set_defaults(func=cmd_twin_calibration)
    s = sub.add_parser("render-benchmark", help="twin renderers' time per scene against error to a converged reference")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--objects", type=json_arg, required=True, help="JSON list of the objects' sheet rows to draw scenes from")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "sizes": [...], "twin": {...}}')
    add_time_axis(s)
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_render_benchmark)
    s = sub.add_parser("fig18", help="Fig 18: tracking frames, twin renders and real vs calibrated twin histograms of every zone")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--sets", nargs="+", required=True, help="light-on 3x3 capture-set stores, one per row")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT stores, in the same order")
    s.add_argument("--twins", nargs="+", required=True, help="the matching calibrated twin stores (results/twin_calibrated/<object>_<size>.zarr)")
    s.add_argument("--calibration", required=True, help="results/twin_calibration.json: the zones' gains and the pulse")
    s.add_argument("--crop", required=True, help="results/features/crop_3x3.json: the features' first kept bin")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "variant": ..., "fig18": {...}}')
    add_time_axis(s)
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_fig18)
