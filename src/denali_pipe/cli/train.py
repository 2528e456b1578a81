"""`denali` verbs of one training cell and of the `paper` protocol's inputs (rules/train.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis, json_arg
from denali_pipe.train.cells import PRECISIONS

log = logging.getLogger("denali")


def cmd_train(args: argparse.Namespace) -> None:
    import torch

    from denali_pipe.core.atomic import atomic_dir
    from denali_pipe.train.cell_metrics import METRICS_FILE
    from denali_pipe.train.cells import LINEAR, Cell
    from denali_pipe.train.conditions import condition_view
    from denali_pipe.train.dataset import read_dataset
    from denali_pipe.train.precision import cpu_has_native_bf16
    from denali_pipe.train.saved_cell import MODEL_FILE
    from denali_pipe.train.training import Hyper, run_cell, training_device

    torch.set_num_threads(args.threads)
    cell = Cell(**args.cell)
    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    try:
        x, samples = condition_view(x, samples, cell.task, cell.condition, args.time_axis)
    except ValueError as e:
        raise ValueError(f"{args.table}: {e}") from None
    if cell.model == LINEAR:
        # imported here: scikit-learn costs every neural cell's job ~1.5 CPU-s to import
        from denali_pipe.train.classical import run_linear

        result = run_linear(x, samples, cell, args.validation_fraction)
    elif args.factory is None:
        raise ValueError(f"train: model {cell.model!r} is a network and needs --factory 'package.module:factory'")
    else:
        device = training_device(torch.cuda.is_available())
        hyper = Hyper(**args.hyper)
        weights = Path(args.release_weights) if args.release_weights else None
        result = run_cell(
            x, samples, cell, hyper, args.validation_fraction, args.factory, device, args.budget_seconds, args.precision, cpu_has_native_bf16(), weights
        )
    with atomic_dir(Path(args.outdir)) as tmp:
        (tmp / METRICS_FILE).write_text(result.metrics.to_json())
        result.curves.to_csv(tmp / "curves.csv", index=False)
        torch.save(result.state, tmp / MODEL_FILE)
    m = result.metrics
    log.info("wrote %s: test %s, %.1f s training (%.0f samples/s)", args.outdir, m.test, m.train_seconds, m.train_samples_per_second)


def cmd_paper_dataset(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.core.objects import load_catalogue
    from denali_pipe.train.dataset import location_labels, write_dataset
    from denali_pipe.train.paper_inputs import paper_samples

    x, samples = paper_samples(
        [Path(p) for p in args.stores], load_catalogue(args.objects_sheet), location_labels(pd.read_parquet(args.positions)), args.variant
    )
    write_dataset(x, samples, Path(args.out), Path(args.table), crop_start=0)
    log.info("wrote %s %s and %s", args.out, x.shape, args.table)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("paper-dataset", help="the paper protocol's samples: every repeat's raw counts from the capture stores, in the reference's order")
    s.add_argument("stores", nargs="+", help="store/<set>.zarr of one resolution")
    s.add_argument("--variant", default="base", help="the objects' variant (objects.VARIANTS): base (the benchmark), italic or nonrr")
    s.add_argument("--positions", required=True, help="calibration/tag1_positions.parquet (location labels)")
    s.add_argument("--objects-sheet", required=True, help="objects.tsv")
    s.add_argument("--out", required=True, help="output datasets/paper/<name>.zarr (array x)")
    s.add_argument("--table", required=True, help="output datasets/paper/<name>.parquet (one row per sample)")
    s.set_defaults(func=cmd_paper_dataset)
    s = sub.add_parser("train", help="train and evaluate one cell (model x task x split x resolution x condition x protocol x seed)")
    s.add_argument("dataset", help="datasets/<res>.zarr")
    s.add_argument("--table", required=True, help="datasets/<res>.parquet")
    s.add_argument("--cell", type=json_arg, required=True, help='JSON {"model", "task", "split", "resolution", "condition", "protocol", "seed"}')
    s.add_argument("--hyper", type=json_arg, required=True, help='JSON {"lr", "epochs", "batch_size", "norm"[, "init"]} ({} for the linear model)')
    s.add_argument(
        "--factory", default=None, help="the network's factory 'package.module:factory' (config train.models.<model>.factory; not for the linear model)"
    )
    s.add_argument("--validation-fraction", type=float, required=True, help="validation share of the training split (clean protocol)")
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="float32",
        help="the networks' training dtype (config train.precision; auto: bfloat16 on a CPU that multiplies it natively, where its check passes)",
    )
    s.add_argument("--budget-seconds", type=float, default=None, help="stop a network's training after this much training time")
    add_time_axis(s, needed_by="a jitter condition's blur (FWHM in ps)")
    s.add_argument("--release-weights", default=None, help="results/release_weights, where --hyper's init names a release checkpoint to start from")
    s.add_argument("--outdir", required=True, help="output run folder: metrics.json, curves.csv, model.pt")
    s.set_defaults(func=cmd_train)
