#!/usr/bin/env python
"""Which physical term of the rig moves which feature statistic (REFERENCE
Part 7); prints a table, writes nothing.

    python scripts/rig_feature_terms.py                        # 120 scenes x 2 lightings x 2 repeats
    python scripts/rig_feature_terms.py --scenes 60 --stats DIR

Captures made directly with the rig's functions (`rig.histograms`), single
threaded: random base objects, sizes and gantry locations at their design
pose (`rig.scene.design_scene`), both lightings, a few noisy repeats each,
under the config's photometry; no campaign nuisances unless a row says so.
Each row changes one term and keeps the rest (the light transport is shared):

- the floor per zone: dark counts, room light, the laser's slow tail;
- the direct return's height and width: the flux, the pulse's fast part,
  the combiner's saturation, the SPADs' dead time;
- the receiver's glare (none);
- the object's bump (the mount alone);
- the noise between repeats: none (expected counts), or the campaign's
  nuisances drawn per capture (laser power, room light, clock offset:
  `rig.nuisances.*` sds).

Columns: the feature-moment distance averaged over the 18 release nets and
3 layers, per layer, the raw-count and log-input nets' layer-1 median signed
log variance ratio (below 0: less variance than the real), the largest and
the centre zone's z mean offset from Part 7's, and the worst and centre zone
mean's error against Part 5's. Then, for the configured rig, where in time
its moments leave the real ones (`feature_moments.time_profile`: per layer
and 16-bin block, the median over channels of E[(y - running_mean)^2] /
running_var, the median over each kind of net; the real data average ~1).
A few minutes on one core.

Cited by docs/rig_zones.md, "The feature statistics".
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import yaml

from denali_pipe.core.geometry import N_LOCATIONS, TimeAxis
from denali_pipe.core.objects import load_catalogue
from denali_pipe.report.paper import REAL_LOG_ZONE_MEANS, REAL_ZONE_MEANS
from denali_pipe.rig import feature_moments as fm
from denali_pipe.rig import histograms as H
from denali_pipe.rig.scene import design_scene

REPO = Path(__file__).resolve().parents[1]
STATS = REPO.parent / "shared" / "denali-assets" / "feature_stats"
SIZES = ("4inch", "8inch")


def scenes(catalogue: dict, phot: H.Photometry, n: int, seed: int) -> list[tuple[H.Transport, H.Transport]]:
    """n random (object + mount, mount alone) transports at design poses."""
    rng = np.random.default_rng(seed)
    base = sorted(name for name, spec in catalogue.items() if spec.variant == "base")
    out = []
    for _ in range(n):
        scene = design_scene(catalogue[base[rng.integers(len(base))]], SIZES[rng.integers(2)], int(rng.integers(N_LOCATIONS)))
        out.append((H.transport("3x3", scene, phot), H.transport("3x3", scene[:1], phot)))
    return out


def captures(lights, phot: H.Photometry, repeats: int, seed: int, noise: str = "poisson", nuisances: dict | None = None, bump: bool = True) -> np.ndarray:
    """(scenes x 2 lightings x repeats, 9, 128) histograms; noise `poisson`
    (shot and read noise) or `none` (expected counts); `nuisances` draws each
    capture's laser power, room light and clock offset."""
    rng = np.random.default_rng(seed)
    out = []
    for with_object, mount in lights:
        light = with_object if bump else mount
        for on in (False, True):
            for _ in range(repeats):
                cond = H.Conditions()
                if nuisances is not None:
                    p, a, t = rng.standard_normal(3)
                    cond = H.Conditions(1 + nuisances["power_drift"] * p, 1 + nuisances["ambient_drift"] * a, nuisances["timing_drift_bins"] * t)
                expected = H.counts_from_transport("3x3", on, light, phot, cond)
                h = expected if noise == "none" else H.sample_counts(expected, phot, rng)
                out.append(h.reshape(9, -1))
    return np.asarray(out, float)


