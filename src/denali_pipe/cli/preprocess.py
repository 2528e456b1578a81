"""`denali` verbs of background subtraction, cropping and the benchmark's datasets (rules/preprocess.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis

log = logging.getLogger("denali")


def cmd_crop_window(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.core.objects import SIZES
    from denali_pipe.io.store import open_set
    from denali_pipe.preprocess.histograms import DIRECT_END_FRACTION, crop_window
    from denali_pipe.twin.layout import load_calibration, three_bounce_lead

    stores = [open_set(Path(p)) for p in args.backgrounds]
    n = stores[0].histograms.shape[2]
    lead = three_bounce_lead(load_calibration(Path(args.scene)), n, max(SIZES.values())) / args.time_axis.bin_width_opl
    window = crop_window([s.histograms[...] for s in stores], lead)
    record = {
        **window.to_dict(),
        "direct_end_fraction": DIRECT_END_FRACTION,
        "three_bounce_lead_bins": lead.round(2).tolist(),
        "backgrounds": [s.name for s in stores],
    }
    with atomic_file(Path(args.out)) as tmp:
        tmp.write_text(json.dumps(record, indent=1) + "\n")
    log.info("wrote %s: first kept bin %d, per zone %s", args.out, window.crop_start, window.zone_starts.tolist())


def cmd_preprocess(args: argparse.Namespace) -> None:
    from denali_pipe.io.features import write_features
    from denali_pipe.io.store import open_set
    from denali_pipe.preprocess.histograms import background_means, preprocess, read_crop_window

    store, bg = open_set(Path(args.store)), open_set(Path(args.background))
    window = read_crop_window(Path(args.crop))
    try:
        feats = preprocess(store.histograms[...], store.locations, background_means(bg.histograms[...]), bg.locations, window)
    except ValueError as e:
        raise ValueError(f"{args.store} (background {args.background}): {e}") from None
    write_features(Path(args.out), store.capture_set, feats, bg.name)
    log.info("wrote %s: %s from bin %d, shifts %s", args.out, feats.values.shape, window.crop_start, sorted(set(feats.shifts.ravel().tolist())))


def cmd_dataset(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.core.objects import load_catalogue
    from denali_pipe.io.features import read_features
    from denali_pipe.train.dataset import build_dataset, location_labels, write_dataset

    x, samples = build_dataset(
        [Path(p) for p in args.features], load_catalogue(args.objects_sheet), location_labels(pd.read_parquet(args.positions)), args.variant
    )
    write_dataset(x, samples, Path(args.out), Path(args.table), read_features(Path(args.features[0]))[1].crop_start)
    log.info("wrote %s %s and %s", args.out, x.shape, args.table)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("crop-window", help="first histogram bin after the direct return, from background sets")
    s.add_argument("backgrounds", nargs="+", help="NOOBJECT stores of one resolution")
    s.add_argument("--scene", required=True, help="results/calibration/scene.json: where the objects can be")
    add_time_axis(s)
    s.add_argument("--out", required=True, help="output crop_<res>.json")
    s.set_defaults(func=cmd_crop_window)
    s = sub.add_parser("preprocess", help="align, subtract the background and crop one capture set")
    s.add_argument("store", help="the set's <set>.zarr")
    s.add_argument("--background", required=True, help="the matching NOOBJECT store")
    s.add_argument("--crop", required=True, help="crop_<res>.json from crop-window")
    s.add_argument("--out", required=True, help="output features/<set>.zarr")
    s.set_defaults(func=cmd_preprocess)
    s = sub.add_parser("dataset", help="stack one variant's features and location labels into samples (base: the benchmark's)")
    s.add_argument("features", nargs="+", help="features/<set>.zarr of one resolution")
    s.add_argument("--variant", default="base", help="the objects' variant (objects.VARIANTS): base (the benchmark), italic or nonrr")
    s.add_argument("--positions", required=True, help="calibration/tag1_positions.parquet (location labels)")
    s.add_argument("--objects-sheet", required=True, help="objects.tsv")
    s.add_argument("--out", required=True, help="output datasets/<res>.zarr (array x)")
    s.add_argument("--table", required=True, help="output datasets/<res>.parquet (one row per sample)")
    s.set_defaults(func=cmd_dataset)
