"""`denali check-release`: a capture tree (the real release, or capture
streams) against the configured grid, before a run."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_check_release(args: argparse.Namespace) -> None:
    import yaml

    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.core.capture_sets import expected_sets, select_sets
    from denali_pipe.core.objects import load_catalogue
    from denali_pipe.io.tree import survey_tree
    from denali_pipe.workflow.config import load_config

    config = load_config(args.configfile, args.defaults)
    source = args.source or (config["source"] if config["source"] != "synthetic" else "release")
    sets = select_sets(expected_sets(load_catalogue(config["objects_sheet"]), config), config["sets"])
    survey = survey_tree(Path(args.raw_dir), sets, source)
    print(survey.listing())
    if args.write_sets:
        usable = survey.usable()
        if not usable:
            raise ValueError(f"{args.raw_dir}: no configured set is here whole: nothing to write to {args.write_sets}")
        header = f"# The {len(usable)} capture sets of {args.raw_dir} found whole by `denali check-release`\n"
        with atomic_file(Path(args.write_sets)) as tmp:
            tmp.write_text(header + yaml.safe_dump({"sets": usable}))
        log.info("wrote %s: add it after the preset's --configfile to run on these %d sets", args.write_sets, len(usable))
    if not survey.complete:
        raise ValueError(f"{args.raw_dir}: the capture tree does not hold every configured set whole (listed above)")


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("check-release", help="list a capture tree's found, missing and misnamed capture sets and their locations against the config")
    s.add_argument("raw_dir", help="the capture tree: the release's folder of <set>_NLOSdata/ folders (or of .pkl streams)")
    s.add_argument("--configfile", nargs="+", default=[], help="config files merged over the defaults, as for snakemake (e.g. config/presets/release.yaml)")
    s.add_argument("--defaults", default="config/config.yaml", help="the defaults file; the schema beside it validates the result")
    s.add_argument("--source", choices=("release", "pickle"), default=None, help="what the tree holds (default: the config's source, release if synthetic)")
    s.add_argument("--write-sets", metavar="FILE", default=None, help="write the configured sets found whole as a config file (`sets: [...]`)")
    s.set_defaults(func=cmd_check_release)
