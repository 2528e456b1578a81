"""`denali predict`: trained cells on one raw capture, as JSON on stdout."""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_predict(args: argparse.Namespace) -> None:
    from denali_pipe.preprocess.histograms import read_crop_window
    from denali_pipe.train.evaluate import load_cell
    from denali_pipe.train.predict import predict_capture, read_background, read_capture

    cells = [(Path(r), load_cell(Path(r))) for r in args.runs]
    capture = read_capture(Path(args.capture), args.location)
    background = read_background(Path(args.background), capture.location)
    if background.n_locations == 1:
        log.warning(
            "%s: a background of one location keeps its shot noise, which the training's backgrounds had removed; give the whole NOOBJECT set", args.background
        )
    record = predict_capture(cells, capture, background, read_crop_window(Path(args.crop)), args.repeat)
    print(json.dumps(record, indent=1))


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("predict", help="predict one capture with trained cells (one per task): location, shape top-5, size as JSON")
    s.add_argument("runs", nargs="+", metavar="RUN", help="run folders of the cells (results/runs/.../<model>_<task>/seed<N>), at most one per task")
    s.add_argument("capture", help="the capture: a release <set>_NLOSdata/spad_histogram/NNN.npy, a <set>.zarr store or a .pkl capture stream")
    s.add_argument(
        "--background",
        required=True,
        help="the matching NOOBJECT set (same resolution and lighting): its <set>_NLOSdata folder, store or stream (a single NNN.npy keeps its shot noise)",
    )
    s.add_argument("--crop", required=True, help="crop_<res>.json from crop-window (results/features/crop_<res>.json of the run)")
    s.add_argument(
        "--location", type=int, default=None, help="the gantry location (default: NNN of the file name; needed for a store or stream of several locations)"
    )
    s.add_argument("--repeat", type=int, default=None, help="use this repeat only (default: average over every repeat of the capture)")
    s.set_defaults(func=cmd_predict)
