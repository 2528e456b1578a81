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


def cmd_rig(args: argparse.Namespace) -> None:
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


def cmd_training_report(args: argparse.Namespace) -> None:
    from denali_pipe.conditions import TABLES
    from denali_pipe.report.condition_table import write_condition_table
    from denali_pipe.report.speed_vs_accuracy import write_speed_vs_accuracy
    from denali_pipe.report.table2 import write_table2
    from denali_pipe.report.table5 import write_table5
    from denali_pipe.report.table10 import write_table10
    from denali_pipe.report.training_curves import write_training_curves

    paths, out = [Path(p) for p in args.runs], Path(args.out)
    if args.kind == "table5":
        write_table5(paths, out)
    elif args.kind == "table2":
        write_table2(paths, out)
    elif args.kind == "table10":
        write_table10(paths, out)
    elif args.kind == "speed-vs-accuracy":
        write_speed_vs_accuracy(paths, out)
    elif args.kind in TABLES:
        write_condition_table(paths, args.kind, args.groups, out)
    else:
        task = {"fig16": "location", "fig17": "shape"}[args.kind]
        write_training_curves(paths, task, args.title, out)
    log.info("wrote %s from %d cells", out, len(paths))


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


def _lit_tables(paths: list[str], verb: str) -> list:
    import pandas as pd

    tables = [pd.read_parquet(p) for p in paths]
    dark = [p for p, t in zip(paths, tables) if not (t["light"] == "lighton").all()]
    if dark or not tables:
        raise ValueError(f"{verb} takes light-on pose tables only; got {dark or 'none'}")
    return tables


