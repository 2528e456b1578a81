"""`denali` verbs of saved cells on the held-out variants, Figs 10 and 11 (rules/generalisation.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_evaluate(args: argparse.Namespace) -> None:
    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.train.dataset import read_dataset
    from denali_pipe.train.evaluate import evaluate_run

    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    evaluation = evaluate_run(Path(args.run), x, samples, Path(args.dataset))
    with atomic_file(Path(args.out)) as tmp:
        tmp.write_text(evaluation.to_json())
    log.info("wrote %s: %s on %s (%d samples): %s, baseline %s", args.out, args.run, args.dataset, len(samples), evaluation.metrics, evaluation.baseline)


def _generalisation_inputs(args: argparse.Namespace) -> tuple[list, list]:
    from denali_pipe.train.cell_metrics import CellMetrics
    from denali_pipe.train.evaluate import Evaluation

    return [CellMetrics.read(Path(p)) for p in args.cells], [Evaluation.read(Path(p)) for p in args.evaluations]


def cmd_fig10(args: argparse.Namespace) -> None:
    from denali_pipe.experiments.generalisation import fig10, histogram_table
    from denali_pipe.train.dataset import read_dataset

    x_variant, variant, crop = read_dataset(Path(args.variant_dataset), Path(args.variant_table))
    x_base, base, base_crop = read_dataset(Path(args.base_dataset), Path(args.base_table))
    if crop != base_crop:
        raise ValueError(f"{args.variant_dataset} starts at bin {crop} but {args.base_dataset} at bin {base_crop}; they must share the crop window")
    table = fig10(*_generalisation_inputs(args), histogram_table(x_variant, variant, x_base, base, crop), Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, table[table["panel"] == "score"].dropna(axis=1, how="all").to_string(index=False))


def cmd_fig11(args: argparse.Namespace) -> None:
    from denali_pipe.experiments.generalisation import fig11

    table = fig11(*_generalisation_inputs(args), Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, table.dropna(axis=1, how="all").to_string(index=False))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("evaluate", help="score a saved training cell on another dataset (e.g. the italic or non-RR sets)")
    s.add_argument("run", help="the cell's run folder (model.pt, metrics.json)")
    s.add_argument("dataset", help="datasets/<name>.zarr to score it on")
    s.add_argument("--table", required=True, help="datasets/<name>.parquet")
    s.add_argument("--out", required=True, help="output JSON: the cell's metrics and its baseline's on the dataset")
    s.set_defaults(func=cmd_evaluate)
    for name, what in (
        ("fig10", "Fig 10: non-RR objects' returns, and the benchmark model's base cells scored on them"),
        ("fig11", "Fig 11: the benchmark model's base cells scored on the italic objects"),
    ):
        s = sub.add_parser(name, help=what)
        s.add_argument("--cells", nargs="+", required=True, help="the cells' metrics.json (their own test scores)")
        s.add_argument("--evaluations", nargs="+", required=True, help="`denali evaluate` JSONs of those cells on the variant dataset")
        if name == "fig10":
            s.add_argument("--variant-dataset", required=True, help="datasets/nonrr_<res>.zarr")
            s.add_argument("--variant-table", required=True, help="datasets/nonrr_<res>.parquet")
            s.add_argument("--base-dataset", required=True, help="datasets/<res>.zarr: the retroreflective histograms beside them")
            s.add_argument("--base-table", required=True, help="datasets/<res>.parquet")
        s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
        s.set_defaults(func=cmd_fig10 if name == "fig10" else cmd_fig11)
