"""`denali` verbs of capture sets into Zarr stores and the capture index (rules/ingest.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import json_arg

log = logging.getLogger("denali")


def cmd_ingest(args: argparse.Namespace) -> None:
    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.core.objects import spec_from_dict
    from denali_pipe.ingest.capture_set import ingest_set

    spec = None if args.object is None else spec_from_dict(args.object)
    index = ingest_set(Path(args.source), Path(args.store), spec)
    with atomic_file(Path(args.index)) as tmp:
        index.to_parquet(tmp, index=False)
    log.info("wrote %s (%d captures) and %s", args.store, len(index), args.index)


def cmd_index(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.core.atomic import atomic_file

    captures = pd.concat([pd.read_parquet(p) for p in args.indexes], ignore_index=True)
    with atomic_file(Path(args.out)) as tmp:
        captures.to_parquet(tmp, index=False)
    log.info("wrote %s (%d captures from %d sets)", args.out, len(captures), len(args.indexes))


def cmd_table4(args: argparse.Namespace) -> None:
    from denali_pipe.report.table4 import write_table4

    write_table4([Path(p) for p in args.stores], Path(args.out))
    log.info("wrote %s", args.out)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("ingest", help="ingest one capture set (release folder or pickle stream) into Zarr")
    s.add_argument("source", help="<set>_NLOSdata folder or <set>_short_NLOSdata.pkl stream")
    s.add_argument("--object", type=json_arg, default=None, help="the object's sheet row as JSON (omit for backgrounds)")
    s.add_argument("--store", required=True, help="output <set>.zarr")
    s.add_argument("--index", required=True, help="output <set>.parquet: one row per capture")
    s.set_defaults(func=cmd_ingest)
    s = sub.add_parser("index", help="concatenate per-set capture indexes")
    s.add_argument("indexes", nargs="+", help="per-set index parquet files")
    s.add_argument("--out", required=True, help="output captures.parquet")
    s.set_defaults(func=cmd_index)
    s = sub.add_parser("table4", help="on-disk size per modality and resolution (Table 4)")
    s.add_argument("stores", nargs="+", help="capture-set Zarr stores")
    s.add_argument("--out", required=True, help="output table4.csv")
    s.set_defaults(func=cmd_table4)
