"""`denali` verb of the stability report (rules/stability.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_stability(args: argparse.Namespace) -> None:
    from denali_pipe.report.stability import write_stability

    table = write_stability([Path(p) for p in args.cells], Path(args.transforms), Path(args.calibration), Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, table[["failure", "count", "of", "governed_by"]].to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("stability", help="every failure mode of the run's training cells, sim-to-real fit and twin calibration")
    s.add_argument("cells", nargs="+", help="metrics.json of every training cell of the run")
    s.add_argument("--transforms", required=True, help="results/transforms.json")
    s.add_argument("--calibration", required=True, help="results/twin_calibration.json")
    s.add_argument("--out", required=True, help="PNG path; the table (stability.csv) goes beside it as CSV")
    s.set_defaults(func=cmd_stability)
