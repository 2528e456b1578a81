"""`denali` verbs of Fig 9, sim-to-real transfer (rules/fig9.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import json_arg
from denali_pipe.cli.fit import pairs_and_split
from denali_pipe.train.cells import PRECISIONS

log = logging.getLogger("denali")


def cmd_fig9(args: argparse.Namespace) -> None:
    import numpy as np
    import pandas as pd
    import torch

    from denali_pipe.experiments.fig9 import run_fig9
    from denali_pipe.report.fig9 import write_fig9
    from denali_pipe.train.dataset import location_labels
    from denali_pipe.train.precision import cpu_has_native_bf16
    from denali_pipe.train.training import Hyper
    from denali_pipe.transforms.sim_to_real import read_fit_check, read_transforms

    torch.set_num_threads(args.threads)
    pairs, _ = pairs_and_split(args)
    labels = location_labels(pd.read_parquet(args.positions))
    unlabelled = sorted(set(pairs.keys["location"]) - set(labels))
    if unlabelled:
        raise ValueError(f"{args.positions}: no tag 1 position for locations {unlabelled}")
    _, _, captures = pairs.captures()
    xy = np.array([labels[int(k)] for k in captures["location"]], np.float32)
    for z, check in enumerate(read_fit_check(Path(args.transforms))):
        if not check.identifiable:
            log.warning(
                "%s: zone %d's simulated fidelities use transforms the real captures do not identify (%s)", args.transforms, z, ", ".join(check.unidentified)
            )
    runs = run_fig9(
        pairs,
        xy,
        read_transforms(Path(args.transforms)),
        args.config["fit"],
        Hyper(**args.hyper),
        args.config["seed"],
        args.precision,
        cpu_has_native_bf16(),
    )
    out = Path(args.out)
    table = write_fig9(runs, out, out.with_suffix(".csv"))
    log.info("wrote %s and its CSV:\n%s", out, table.to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("fig9", help="Fig 9: localisation RMSE on real captures against real samples added to simulated training data")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--twins", nargs="+", required=True, help="their objects' twin stores (results/twin/<object>_<size>.zarr)")
    s.add_argument("--positions", required=True, help="results/calibration/tag1_positions.parquet (location labels)")
    s.add_argument("--transforms", required=True, help="results/transforms.json")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "fit": {...}}')
    s.add_argument("--hyper", type=json_arg, required=True, help='JSON {"lr", "epochs", "batch_size", "norm"} of the localiser')
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="float32",
        help="the localisers' training dtype (config train.precision; auto: bfloat16 on a CPU that multiplies it natively, where its check passes)",
    )
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_fig9)