def yardsticks(hist: np.ndarray, nets: list[fm.Backbone]) -> dict:
    table = fm.feature_distances(nets, hist)
    s = fm.summary(table)
    l1 = table[table.layer == 1].groupby("input").var_log_ratio.median()
    dz = fm.log_zone_means(hist) - np.ravel(REAL_LOG_ZONE_MEANS)
    err = hist.mean(axis=(0, 2)) / np.ravel(REAL_ZONE_MEANS) - 1
    return {
        "distance": s["distance"],
        "L1": s["layer 1"],
        "L2": s["layer 2"],
        "L3": s["layer 3"],
        "raw L1 logvar": l1["raw"],
        "log L1 logvar": l1["log_z"],
        "max |dz|": np.abs(dz).max(),
        "centre dz": dz[4],
        "worst zone %": 100 * err[np.argmax(np.abs(err))],
        "centre %": 100 * err[4],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--stats", type=Path, default=STATS, help="the release's feature statistics folder")
    ap.add_argument("--scenes", type=int, default=120)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    with open(args.config) as f:
        config = yaml.safe_load(f)
    rig = config["rig"]
    phot = H.Photometry.from_config(rig["photometry"], TimeAxis.from_config(config["sensor"]["time_axis"]))
    nets = fm.load_backbones(args.stats)
    lights = scenes(load_catalogue(REPO / "config" / "objects.tsv"), phot, args.scenes, args.seed)
    change = lambda **kw: dataclasses.replace(phot, **kw)  # noqa: E731
    rows = {
        "configured rig": {},
        "floor: no dark counts": {"phot": change(dark_counts=0.0)},
        "floor: no room light": {"phot": change(ambient_counts=0.0)},
        "floor: dark counts x2": {"phot": change(dark_counts=2 * phot.dark_counts)},
        "floor: no slow tail": {"phot": change(slow_tail_fraction=0.0)},
        "floor: slow tail x2 longer": {"phot": change(slow_tail_bins=2 * phot.slow_tail_bins)},
        "direct: flux x2": {"phot": change(direct_peak_counts=2 * phot.direct_peak_counts)},
        "direct: pulse fast part x2": {"phot": change(pulse_sigma_bins=2 * phot.pulse_sigma_bins, pulse_tail_bins=2 * phot.pulse_tail_bins)},
        "direct: no saturation": {"phot": change(saturation_counts=1e12)},
        "direct: saturation x2": {"phot": change(saturation_counts=2 * phot.saturation_counts)},
        "direct: no dead time": {"phot": change(dead_time_counts=1e15)},
        "receiver: no glare": {"phot": change(glare_share=0.0)},
        "bump: no object (mount only)": {"bump": False},
        "repeats: no noise (expected)": {"noise": "none"},
        "repeats: campaign nuisances per capture": {"nuisances": rig["nuisances"]},
    }
    n = args.scenes * 2 * args.repeats
    print(f"{n} captures: {args.scenes} scenes x 2 lightings x {args.repeats} repeats; real: distance 0, log-var 0, dz 0, zone % 0")
    header = None
    for name, kw in rows.items():
        hist = captures(lights, kw.pop("phot", phot), args.repeats, args.seed + 1, **kw)
        y = yardsticks(hist, nets)
        if header is None:
            header = f"{'':42s}" + "".join(f"{k:>15s}" for k in y)
            print(header)
        print(f"{name:42s}" + "".join(f"{v:15.2f}" for v in y.values()), flush=True)
    hist = captures(lights, phot, args.repeats, args.seed + 1)
    print("\nconfigured rig, per 16-bin block: median channel's E[(y - running_mean)^2] / running_var (real ~1)")
    for kind in ("raw", "log_z"):
        profile = np.median([fm.time_profile(net, hist) for net in nets if net.input == kind], axis=0)
        for layer, p in zip(fm.LAYERS, profile):
            blocks = p.reshape(-1, 16).mean(1)
            print(f"  {kind:5s} nets, layer {layer}: " + " ".join(f"{v:7.1f}" for v in blocks))


if __name__ == "__main__":
    main()
