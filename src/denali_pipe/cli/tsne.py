"""`denali` verbs of Figs 13/14, t-SNE of shape cells (rules/tsne.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_tsne(args: argparse.Namespace) -> None:
    import torch

    from denali_pipe.experiments.tsne import run_tsne, write_tsne
    from denali_pipe.train.dataset import read_dataset

    torch.set_num_threads(args.threads)
    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    table = run_tsne([Path(d) for d in args.runs], x, samples, args.seed)
    write_tsne(table, args.title, Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, table[table["row"] != "point"].dropna(axis=1, how="all").to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("tsne", help="Figs 13/14: t-SNE of shape cells' penultimate-layer embeddings and their separability")
    s.add_argument("runs", nargs="+", help="run folders of shape cells of one resolution (one per seed)")
    s.add_argument("--dataset", required=True, help="datasets/<res>.zarr the cells trained on")
    s.add_argument("--table", required=True, help="datasets/<res>.parquet")
    s.add_argument("--seed", type=int, required=True, help="the config seed: draws the classes, seeds t-SNE and the folds")
    s.add_argument("--title", required=True, help="figure title")
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_tsne)
