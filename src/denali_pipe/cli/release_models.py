"""`denali` verbs of the release's trained generalisation networks (rules/release_models.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_release_weights(args: argparse.Namespace) -> None:
    from denali_pipe.io.release_weights import gather

    status = gather(Path(args.out), Path(args.folder) if args.folder else None, args.url)
    if status.available:
        log.info("wrote %s: the release's weights from %s", args.out, status.source)
    else:
        log.warning("%s: the release's weights are unavailable: %s", args.out, status.missing)


def cmd_release_models(args: argparse.Namespace) -> None:
    import torch

    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.experiments.release_models import BASE, release_models
    from denali_pipe.train.dataset import read_dataset

    torch.set_num_threads(args.threads)
    datasets = {}
    for name, files in ((BASE, args.base), ("italic", args.italic), ("nonrr", args.nonrr)):
        datasets[name] = None if files is None else read_dataset(Path(files[0]), Path(files[1]))[:2]
    table = release_models(Path(args.weights), datasets)
    with atomic_file(Path(args.out)) as tmp:
        table.to_csv(tmp, index=False)
    log.info("wrote %s:\n%s", args.out, table[table.light == "both"].drop(columns=["light", "note"]).to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("release-weights", help="the release's 15 trained generalisation networks, from a local copy or downloaded, sha256 checked")
    s.add_argument("--folder", default=None, help="a copy of the release's benchmark/generalization/ (config release_models.weights); used where it exists")
    s.add_argument("--url", default=None, help="URL template with {commit} and {path} to download from otherwise (config release_models.url); omit for none")
    s.add_argument("--out", required=True, help="output folder (results/release_weights): the files and status.json")
    s.set_defaults(func=cmd_release_weights)
    s = sub.add_parser("release-models", help="the release's networks scored on their own test parts of this run's 3x3 captures")
    s.add_argument("--weights", required=True, help="results/release_weights (`denali release-weights`)")
    for name, what in (("base", "base objects"), ("italic", "italic variants"), ("nonrr", "non-retroreflective variants")):
        s.add_argument(
            f"--{name}",
            nargs=2,
            metavar=("X", "TABLE"),
            default=None,
            help=f"datasets/paper/ zarr and parquet of the {what} at 3x3; omit where the run has none",
        )
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument("--out", required=True, help="results/release_models.csv")
    s.set_defaults(func=cmd_release_models)
