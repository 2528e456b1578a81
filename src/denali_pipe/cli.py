"""`denali`: one verb per pipeline stage. Each verb is a thin call into the library.

Snakemake rules call these verbs with the (already validated) config subset a
stage needs as JSON, so that a changed setting reruns exactly the jobs that use it.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

log = logging.getLogger("denali")


def _json(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise argparse.ArgumentTypeError(f"not valid JSON ({e}): {text[:80]!r}") from None


def cmd_synth(args: argparse.Namespace) -> None:
    from denali_pipe.capture_sets import parse_set_name
    from denali_pipe.objects import spec_from_dict
    from denali_pipe.rig.capture import synth_sets

    outs = [Path(p) for p in args.outs]
    sets = [parse_set_name(p.name) for p in outs]
    missing = {"seed", "rig"} - set(args.config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
    try:
        spec = None if args.object is None else spec_from_dict(args.object)
    except TypeError as e:
        raise ValueError(f"--object is not an objects-sheet row ({e}): {args.object}") from None
    for cs in sets:
        if (spec is None) != cs.is_background or (spec is not None and spec.name != cs.object):
            raise ValueError(f"capture set {cs.name}: the object record {args.object} does not match the set's object")
    synth_sets(sets, spec, args.config, outs, args.format)
    log.info("wrote %s", " ".join(args.outs))


def cmd_ingest(args: argparse.Namespace) -> None:
    from denali_pipe.atomic import atomic_file
    from denali_pipe.ingest import ingest_set
    from denali_pipe.objects import spec_from_dict

    spec = None if args.object is None else spec_from_dict(args.object)
    index = ingest_set(Path(args.source), Path(args.store), spec)
    with atomic_file(Path(args.index)) as tmp:
        index.to_parquet(tmp, index=False)
    log.info("wrote %s (%d captures) and %s", args.store, len(index), args.index)


def cmd_index(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.atomic import atomic_file

    captures = pd.concat([pd.read_parquet(p) for p in args.indexes], ignore_index=True)
    with atomic_file(Path(args.out)) as tmp:
        captures.to_parquet(tmp, index=False)
    log.info("wrote %s (%d captures from %d sets)", args.out, len(captures), len(args.indexes))


def cmd_table4(args: argparse.Namespace) -> None:
    from denali_pipe.report.table4 import write_table4

    write_table4([Path(p) for p in args.stores], Path(args.out))
    log.info("wrote %s", args.out)


def cmd_poses(args: argparse.Namespace) -> None:
    from denali_pipe.atomic import atomic_file
    from denali_pipe.poses.estimate import detect_set

    table = detect_set(Path(args.store))
    with atomic_file(Path(args.out)) as tmp:
        table.to_parquet(tmp, index=False)
    log.info("wrote %s (%d tag rows, %d estimates)", args.out, len(table), int((table["status"] == "ok").sum()))


def cmd_calibrate(args: argparse.Namespace) -> None:
    import json

    import pandas as pd

    from denali_pipe.atomic import atomic_file
    from denali_pipe.poses.calibrate import calibrate, detection_rates, pool
    from denali_pipe.report.fig12 import write_fig12_from_store
    from denali_pipe.report.table6 import write_table6

    tables = [pd.read_parquet(p) for p in args.poses]
    lit = [t for t in tables if (t["light"] == "lighton").all()]
    if not lit:
        raise ValueError(f"calibrate: none of the {len(tables)} pose tables is from a light-on set")
    cal = calibrate(lit)  # the scene is estimated from light-on frames only
    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    with atomic_file(outdir / "tag1_positions.parquet") as tmp:
        cal.object_positions.to_parquet(tmp, index=False)
    with atomic_file(outdir / "scene.json") as tmp:
        tmp.write_text(json.dumps(cal.scene, indent=1, sort_keys=True) + "\n")
    with atomic_file(outdir / "detections.csv") as tmp:
        detection_rates(pool(tables)).to_csv(tmp, index=False)  # every lighting
    write_table6(cal.estimates, Path(args.table6))
    write_fig12_from_store(Path(args.figure_store), cal.estimates, cal.filtered, Path(args.fig12))
    log.info("wrote %s, %s, %s", outdir, args.table6, args.fig12)


def cmd_rig_examples(args: argparse.Namespace) -> None:
    from denali_pipe.rig.examples import rig_examples

    if len(args.sets) != len(args.backgrounds):
        raise ValueError(f"rig-examples: {len(args.sets)} sets but {len(args.backgrounds)} backgrounds")
    rig_examples(list(zip(map(Path, args.sets), map(Path, args.backgrounds))), Path(args.out))
    log.info("wrote %s", args.out)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="denali", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="verb", required=True)

    s = sub.add_parser("synth", help="synthesise capture sets of one object and size with the embedded capture rig")
    s.add_argument("outs", nargs="+", help="<set>_NLOSdata folders, or <set>_short_NLOSdata.pkl with --format pickle")
    s.add_argument("--object", type=_json, default=None, help="the object's sheet row as JSON (omit for backgrounds)")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "rig": {...}}')
    s.add_argument("--format", choices=["release", "pickle"], default="release", help="release folders or raw pickle streams")
    s.set_defaults(func=cmd_synth)

    s = sub.add_parser("ingest", help="ingest one capture set (release folder or pickle stream) into Zarr")
    s.add_argument("source", help="<set>_NLOSdata folder or <set>_short_NLOSdata.pkl stream")
    s.add_argument("--object", type=_json, default=None, help="the object's sheet row as JSON (omit for backgrounds)")
    s.add_argument("--store", required=True, help="output <set>.zarr")
    s.add_argument("--index", required=True, help="output <set>.parquet: one row per capture")
    s.set_defaults(func=cmd_ingest)

    s = sub.add_parser("index", help="concatenate per-set capture indexes")
    s.add_argument("indexes", nargs="+", help="per-set index parquet files")
    s.add_argument("--out", required=True, help="output captures.parquet")
    s.set_defaults(func=cmd_index)

    s = sub.add_parser("table4", help="on-disk size per modality and resolution (Table 4)")
    s.add_argument("stores", nargs="+", help="capture-set Zarr stores")
    s.add_argument("--out", required=True, help="output table4.csv")
    s.set_defaults(func=cmd_table4)

    s = sub.add_parser("poses", help="detect AprilTags and estimate their poses in one capture set's tracking frames")
    s.add_argument("store", help="the set's <set>.zarr")
    s.add_argument("--out", required=True, help="output <set>.parquet: one row per (frame, tag)")
    s.set_defaults(func=cmd_poses)

    s = sub.add_parser("calibrate", help="world frame, filtered tag positions, scene.json, Table 6, Fig 12")
    s.add_argument("poses", nargs="+", help="per-set pose tables (light-on ones calibrate; all count for detection rates)")
    s.add_argument("--figure-store", required=True, help="the light-on store whose first frame Fig 12 shows")
    s.add_argument("--outdir", required=True, help="results/calibration: tag1_positions.parquet, scene.json, detections.csv")
    s.add_argument("--table6", required=True, help="output table6.csv")
    s.add_argument("--fig12", required=True, help="output fig12.png (its data beside it as CSV)")
    s.set_defaults(func=cmd_calibrate)

    s = sub.add_parser("rig-examples", help="plot example histograms with the three-bounce bump marked")
    s.add_argument("--sets", nargs="+", required=True, help="object capture-set stores (<set>.zarr)")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT set stores, in the same order")
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_rig_examples)
    return p


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except (ValueError, FileNotFoundError, OSError) as e:
        log.error("%s", e)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
