"""`denali export`: a trained cell as a torch.export program or an ONNX model, with its normalisation and labels."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_export(args: argparse.Namespace) -> None:
    from denali_pipe.preprocess.histograms import read_crop_window
    from denali_pipe.train.evaluate import load_cell
    from denali_pipe.train.export import METADATA_KEY, export_cell

    run = Path(args.run)
    meta = export_cell(load_cell(run), run, Path(args.out), None if args.crop is None else read_crop_window(Path(args.crop)))
    log.info(
        "wrote %s: %s %s cell, input %s, classes %s (metadata in its %s)",
        args.out,
        meta["cell"]["model"],
        meta["task"],
        meta["input_shape"],
        meta["classes"],
        METADATA_KEY,
    )


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser(
        "export", help="write a trained cell as a torch.export program (.pt2) or an ONNX model (.onnx), its normalisation inside and its labels in denali.json"
    )
    s.add_argument("run", help="the cell's run folder (model.pt)")
    s.add_argument("out", help="output file: .pt2 (torch.export) or .onnx")
    s.add_argument("--crop", default=None, help="crop_<res>.json from crop-window, recorded in the metadata so the file says its input's time window")
    s.set_defaults(func=cmd_export)