def cmd_calibrate(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.atomic import atomic_file
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

    from denali_pipe.atomic import atomic_file
    from denali_pipe.poses.calibrate import detection_rates, pool

    with atomic_file(Path(args.out)) as tmp:
        detection_rates(pool([pd.read_parquet(p) for p in args.poses])).to_csv(tmp, index=False)
    log.info("wrote %s", args.out)


def cmd_crop_window(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.atomic import atomic_file
    from denali_pipe.io.store import open_set
    from denali_pipe.preprocess import DIRECT_END_FRACTION, crop_window

    stores = [open_set(Path(p)) for p in args.backgrounds]
    window = crop_window([s.histograms[...] for s in stores])
    record = {**window.to_dict(), "direct_end_fraction": DIRECT_END_FRACTION, "backgrounds": [s.name for s in stores]}
    with atomic_file(Path(args.out)) as tmp:
        tmp.write_text(json.dumps(record, indent=1) + "\n")
    log.info("wrote %s: first kept bin %d, per zone %s", args.out, window.crop_start, window.zone_starts.tolist())


def cmd_preprocess(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.io.features import write_features
    from denali_pipe.io.store import open_set
    from denali_pipe.preprocess import CropWindow, preprocess

    store, bg = open_set(Path(args.store)), open_set(Path(args.background))
    window = CropWindow.from_dict(json.loads(Path(args.crop).read_text()))
    try:
        feats = preprocess(store.histograms[...], store.locations, bg.histograms[...], bg.locations, window)
    except ValueError as e:
        raise ValueError(f"{args.store} (background {args.background}): {e}") from None
    write_features(Path(args.out), store.capture_set, feats, bg.name)
    log.info("wrote %s: %s from bin %d, shifts %s", args.out, feats.values.shape, window.crop_start, sorted(set(feats.shifts.ravel().tolist())))


def cmd_dataset(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.dataset import build_dataset, location_labels, write_dataset
    from denali_pipe.io.features import read_features
    from denali_pipe.objects import load_catalogue

    x, samples = build_dataset(
        [Path(p) for p in args.features], load_catalogue(args.objects_sheet), location_labels(pd.read_parquet(args.positions)), args.variant
    )
    write_dataset(x, samples, Path(args.out), Path(args.table), read_features(Path(args.features[0]))[1].crop_start)
    log.info("wrote %s %s and %s", args.out, x.shape, args.table)


def cmd_train(args: argparse.Namespace) -> None:
    import torch

    from denali_pipe.atomic import atomic_dir
    from denali_pipe.cell_metrics import METRICS_FILE
    from denali_pipe.cells import LINEAR, Cell
    from denali_pipe.conditions import condition_view
    from denali_pipe.dataset import read_dataset
    from denali_pipe.train import Hyper, run_cell

    torch.set_num_threads(args.threads)
    cell = Cell(**args.cell)
    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    try:
        x, samples = condition_view(x, samples, cell.task, cell.condition)
    except ValueError as e:
        raise ValueError(f"{args.table}: {e}") from None
    if cell.model == LINEAR:
        # imported here: scikit-learn costs every neural cell's job ~1.5 CPU-s to import
        from denali_pipe.classical import run_linear

        result = run_linear(x, samples, cell, args.validation_fraction)
    else:
        device = "cuda" if torch.cuda.is_available() else "cpu"
        result = run_cell(x, samples, cell, Hyper(**args.hyper), args.validation_fraction, device, args.budget_seconds)
    with atomic_dir(Path(args.outdir)) as tmp:
        (tmp / METRICS_FILE).write_text(result.metrics.to_json())
        result.curves.to_csv(tmp / "curves.csv", index=False)
        torch.save(result.state, tmp / "model.pt")
    m = result.metrics
    log.info("wrote %s: test %s, %.1f s training (%.0f samples/s)", args.outdir, m.test, m.train_seconds, m.train_samples_per_second)


def cmd_twin(args: argparse.Namespace) -> None:
    from denali_pipe.objects import spec_from_dict
    from denali_pipe.twin.render import render_twin

    missing = {"seed", "resolutions", "twin"} - set(args.config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
    calibration = Path(args.calibration) if args.calibration else None
    render_twin(spec_from_dict(args.object), args.size, Path(args.scene), args.config, Path(args.out), calibration)
    log.info("wrote %s", args.out)


def cmd_twin_calibrate(args: argparse.Namespace) -> None:
    import time

    from denali_pipe.objects import spec_from_dict
    from denali_pipe.report.twin_calibration import plot_calibration
    from denali_pipe.transforms import read_real, split_pairs
    from denali_pipe.twin.calibrate import Captures, at_bound, calibrate, write_calibration
    from denali_pipe.twin.layout import load_calibration

    missing = {"seed", "fit", "twin"} - set(args.config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
    t0 = time.perf_counter()
    real, keys, crop = read_real([Path(p) for p in args.features])
    split = split_pairs(keys, args.config["seed"], args.config["fit"]["test_fraction"])
    train = Captures(real, keys, crop).subset(split.train)
    specs = {d["name"]: spec_from_dict(d) for d in args.objects}
    settings = args.config["twin"]
    result, problem, held = calibrate(load_calibration(Path(args.scene)), specs, train, settings, args.config["seed"])
    record = {
        "n_captures": len(problem.y),
        "n_validation": len(held.y),
        "n_test_excluded": int(len(split.test)),
        "crop_start": crop,
        "config": args.config,
        "seconds": time.perf_counter() - t0,
    }
    write_calibration(Path(args.out), result, settings, record)
    pinned = at_bound(result.x, settings)
    if pinned:
        log.warning(
            "twin calibration: %d coordinates at the edge of their range (%s): the twin's geometry cannot follow the captures there",
            len(pinned),
            ", ".join(pinned),
        )
    plot_calibration(result, held, Path(args.png))
    log.info("wrote %s and %s (%.1f s): residual before %s, after %s", args.out, args.png, record["seconds"], result.before, result.after)


def cmd_render_benchmark(args: argparse.Namespace) -> None:
    from denali_pipe.objects import spec_from_dict
    from denali_pipe.report.render_benchmark import plot_render_benchmark
    from denali_pipe.twin.benchmark import run_benchmark
    from denali_pipe.twin.layout import load_calibration

    missing = {"seed", "sizes", "twin"} - set(args.config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
    specs = [spec_from_dict(d) for d in args.objects]
    summary, _ = run_benchmark(load_calibration(Path(args.scene)), specs, args.config["sizes"], args.config["twin"], args.config["seed"])
    plot_render_benchmark(summary, Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, summary.to_string(index=False))


def cmd_fig18(args: argparse.Namespace) -> None:
    import json

    from denali_pipe.report.fig18 import fig18

    if not len(args.sets) == len(args.backgrounds) == len(args.twins):
        raise ValueError(f"fig18: {len(args.sets)} sets, {len(args.backgrounds)} backgrounds and {len(args.twins)} twins; expected one of each per row")
    captures = [(Path(a), Path(b), Path(c)) for a, b, c in zip(args.sets, args.backgrounds, args.twins)]
    crop = json.loads(Path(args.crop).read_text())["crop_start"]
    fig18(captures, Path(args.scene), Path(args.calibration), crop, args.config, Path(args.out))
    log.info("wrote %s", args.out)


def _pairs_and_split(args: argparse.Namespace):
    """The sim-to-real pairs of --features and --twins and the real train/test split of --config."""
    from denali_pipe.transforms import build_pairs, split_pairs

    missing = {"seed", "fit"} - set(args.config)
    if missing:
        raise ValueError(f"--config lacks the keys {sorted(missing)}")
    pairs = build_pairs([Path(p) for p in args.features], [Path(p) for p in args.twins])
    return pairs, split_pairs(pairs.keys, args.config["seed"], args.config["fit"]["test_fraction"])


def cmd_transforms(args: argparse.Namespace) -> None:
    import time

    from denali_pipe.transforms import check_fit, choose_mode, fit_zone_transforms, write_transforms

    t0 = time.perf_counter()
    pairs, split = _pairs_and_split(args)
    train = pairs.subset(split.train)
    fit = args.config["fit"]
    mode, residuals = choose_mode(train, args.config["seed"], fit["mode_validation_fraction"])
    zt = fit_zone_transforms(train, mode)
    t1 = time.perf_counter()
    boot = fit["bootstrap"]
    if mode == "shared":
        checks = [check_fit(train, zt.zones[0], boot["resamples"], args.config["seed"], boot["level"], boot["max_rel_se"])] * len(zt.zones)
    else:
        checks = [check_fit(train.zone(z), t, boot["resamples"], args.config["seed"], boot["level"], boot["max_rel_se"]) for z, t in enumerate(zt.zones)]
    t2 = time.perf_counter()
    record = {
        "mode_residual": residuals,
        "n_pairs": int(len(split.train)),
        "n_test_pairs": int(len(split.test)),
        "repeats": int(pairs.real.shape[1]),
        "crop_start": pairs.crop_start,
        "bins": pairs.bins,
        "config": args.config,
        "seconds": t2 - t0,
        "bootstrap_seconds": t2 - t1,
    }
    write_transforms(Path(args.out), zt, checks, record)
    log.info(
        "wrote %s: mode %s (held-out residual %s), centre zone %s, identifiable %s (%.1f s, of which the bootstrap %.1f s)",
        args.out,
        mode,
        residuals,
        zt.zones[len(zt.zones) // 2].to_dict(),
        [c.identifiable for c in checks],
        t2 - t0,
        t2 - t1,
    )


def cmd_fig9(args: argparse.Namespace) -> None:
    import numpy as np
    import pandas as pd
    import torch

    from denali_pipe.dataset import location_labels
    from denali_pipe.experiments.fig9 import run_fig9
    from denali_pipe.report.fig9 import write_fig9
    from denali_pipe.train import Hyper
    from denali_pipe.transforms import read_fit_check, read_transforms

    torch.set_num_threads(args.threads)
    pairs, _ = _pairs_and_split(args)
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
    runs = run_fig9(pairs, xy, read_transforms(Path(args.transforms)), args.config["fit"], Hyper(**args.hyper), args.config["seed"])
    out = Path(args.out)
    table = write_fig9(runs, out, out.with_suffix(".csv"))
    log.info("wrote %s and its CSV:\n%s", out, table.to_string(index=False))


def cmd_evaluate(args: argparse.Namespace) -> None:
    from denali_pipe.atomic import atomic_file
    from denali_pipe.dataset import read_dataset
    from denali_pipe.evaluate import evaluate_run

    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    evaluation = evaluate_run(Path(args.run), x, samples, Path(args.dataset))
    with atomic_file(Path(args.out)) as tmp:
        tmp.write_text(evaluation.to_json())
    log.info("wrote %s: %s on %s (%d samples): %s, baseline %s", args.out, args.run, args.dataset, len(samples), evaluation.metrics, evaluation.baseline)


def _generalisation_inputs(args: argparse.Namespace) -> tuple[list, list]:
    from denali_pipe.cell_metrics import CellMetrics
    from denali_pipe.evaluate import Evaluation

    return [CellMetrics.read(Path(p)) for p in args.cells], [Evaluation.read(Path(p)) for p in args.evaluations]


def cmd_fig10(args: argparse.Namespace) -> None:
    from denali_pipe.dataset import read_dataset
    from denali_pipe.experiments.generalisation import fig10, histogram_table

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


def cmd_tsne(args: argparse.Namespace) -> None:
    import torch

    from denali_pipe.dataset import read_dataset
    from denali_pipe.experiments.tsne import run_tsne, write_tsne

    torch.set_num_threads(args.threads)
    x, samples, _ = read_dataset(Path(args.dataset), Path(args.table))
    table = run_tsne([Path(d) for d in args.runs], x, samples, args.seed)
    write_tsne(table, args.title, Path(args.out))
    log.info("wrote %s and its CSV:\n%s", args.out, table[table["row"] != "point"].dropna(axis=1, how="all").to_string(index=False))


def cmd_jitter(args: argparse.Namespace) -> None:
    from denali_pipe.experiments.jitter import jitter_curve
    from denali_pipe.report.jitter import plot_jitter
    from denali_pipe.report.runs import load_runs, protocol_of

    runs = load_runs([Path(p) for p in args.runs])
    curve = jitter_curve(runs)
    title = f"1D CNN on the 3x3 centre zone, lights on, against timing jitter (random split, {protocol_of(runs)} protocol)"
    plot_jitter(curve, title, Path(args.out))
    log.info("wrote %s and its CSV from %d cells:\n%s", args.out, len(runs), curve.to_string(index=False))


def cmd_rig_examples(args: argparse.Namespace) -> None:
    from denali_pipe.rig.examples import rig_examples

    if len(args.sets) != len(args.backgrounds):
        raise ValueError(f"rig-examples: {len(args.sets)} sets but {len(args.backgrounds)} backgrounds")
    rig_examples(list(zip(map(Path, args.sets), map(Path, args.backgrounds))), Path(args.out))
    log.info("wrote %s", args.out)


def cmd_rig_vs_real(args: argparse.Namespace) -> None:
    from denali_pipe.report.rig_vs_real import rig_vs_real

    if len(args.sets) != len(args.backgrounds):
        raise ValueError(f"rig-vs-real: {len(args.sets)} sets but {len(args.backgrounds)} backgrounds")
    rig_vs_real(list(zip(map(Path, args.sets), map(Path, args.backgrounds))), Path(args.png), Path(args.csv))
    log.info("wrote %s and %s", args.png, args.csv)


def cmd_explore(args: argparse.Namespace) -> None:
    from denali_pipe.explore.app import serve

    serve(Path(args.results), args.host, args.port)


def build_parser() -> argparse.ArgumentParser:
    from denali_pipe.conditions import CONDITION_GROUPS
    from denali_pipe.conditions import TABLES as CONDITION_TABLES

    p = argparse.ArgumentParser(prog="denali", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="verb", required=True)

    s = sub.add_parser("rig", help="synthesise capture sets of one object and size with the embedded capture rig")
    s.add_argument("outs", nargs="+", help="<set>_NLOSdata folders, or <set>_short_NLOSdata.pkl with --format pickle")
    s.add_argument("--object", type=_json, default=None, help="the object's sheet row as JSON (omit for backgrounds)")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "rig": {...}}')
    s.add_argument("--format", choices=["release", "pickle"], default="release", help="release folders or raw pickle streams")
    s.set_defaults(func=cmd_rig)

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

    s = sub.add_parser("report", help="a training table or figure from cells' metrics.json / curves.csv")
    s.add_argument("kind", choices=["table2", "table5", *CONDITION_TABLES, "table10", "fig16", "fig17", "speed-vs-accuracy"])
    s.add_argument("runs", nargs="+", help="metrics.json files (curves.csv for fig16/fig17)")
    s.add_argument("--title", default="", help="figure title (fig16/fig17)")
    s.add_argument("--groups", nargs="+", choices=CONDITION_GROUPS, default=list(CONDITION_GROUPS), help="condition groups trained (tables 7-9; default: all)")
    s.add_argument("--out", required=True, help="output CSV or PNG (a PNG gets its data beside it as CSV)")
    s.set_defaults(func=cmd_training_report)

    s = sub.add_parser("table4", help="on-disk size per modality and resolution (Table 4)")
    s.add_argument("stores", nargs="+", help="capture-set Zarr stores")
    s.add_argument("--out", required=True, help="output table4.csv")
    s.set_defaults(func=cmd_table4)

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

    s = sub.add_parser("crop-window", help="first histogram bin after the direct return, from background sets")
    s.add_argument("backgrounds", nargs="+", help="NOOBJECT stores of one resolution")
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

    s = sub.add_parser("train", help="train and evaluate one cell (model x task x split x resolution x condition x protocol x seed)")
    s.add_argument("dataset", help="datasets/<res>.zarr")
    s.add_argument("--table", required=True, help="datasets/<res>.parquet")
    s.add_argument("--cell", type=_json, required=True, help='JSON {"model", "task", "split", "resolution", "condition", "protocol", "seed"}')
    s.add_argument("--hyper", type=_json, required=True, help='JSON {"lr", "epochs", "batch_size", "norm"} ({} for the linear model)')
    s.add_argument("--validation-fraction", type=float, required=True, help="validation share of the training split (clean protocol)")
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument("--budget-seconds", type=float, default=None, help="stop a network's training after this much training time")
    s.add_argument("--outdir", required=True, help="output run folder: metrics.json, curves.csv, model.pt")
    s.set_defaults(func=cmd_train)

    s = sub.add_parser("twin", help="render one object and size's digital twin at every calibrated location")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--object", type=_json, required=True, help="the object's sheet row as JSON")
    s.add_argument("--size", required=True, choices=["4inch", "8inch"], help="object size")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "twin": {...}}')
    s.add_argument("--calibration", help="results/twin_calibration.json: render the calibrated twin (footprints, time offset, lobe)")
    s.add_argument("--out", required=True, help="output results/twin/<object>_<size>.zarr")
    s.set_defaults(func=cmd_twin)

    s = sub.add_parser("twin-calibrate", help="fit the twin's zone footprints, time offset and lobe to the training captures")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--objects", type=_json, required=True, help="JSON list of the objects' sheet rows")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "fit": {"test_fraction": ...}, "twin": {...}}')
    s.add_argument("--out", required=True, help="output results/twin_calibration.json")
    s.add_argument("--png", required=True, help="the figure of real against twin per zone, before and after (CSV beside it)")
    s.set_defaults(func=cmd_twin_calibrate)

    s = sub.add_parser("render-benchmark", help="twin renderers' time per scene against error to a converged reference")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--objects", type=_json, required=True, help="JSON list of the objects' sheet rows to draw scenes from")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "sizes": [...], "twin": {...}}')
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_render_benchmark)

    s = sub.add_parser("fig18", help="Fig 18: tracking frames, twin renders and real vs calibrated twin histograms of every zone")
    s.add_argument("scene", help="results/calibration/scene.json")
    s.add_argument("--sets", nargs="+", required=True, help="light-on 3x3 capture-set stores, one per row")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT stores, in the same order")
    s.add_argument("--twins", nargs="+", required=True, help="the matching calibrated twin stores (results/twin_calibrated/<object>_<size>.zarr)")
    s.add_argument("--calibration", required=True, help="results/twin_calibration.json: the zones' gains and the pulse")
    s.add_argument("--crop", required=True, help="results/features/crop_3x3.json: the features' first kept bin")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "variant": ..., "fig18": {...}}')
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_fig18)

    s = sub.add_parser("transforms", help="fit the sim-to-real transforms (scale, blur, noise) on the training captures' twins")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--twins", nargs="+", required=True, help="their objects' twin stores (results/twin/<object>_<size>.zarr)")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "fit": {...}}')
    s.add_argument("--out", required=True, help="output results/transforms.json")
    s.set_defaults(func=cmd_transforms)

    s = sub.add_parser("fig9", help="Fig 9: localisation RMSE on real captures against real samples added to simulated training data")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--twins", nargs="+", required=True, help="their objects' twin stores (results/twin/<object>_<size>.zarr)")
    s.add_argument("--positions", required=True, help="results/calibration/tag1_positions.parquet (location labels)")
    s.add_argument("--transforms", required=True, help="results/transforms.json")
    s.add_argument("--config", type=_json, required=True, help='JSON {"seed": ..., "fit": {...}}')
    s.add_argument("--hyper", type=_json, required=True, help='JSON {"lr", "epochs", "batch_size", "norm"} of the localiser')
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_fig9)

    s = sub.add_parser("evaluate", help="score a saved training cell on another dataset (e.g. the italic or non-RR sets)")
    s.add_argument("run", help="the cell's run folder (model.pt, metrics.json)")
    s.add_argument("dataset", help="datasets/<name>.zarr to score it on")
    s.add_argument("--table", required=True, help="datasets/<name>.parquet")
    s.add_argument("--out", required=True, help="output JSON: the cell's metrics and its baseline's on the dataset")
    s.set_defaults(func=cmd_evaluate)

    for name, what in (
        ("fig10", "Fig 10: non-RR objects' returns, and base 1D CNN cells scored on them"),
        ("fig11", "Fig 11: base 1D CNN cells scored on the italic objects"),
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

    s = sub.add_parser("tsne", help="Figs 13/14: t-SNE of shape cells' penultimate-layer embeddings and their separability")
    s.add_argument("runs", nargs="+", help="run folders of shape cells of one resolution (one per seed)")
    s.add_argument("--dataset", required=True, help="datasets/<res>.zarr the cells trained on")
    s.add_argument("--table", required=True, help="datasets/<res>.parquet")
    s.add_argument("--seed", type=int, required=True, help="the config seed: draws the classes, seeds t-SNE and the folds")
    s.add_argument("--title", required=True, help="figure title")
    s.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_tsne)
    s = sub.add_parser("jitter", help="the timing-jitter sweep: each task's metrics against the jitter's FWHM, from its cells")
    s.add_argument("runs", nargs="+", help="metrics.json of the jitter<FWHM>ps cells")
    s.add_argument("--out", required=True, help="PNG path; the table goes beside it as CSV")
    s.set_defaults(func=cmd_jitter)

    s = sub.add_parser("rig-examples", help="plot example histograms with the three-bounce bump marked")
    s.add_argument("--sets", nargs="+", required=True, help="object capture-set stores (<set>.zarr)")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT set stores, in the same order")
    s.add_argument("--out", required=True, help="PNG path; the plotted data goes beside it as CSV")
    s.set_defaults(func=cmd_rig_examples)

    s = sub.add_parser("rig-vs-real", help="measure raw centre-zone histograms against the real captures' figures")
    s.add_argument("--sets", nargs="+", required=True, help="3x3 object capture-set stores (<set>.zarr)")
    s.add_argument("--backgrounds", nargs="+", required=True, help="the matching NOOBJECT set stores, in the same order")
    s.add_argument("--png", required=True, help="the figure")
    s.add_argument("--csv", required=True, help="the measured numbers beside the real figures'")
    s.set_defaults(func=cmd_rig_vs_real)

    s = sub.add_parser("explore", help="browse the workflow's outputs in a web app: captures, histograms, twins, live predictions")
    s.add_argument("--results", default="results", help="the results folder to read (nothing is written to it)")
    s.add_argument("--host", default="127.0.0.1", help="address to serve on")
    s.add_argument("--port", type=int, default=8050, help="port to serve on")
    s.set_defaults(func=cmd_explore)
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
