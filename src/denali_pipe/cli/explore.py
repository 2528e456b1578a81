"""`denali` verbs of the capture explorer."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_explore(args: argparse.Namespace) -> None:
    from denali_pipe.core.geometry import TimeAxis
    from denali_pipe.explore.app import serve
    from denali_pipe.workflow.config import load_config

    # the captures' time axis, from the config the run that wrote them had
    axis = TimeAxis.from_config(load_config(args.configfile, args.defaults)["sensor"]["time_axis"])
    serve(Path(args.results), axis, args.host, args.port)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("explore", help="browse the workflow's outputs in a web app: captures, histograms, twins, live predictions")
    s.add_argument("--results", default="results", help="the results folder to read (nothing is written to it)")
    s.add_argument("--configfile", nargs="+", default=[], help="config files merged over the defaults, as for the snakemake run that wrote the results")
    s.add_argument("--defaults", default="config/config.yaml", help="the defaults file; the schema beside it validates the result")
    s.add_argument("--host", default="127.0.0.1", help="address to serve on")
    s.add_argument("--port", type=int, default=8050, help="port to serve on")
    s.set_defaults(func=cmd_explore)
