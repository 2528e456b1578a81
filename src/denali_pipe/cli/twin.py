"""`denali` verbs of digital twins, the renderers' benchmark and Fig 18 (rules/twin.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import json_arg, require_keys

log = logging.getLogger("denali")


def cmd_twin(args: argparse.Namespace) -> None:
    from denali_pipe.objects import spec_from_dict
    from denali_pipe.twin.render import render_twin

    require_keys(args.config, {"seed", "twin"})
    render_twin(spec_from_dict(args.object), args.size, Path(args.scene), args.config, Path(args.out))
    log.info("wrote %s", args.out)


def cmd_render_benchmark(args: argparse.Namespace) -> None:
    from denali_pipe.objects import spec_from_dict
    from denali_pipe.report.render_benchmark import plot_render_benchmark
    from denali_pipe.twin.benchmark import run_benchmark
    from denali_pipe.twin.layout import load_calibration

    require_keys(args.config, {"seed", "sizes", "twin"})
    specs = [spec_from_dict(d) for d in args.objects]
    summary, _ = run_benchmark(load_calibration(Path(args.scene)), specs, args.config["sizes"], args.config["twin"], args.config["seed"])
    plot_render_benchmark(summary, Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, summary.to_string(index=False))


def cmd_fig18(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.report.fig18 import fig18

    if not len(args.sets) == len(args.backgrounds) == len(args.twins):
        raise ValueError(f"fig18: {len(args.sets)} sets, {len(args.backgrounds)} backgrounds and {len(args.twins)} twins; expected one of each per row")
    captures = [(Path(a), Path(b), Path(c)) for a, b, c in zip(args.sets, args.backgrounds, args.twins)]
    crop = json.loads(Path(args.crop).read_text())["crop_start"]
    fig18(captures, Path(args.scene), crop, args.config, Path(args.out))
    log.info("wrote %s", args.out)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("twin", help="render one object and size's digital twin at every calibrated location")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--object", type=json_arg, required=True, help="the object's sheet row as JSON")
    s.add_argument("--size", required=True, choices=["4inch", "8inch"], help="object size")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "twin": {...}}')
    s.add_argument("--out", required=True, help="output results/twin/<object>_<size>.zarr")
    s.set_defaults(func=cmd_twin)
    s = sub.add_parser("render-benchmark", help="twin renderers' time per scene against error to a converged reference")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--objects", type=json_arg, required=True, help="JSON list of the objects' sheet rows to draw scenes from")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "sizes": [...], "twin": {...}}')
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_render_benchmark)
    s = sub.add_parser("fig18", help="Fig 18: tracking frames, twin renders and real vs simulated centre-pixel histograms")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--sets", nargs="+", required=True, help="light-on 3x3 capture-set stores, one per row")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT stores, in the same order")
    s.add_argument("--twins", nargs="+", required=True, help="the matching twin stores (results/twin/<object>_<size>.zarr)")
    s.add_argument("--crop", required=True, help="results/features/crop_3x3.json: the features' first kept bin")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "variant": ..., "fig18": {...}}')
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_fig18)
