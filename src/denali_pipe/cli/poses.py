"""`denali` verbs of tracking poses and the scene calibration (rules/poses.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_poses(args: argparse.Namespace) -> None:
    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.poses.estimate import detect_set

    table = detect_set(Path(args.store))
    with atomic_file(Path(args.out)) as tmp:
        table.to_parquet(tmp, index=False)
    log.info("wrote %s (%d tag rows, %d estimates)", args.out, len(table), int((table["status"] == "ok").sum()))


def _lit_tables(paths: list[str], verb: str) -> list:
    import pandas as pd

    tables = [pd.read_parquet(p) for p in paths]
    dark = [p for p, t in zip(paths, tables) if not (t["light"] == "lighton").all()]
    if dark or not tables:
        raise ValueError(f"{verb} takes light-on pose tables only; got {dark or 'none'}")
    return tables


def cmd_calibrate(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.poses.calibrate import calibrate

    cal = calibrate(_lit_tables(args.poses, "calibrate"))
    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    with atomic_file(outdir / "tag1_positions.parquet") as tmp:
        cal.object_positions.to_parquet(tmp, index=False)
    with atomic_file(outdir / "scene.json") as tmp:
        tmp.write_text(json.dumps(cal.scene, indent=1, sort_keys=True) + "\n")
    log.info("wrote %s from %d sets", outdir, len(args.poses))


def cmd_table6(args: argparse.Namespace) -> None:
    from denali_pipe.poses.calibrate import calibrate
    from denali_pipe.report.fig12 import write_fig12_from_store
    from denali_pipe.report.table6 import write_table6

    cal = calibrate(_lit_tables(args.poses, "table6"))
    write_table6(cal.estimates, Path(args.table6))
    write_fig12_from_store(Path(args.figure_store), cal.estimates, cal.filtered, Path(args.fig12))
    log.info("wrote %s, %s", args.table6, args.fig12)


def cmd_detections(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.poses.calibrate import detection_rates, pool

    with atomic_file(Path(args.out)) as tmp:
        detection_rates(pool([pd.read_parquet(p) for p in args.poses])).to_csv(tmp, index=False)
    log.info("wrote %s", args.out)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("poses", help="detect AprilTags and estimate their poses in one capture set's tracking frames")
    s.add_argument("store", help="the set's <set>.zarr")
    s.add_argument("--out", required=True, help="output <set>.parquet: one row per (frame, tag)")
    s.set_defaults(func=cmd_poses)
    s = sub.add_parser("calibrate", help="world frame, filtered tag-1 positions and scene.json from the light-on background sets")
    s.add_argument("poses", nargs="+", help="per-set pose tables of the light-on background sets")
    s.add_argument("--outdir", required=True, help="results/calibration: tag1_positions.parquet, scene.json")
    s.set_defaults(func=cmd_calibrate)
    s = sub.add_parser("table6", help="Table 6 and Fig 12: tag statistics over every light-on set")
    s.add_argument("poses", nargs="+", help="per-set pose tables of the light-on sets")
    s.add_argument("--figure-store", required=True, help="the light-on store whose first frame Fig 12 shows")
    s.add_argument("--table6", required=True, help="output table6.csv")
    s.add_argument("--fig12", required=True, help="output fig12.png (its data beside it as CSV)")
    s.set_defaults(func=cmd_table6)
    s = sub.add_parser("detections", help="AprilTag detection rates per tag and lighting")
    s.add_argument("poses", nargs="+", help="per-set pose tables (every lighting)")
    s.add_argument("--out", required=True, help="output detections.csv")
    s.set_defaults(func=cmd_detections)
