#!/usr/bin/env python
"""How much an object's size changes the captures: the real sensor's
contrast between 4 in and 8 in objects beside the rig's. Prints a table,
writes nothing.

    python scripts/size_contrast.py                      # 300 scenes, a minute on one core
    python scripts/size_contrast.py --scenes 100 --seed 1 --stats DIR
    python scripts/size_contrast.py --terms               # and which response terms move it

Real: the release's log-input nets trained on the base objects at 4 in only,
at 8 in only and at both (`rig.feature_moments.SIZE_NETS`) carry in their
input transform the exact mean and std of log1p(counts) over their training
captures' zones and bins (the two halves pool into the third to 1e-5).
Their difference is the real captures' size contrast as a log-input network
meets it.

Rig: the same moments of paired captures made with the rig's functions,
single threaded: a random base object at a random gantry location at its
design pose (`rig.scene.design_scene`), once at each size, both lightings,
one noisy capture each under the config's photometry, no campaign
nuisances. Also printed: each zone's share of the rig's contrast, and the 4 in
object's own contrast over the mount alone, and the sd that the campaign's
set-to-set drifts (`rig.nuisances`: laser power, room light) give the real
contrast, pooled as the release pools it (one set per object, size and
lighting). With `--terms`, the contrast
again with one response term changed at a time (the light transport kept):
which of the rig's terms move it.

Cited by docs/rig_zones.md, "What the localisers read, and the held-out size".
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import yaml

from denali_pipe.core.geometry import N_LOCATIONS, TimeAxis
from denali_pipe.core.objects import load_catalogue
from denali_pipe.rig import feature_moments as fm
from denali_pipe.rig import histograms as H
from denali_pipe.rig.scene import design_scene

REPO = Path(__file__).resolve().parents[1]
STATS = REPO.parent / "shared" / "denali-assets" / "feature_stats"
# Scenes whose expected counts give the drift's derivatives (they vary little between scenes).
DRIFT_SCENES = 30


def paired_transports(catalogue: dict, phot: H.Photometry, n: int, seed: int) -> list[dict[str, H.Transport]]:
    """n random scenes, each as {"4inch", "8inch", "mount"} light transports:
    a base object at a gantry location at each size, and the mount alone."""
    rng = np.random.default_rng(seed)
    base = sorted(name for name, spec in catalogue.items() if spec.variant == "base")
    out = []
    for _ in range(n):
        obj, location = catalogue[base[rng.integers(len(base))]], int(rng.integers(N_LOCATIONS))
        scenes = {size: design_scene(obj, size, location) for size in ("4inch", "8inch")}
        scenes["mount"] = scenes["4inch"][:1]
        out.append({key: H.transport("3x3", scene, phot) for key, scene in scenes.items()})
    return out


def captures(transports: list[dict[str, H.Transport]], phot: H.Photometry, seed: int) -> dict[str, np.ndarray]:
    """{"4inch", "8inch", "mount": (2 n, 9, 128)}: both lightings, one noisy
    capture each; the three share every scene, lighting and noise seed."""
    out = {key: [] for key in transports[0]}
    for i, scene in enumerate(transports):
        for key, light in scene.items():
            for on in (False, True):
                expected = H.counts_from_transport("3x3", on, light, phot)
                out[key].append(H.sample_counts(expected, phot, np.random.default_rng((seed, i, on))).reshape(9, -1))
    return {key: np.asarray(v, float) for key, v in out.items()}


def contrast(hist: dict[str, np.ndarray]) -> tuple[float, float]:
    """(mean, std) of log1p(counts) at 8 in less at 4 in."""
    (m4, s4), (m8, s8) = fm.log_moments(hist["4inch"]), fm.log_moments(hist["8inch"])
    return m8 - m4, s8 - s4


def drift_sd(transports: list[dict[str, H.Transport]], phot: H.Photometry, nuisances: dict, n_sets: int) -> tuple[float, float]:
    """The sds of the size contrast's (mean, std) of log1p(counts) that
    set-to-set drift alone gives when each size and lighting pools `n_sets`
    sets: one sd of laser power and of room light per set, each set's first
    and second moments moved linearly (expected counts of the 4 in scenes)."""

    def moments(on: bool, power: float = 1.0, ambient: float = 1.0) -> np.ndarray:
        cond = H.Conditions(power, ambient, 0.0)
        logs = np.array([fm.log_counts(H.counts_from_transport("3x3", on, scene["4inch"], phot, cond)) for scene in transports])
        return np.array([logs.mean(), (logs**2).mean()])

    base = {on: moments(on) for on in (False, True)}
    m1, m2 = np.mean(list(base.values()), axis=0)
    sd = np.sqrt(m2 - m1**2)
    var = np.zeros(2)
    for on in (False, True):
        for step in ({"power": 1 + nuisances["power_drift"]}, {"ambient": 1 + nuisances["ambient_drift"]}):
            d1, d2 = moments(on, **step) - base[on]
            # a set's shift of the pooled (mean, std): std = sqrt(m2 - m1^2), linearised
            var += np.array([d1, (d2 - 2 * m1 * d1) / (2 * sd)]) ** 2
    # a size's pooled moments average its 2 n_sets sets (variance var / (4 n_sets)); the contrast differences two sizes
    return tuple(float(v) for v in np.sqrt(var / (2 * n_sets)))


def term_rows(phot: H.Photometry) -> dict[str, H.Photometry]:
    """The response terms changed one at a time (as scripts/rig_feature_terms.py)."""
    change = lambda **kw: dataclasses.replace(phot, **kw)  # noqa: E731
    return {
        "configured rig": phot,
        "floor: no dark counts": change(dark_counts=0.0),
        "floor: no room light": change(ambient_counts=0.0),
        "floor: room light x2": change(ambient_counts=2 * phot.ambient_counts),
        "floor: no slow tail": change(slow_tail_fraction=0.0),
        "direct: flux x2": change(direct_peak_counts=2 * phot.direct_peak_counts),
        "direct: no saturation": change(saturation_counts=1e12),
        "direct: no dead time": change(dead_time_counts=1e15),
        "receiver: no glare": change(glare_share=0.0),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--stats", type=Path, default=STATS, help="the release's feature statistics folder")
    ap.add_argument("--scenes", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--terms", action="store_true", help="also the contrast with each response term changed")
    args = ap.parse_args()
    with open(args.config) as f:
        config = yaml.safe_load(f)
    rig_config = config["rig"]
    phot = H.Photometry.from_config(rig_config["photometry"], TimeAxis.from_config(config["sensor"]["time_axis"]))
    catalogue = load_catalogue(REPO / "config" / "objects.tsv")
    real = fm.real_log_moments_by_size(fm.load_backbones(args.stats))
    transports = paired_transports(catalogue, phot, args.scenes, args.seed)
    hist = captures(transports, phot, args.seed)
    logs = {key: fm.log_counts(h) for key, h in hist.items()}
    rig = {key: (float(v.mean()), float(v.std())) for key, v in logs.items()}
    # each scene's contrast, for the standard error over scenes
    per_scene = logs["8inch"].mean(axis=(1, 2)) - logs["4inch"].mean(axis=(1, 2))
    se = per_scene.std(ddof=1) / np.sqrt(len(per_scene))

    print(f"log1p(counts) over every zone and bin; rig: {args.scenes} paired scenes x 2 lightings")
    print(f"{'':8s}{'real mean':>12s}{'real std':>12s}{'rig mean':>12s}{'rig std':>12s}")
    for size in ("4inch", "8inch"):
        print(f"{size:8s}{real[size][0]:12.5f}{real[size][1]:12.5f}{rig[size][0]:12.5f}{rig[size][1]:12.5f}")
    d_real = [real["8inch"][i] - real["4inch"][i] for i in (0, 1)]
    d_rig = [rig["8inch"][i] - rig["4inch"][i] for i in (0, 1)]
    print(f"{'8 - 4 in':8s}{d_real[0]:+12.5f}{d_real[1]:+12.5f}{d_rig[0]:+12.5f}{d_rig[1]:+12.5f}   (rig mean's SE over scenes {se:.5f})")
    print(f"rig contrast over real: mean {d_rig[0] / d_real[0]:.2f}x, std {d_rig[1] / d_real[1]:.2f}x")
    n_sets = sum(spec.variant == "base" for spec in catalogue.values())
    sd = drift_sd(transports[:DRIFT_SCENES], phot, rig_config["nuisances"], n_sets)
    print(
        f"the real contrast's sd from set-to-set drift ({n_sets} sets per size and lighting): mean {sd[0]:.5f}, std {sd[1]:.5f};"
        f" rig - real = {(d_rig[0] - d_real[0]) / sd[0]:.1f} and {(d_rig[1] - d_real[1]) / sd[1]:.1f} sd"
    )
    by_zone = (logs["8inch"] - logs["4inch"]).mean(axis=(0, 2))
    own = (logs["4inch"] - logs["mount"]).mean(axis=(0, 2))
    print("rig, each zone's mean log1p, 8 - 4 in (rows as the captures store them): " + " ".join(f"{v:+.4f}" for v in by_zone))
    print("rig, each zone's mean log1p, 4 in object - mount alone:                  " + " ".join(f"{v:+.4f}" for v in own))
    if args.terms:
        print(f"\n{'one term changed':28s}{'mean 8 - 4 in':>15s}{'std 8 - 4 in':>15s}   (real {d_real[0]:+.5f}, {d_real[1]:+.5f})")
        for name, changed in term_rows(phot).items():
            d = contrast(captures([{size: scene[size] for size in ("4inch", "8inch")} for scene in transports], changed, args.seed))
            print(f"{name:28s}{d[0]:+15.5f}{d[1]:+15.5f}", flush=True)


if __name__ == "__main__":
    main()
