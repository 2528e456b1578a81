"""`denali` verbs of the timing-jitter sweep (rules/jitter.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis

log = logging.getLogger("denali")


def cmd_jitter(args: argparse.Namespace) -> None:
    from denali_pipe.experiments.jitter import jitter_curve
    from denali_pipe.report.jitter import plot_jitter
    from denali_pipe.train.runs import load_runs, protocol_of

    runs = load_runs([Path(p) for p in args.runs])
    curve = jitter_curve(runs, args.time_axis)
    models = ", ".join(sorted(set(runs["model"])))
    title = f"{models} on the 3x3 centre zone, lights on, against timing jitter (random split, {protocol_of(runs)} protocol)"
    plot_jitter(curve, title, args.time_axis, Path(args.out))
    log.info("wrote %s and its CSV from %d cells:\n%s", args.out, len(runs), curve.to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("jitter", help="the timing-jitter sweep: each task's metrics against the jitter's FWHM, from its cells")
    s.add_argument("runs", nargs="+", help="metrics.json of the jitter<FWHM>ps cells")
    add_time_axis(s)
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_jitter)
