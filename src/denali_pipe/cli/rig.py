"""`denali` verbs of the synthetic capture rig (rules/rig.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis, json_arg, require_keys

log = logging.getLogger("denali")


def cmd_rig(args: argparse.Namespace) -> None:
    from denali_pipe.core.capture_sets import parse_set_name
    from denali_pipe.core.objects import spec_from_dict
    from denali_pipe.rig.capture import synth_sets

    outs = [Path(p) for p in args.outs]
    sets = [parse_set_name(p.name) for p in outs]
    require_keys(args.config, {"seed", "rig"})
    try:
        spec = None if args.object is None else spec_from_dict(args.object)
    except TypeError as e:
        raise ValueError(f"--object is not an objects-sheet row ({e}): {args.object}") from None
    for cs in sets:
        if (spec is None) != cs.is_background or (spec is not None and spec.name != cs.object):
            raise ValueError(f"capture set {cs.name}: the object record {args.object} does not match the set's object")
    synth_sets(sets, spec, args.config, args.time_axis, outs, args.format)
    log.info("wrote %s", " ".join(args.outs))


def cmd_rig_examples(args: argparse.Namespace) -> None:
    from denali_pipe.rig.examples import rig_examples

    if len(args.sets) != len(args.backgrounds):
        raise ValueError(f"rig-examples: {len(args.sets)} sets but {len(args.backgrounds)} backgrounds")
    rig_examples(list(zip(map(Path, args.sets), map(Path, args.backgrounds))), args.time_axis, Path(args.out))
    log.info("wrote %s", args.out)


def cmd_rig_vs_real(args: argparse.Namespace) -> None:
    from denali_pipe.report.rig_vs_real import rig_vs_real

    if len(args.sets) != len(args.backgrounds):
        raise ValueError(f"rig-vs-real: {len(args.sets)} sets but {len(args.backgrounds)} backgrounds")
    stats = Path(args.feature_stats) if args.feature_stats else None
    scores = Path(args.release_models) if args.release_models else None
    rig_vs_real(list(zip(map(Path, args.sets), map(Path, args.backgrounds))), Path(args.png), Path(args.csv), stats, scores)
    log.info("wrote %s and %s", args.png, args.csv)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("rig", help="synthesise capture sets of one object and size with the embedded capture rig")
    s.add_argument("outs", nargs="+", help="<set>_NLOSdata folders, or <set>_short_NLOSdata.pkl with --format pickle")
    s.add_argument("--object", type=json_arg, default=None, help="the object's sheet row as JSON (omit for backgrounds)")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "rig": {...}}')
    add_time_axis(s)
    s.add_argument("--format", choices=["release", "pickle"], default="release", help="release folders or raw pickle streams")
    s.set_defaults(func=cmd_rig)
    s = sub.add_parser("rig-examples", help="plot example histograms with the three-bounce bump marked")
    s.add_argument("--sets", nargs="+", required=True, help="object capture-set stores (<set>.zarr)")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT set stores, in the same order")
    add_time_axis(s)
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_rig_examples)
    s = sub.add_parser("rig-vs-real", help="measure raw centre-zone histograms against the real captures' figures")
    s.add_argument("--sets", nargs="+", required=True, help="3x3 object capture-set stores (<set>.zarr)")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT set stores, in the same order")
    s.add_argument("--png", required=True, help="the figure")
    s.add_argument("--csv", required=True, help="the measured numbers beside the real figures'")
    s.add_argument(
        "--feature-stats", default=None, help="folder of the release's 1D CNN backbones and BN statistics (REFERENCE Part 7); omit for no feature-moment panels"
    )
    s.add_argument("--release-models", default=None, help="results/release_models.csv: the release's networks on these captures; omit for no such panel")
    s.set_defaults(func=cmd_rig_vs_real)
