"""`denali` verbs of the sim-to-real transforms (rules/fit.smk)."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from denali_pipe.cli.common import add_time_axis, json_arg, require_keys

log = logging.getLogger("denali")


def pairs_and_split(args: argparse.Namespace):
    """The sim-to-real pairs of --features and --twins and the real train/test split of --config."""
    from denali_pipe.transforms.sim_to_real import build_pairs, split_pairs

    require_keys(args.config, {"seed", "fit"})
    pairs = build_pairs([Path(p) for p in args.features], [Path(p) for p in args.twins])
    return pairs, split_pairs(pairs.keys, args.config["seed"], args.config["fit"]["test_fraction"])


def cmd_transforms(args: argparse.Namespace) -> None:
    import time

    from denali_pipe.transforms.sim_to_real import check_fit, choose_mode, fit_zone_transforms, write_transforms

    t0 = time.perf_counter()
    pairs, split = pairs_and_split(args)
    train = pairs.subset(split.train)
    fit = args.config["fit"]
    mode, residuals, rejected = choose_mode(train, args.config["seed"], fit["mode_validation_fraction"])
    for m, why in rejected.items():
        log.warning("transforms: mode %s rejected: %s", m, why)
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
        "mode_rejected": rejected,
        "n_pairs": int(len(split.train)),
        "n_test_pairs": int(len(split.test)),
        "repeats": int(pairs.real.shape[1]),
        "crop_start": pairs.crop_start,
        "bins": pairs.bins,
        "config": args.config,
        "seconds": t2 - t0,
        "bootstrap_seconds": t2 - t1,
    }
    write_transforms(Path(args.out), zt, checks, args.time_axis, record)
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


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("transforms", help="fit the sim-to-real transforms (scale, blur, noise) on the training captures' twins")
    s.add_argument("--features", nargs="+", required=True, help="3x3 light-on feature stores (results/features/<set>.zarr)")
    s.add_argument("--twins", nargs="+", required=True, help="their objects' twin stores (results/twin/<object>_<size>.zarr)")
    s.add_argument("--config", type=json_arg, required=True, help='JSON {"seed": ..., "fit": {...}}')
    add_time_axis(s)
    s.add_argument("--out", required=True, help="output results/transforms.json")
    s.set_defaults(func=cmd_transforms)
