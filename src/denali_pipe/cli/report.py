"""`denali` verbs of training tables and figures from the cells (rules/report.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import json_arg

log = logging.getLogger("denali")
# The aggregates over every registered model, which name the ones a preset leaves out.
LEFT_OUT_KINDS = ("table2", "table10", "speed-vs-accuracy")


def cmd_training_report(args: argparse.Namespace) -> None:
    from denali_pipe.report.condition_table import write_condition_table
    from denali_pipe.report.speed_vs_accuracy import write_speed_vs_accuracy
    from denali_pipe.report.table2 import write_table2
    from denali_pipe.report.table5 import write_table5
    from denali_pipe.report.table10 import write_table10
    from denali_pipe.report.training_curves import write_training_curves
    from denali_pipe.train.conditions import TABLES

    paths, out = [Path(p) for p in args.runs], Path(args.out)
    if args.left_out and args.kind not in LEFT_OUT_KINDS:
        raise ValueError(f"report {args.kind}: --left-out is for {', '.join(LEFT_OUT_KINDS)} only")
    if args.kind == "table5":
        write_table5(paths, out)
    elif args.kind == "table2":
        write_table2(paths, out, args.left_out)
    elif args.kind == "table10":
        write_table10(paths, out, args.left_out)
    elif args.kind == "speed-vs-accuracy":
        write_speed_vs_accuracy(paths, out, args.left_out)
    elif args.kind in TABLES:
        write_condition_table(paths, args.kind, args.groups, out)
    else:
        task = {"fig16": "location", "fig17": "shape"}[args.kind]
        write_training_curves(paths, task, args.title, out)
    log.info("wrote %s from %d cells", out, len(paths))


def register(sub: argparse._SubParsersAction) -> None:
    from denali_pipe.train.conditions import CONDITION_GROUPS
    from denali_pipe.train.conditions import TABLES as CONDITION_TABLES

    s = sub.add_parser("report", help="a training table or figure from cells' metrics.json / curves.csv")
    s.add_argument("kind", choices=["table2", "table5", *CONDITION_TABLES, "table10", "fig16", "fig17", "speed-vs-accuracy"])
    s.add_argument("runs", nargs="+", help="metrics.json files (curves.csv for fig16/fig17)")
    s.add_argument("--title", default="", help="figure title (fig16/fig17)")
    s.add_argument("--groups", nargs="+", choices=CONDITION_GROUPS, default=list(CONDITION_GROUPS), help="condition groups trained (tables 7-9; default: all)")
    s.add_argument(
        "--left-out",
        type=json_arg,
        default={},
        help="JSON {model: reason} of the registered models not trained (config train.left_out; table2, table10, speed-vs-accuracy)",
    )
    s.add_argument("--out", required=True, help="output CSV or PNG (a PNG gets its data beside it as CSV)")
    s.set_defaults(func=cmd_training_report)
