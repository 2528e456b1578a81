"""`denali` verb of the sensor's fit to real captures (rules/sensor.smk)."""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

log = logging.getLogger("denali")


def cmd_sensor_fit(args: argparse.Namespace) -> None:
    from denali_pipe.core.atomic import atomic_file
    from denali_pipe.report.sensor_fit import write_absent, write_sensor_fit
    from denali_pipe.sensor.captures import SWEEP, read_captures
    from denali_pipe.sensor.fit import fit_sweep, held_out_scores, predict, record, split_sweep

    source, out = Path(args.real_dir), Path(args.out)
    if not (source / SWEEP).is_file():
        log.warning("%s: no %s; the sensor is not fitted", source, SWEEP)
        body = {"source": str(source), "status": f"no real captures: {source / SWEEP} not found"}
        write_absent(source, out.with_suffix(".png"))
    else:
        sweep = read_captures(source / SWEEP)
        fit = fit_sweep(sweep, args.held_out_every, args.min_distance_m, args.rounds)
        _, test = split_sweep(sweep, args.held_out_every, args.min_distance_m)
        held = held_out_scores(fit, test)
        examples = test.select([0, -1])  # the nearest and the farthest held-out plane
        write_sensor_fit(fit, held, examples, predict(fit, examples)[0], out.with_suffix(".png"))
        body = record(fit, held, str(source))
        log.info("held-out scores per zone:\n%s", held.to_string(index=False))
    with atomic_file(out) as tmp:
        tmp.write_text(json.dumps(body, indent=1) + "\n")
    log.info("wrote %s (%s)", out, body["status"])


def cmd_sensor_vs_real(args: argparse.Namespace) -> None:
    import pandas as pd

    from denali_pipe.experiments.sensor_vs_real import compare_scene, read_mesh
    from denali_pipe.report.sensor_vs_real import write_absent, write_sensor_vs_real
    from denali_pipe.sensor.captures import SWEEP, read_captures
    from denali_pipe.sensor.fit import from_record

    source, out = Path(args.real_dir), Path(args.out)
    body = json.loads(Path(args.fit).read_text())
    scenes = sorted(p for p in source.glob("*.npz") if p.name != SWEEP) if source.is_dir() else []
    rows, rendered = [], []
    if body.get("status") != "fitted":
        reason = f"no fitted sensor ({args.fit}: {body.get('status')})"
    elif not scenes:
        reason = f"no scenes: no .npz beside {SWEEP} in {source}"
    else:
        fit = from_record(body)
        for npz in scenes:
            stl = npz.with_suffix(".stl")
            if not stl.is_file():
                rows.append(pd.DataFrame({"scene": [npz.stem], "status": [f"not rendered: no mesh {stl.name}"]}))
                continue
            captures = read_captures(npz)
            table, expected = compare_scene(fit, captures, read_mesh(stl))
            rows.append(table.assign(status="rendered"))
            rendered.append((captures, expected))
            log.info("%s:\n%s", npz.stem, table.to_string(index=False))
        reason = f"no scene in {source} has its mesh (<scene>.stl)"
    table = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame({"scene": [], "status": []})
    table = table[[c for c in table.columns if c != "status"] + ["status"]]
    if rendered:
        write_sensor_vs_real(rendered, table, out.with_suffix(".png"))
    else:
        log.warning("%s; no scene rendered", reason)
        write_absent(reason, table if rows else pd.DataFrame({"status": [reason]}), out.with_suffix(".png"))
    log.info("wrote %s", out)


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("sensor-fit", help="the TMF882x's pulse, timing, pile-up and crosstalk fitted to a real distance sweep")
    s.add_argument("real_dir", help="folder of real captures (config sensor.real_dir); absent, the output says so")
    s.add_argument("--held-out-every", type=int, required=True, help="every n-th distance is held out for the test")
    s.add_argument("--min-distance-m", type=float, required=True, help="captures nearer than this are left out")
    s.add_argument("--rounds", type=int, required=True, help="the fit's alternations")
    s.add_argument("--out", required=True, help="results/sensor_fit.json; the figure and its CSV go beside it")
    s.set_defaults(func=cmd_sensor_fit)
    s = sub.add_parser("sensor-vs-real", help="the fitted sensor on real scenes it was not fitted to: each capture rendered from its mesh and pose")
    s.add_argument("real_dir", help="folder of real captures (config sensor.real_dir): every <scene>.npz with its <scene>.stl")
    s.add_argument("--fit", required=True, help="results/sensor_fit.json")
    s.add_argument("--out", required=True, help="results/sensor_vs_real.csv; the figure goes beside it")
    s.set_defaults(func=cmd_sensor_vs_real)
