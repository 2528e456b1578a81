"""`denali targets`: each paper artefact and the file that builds it."""

from __future__ import annotations

import argparse


def cmd_targets(args: argparse.Namespace) -> None:
    from denali_pipe.workflow.targets import listing

    print(listing())


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("targets", help="list each paper artefact and its target file (`snakemake <file>` builds it)")
    s.set_defaults(func=cmd_targets)
