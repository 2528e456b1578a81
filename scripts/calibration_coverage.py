#!/usr/bin/env python
"""Coverage of the twin calibration's intervals over repeated plantings.
Prints figures, asserts nothing.

    python scripts/calibration_coverage.py [--plantings 10] [--noise 0.01]

Each planting: a scene off the design drawing (`layout.perturbed_scene`,
the sensor and every object pose moved and turned, its own seed), 12
gantry locations drawn at random, two objects (A 8 in, circle 4 in), and
parameters drawn at random under the flood (`draw_truth`: footprints within
+-1.5 cm and 0.9-1.15x, a time offset, a SPAD pulse, a diffuse share of
0.05-0.5, the flood's half widths of 4-15 deg, as narrow as the demo's fit,
a core of 5-90 % of the on-axis intensity and 1-8 deg, and a receiver glare
of 0.5-10 %);
captures the twin renders there with Gaussian noise (`calibrate.planted_captures`,
`--noise` of the brightest bin); the calibration (`calibrate.calibrate`,
starting from the design twin, 26 x 20.5 deg and an even split at 5 deg) run on them. Printed: the
share of coordinates whose interval (`twin.calibration.level`, 90 %) holds
the truth, over all of them, over those not flagged `not_identified`, and
per group (zone footprints; globals: time offset, pulse, share, widths,
glare), and
how many were flagged. The calibration's settings are the tests' (film 2,
10 samples across the object): ~10 CPU-s a planting.

Cited by docs/twin.md, "Calibration" (recovery and coverage).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core.geometry import PAPER_TIME_AXIS
from denali_pipe.core.objects import load_catalogue
from denali_pipe.twin import calibrate as C
from denali_pipe.twin.layout import load_calibration, perturbed_scene

REPO = Path(__file__).resolve().parents[1]
OBJECTS = (("A", "8inch"), ("circle", "4inch"))
SETTINGS = {
    "wall_albedo": 1.0, "object_albedo": 0.5, "table": False, "table_albedo": 0.5,
    "material": "retroreflective", "retroreflective": {"lobe_width_deg": 10.0, "diffuse_share": 0.3},
    "footprint": {"film": 8, "scale": 1.0},
    "illumination": "flood", "flood": {"grid": 2, "beam_hwhm_deg": [26.0, 20.5], "core_share": 0.5, "core_hwhm_deg": 5.0},
    "calibration": {
        "film": 2, "samples": 10, "validation_fraction": 0.2, "max_captures": 0,
        "bootstrap_resamples": 100, "level": 0.9, "max_evaluations": 200,
        "pulse": {"sigma_bins": 1.0, "tail_bins": 1.0}, "glare_share": 0.02,
    },
}  # fmt: skip
CROP, BINS, REPEATS = 60, 60, 3
# Any axis will do: the captures are planted through the same model.
AXIS = PAPER_TIME_AXIS


def draw_truth(rng: np.random.Generator) -> np.ndarray:
    """Fit coordinates (`calibrate.tail_names` of SETTINGS after the zones')."""
    x = C.initial(SETTINGS)
    x[: 2 * C.ZONES] = rng.uniform(-1.5, 1.5, 2 * C.ZONES)  # cm
    x[2 * C.ZONES : 3 * C.ZONES] = np.log(rng.uniform(0.9, 1.15, C.ZONES))
    share = rng.uniform(0.05, 0.5)
    tail = [rng.uniform(-2, 2), np.log(rng.uniform(0.5, 1.2)), np.log(rng.uniform(1.0, 3.0)), np.log(share / (1 - share))]
    glare = rng.uniform(0.005, 0.1)
    core = rng.uniform(0.05, 0.9)
    emission = [*np.log(rng.uniform(4.0, 15.0, 2)), np.log(core / (1 - core)), np.log(rng.uniform(1.0, 8.0))]
    x[3 * C.ZONES :] = tail + emission + [np.log(glare / (1 - glare))]
    return x


def coordinates(phys: dict) -> dict:
    """{coordinate name (`calibrate.coordinate_names`): value} of `to_physical`'s dict, or of its intervals (values (2,))."""
    out = {}
    for k, v in phys.items():
        v = np.asarray(v, float)
        if k in ("offset_u", "offset_v", "scale"):
            for r, c in np.ndindex(C.GRID, C.GRID):
                out[f"{k}[{r}, {c}]"] = v[r, c]
        else:
            out[k] = v
    return out


def planting(seed: int, noise: float, catalogue: dict, workdir: Path) -> pd.DataFrame:
    """One planting's coordinates: name, truth, estimate, low, high, covered, flagged."""
    rng = np.random.default_rng(seed)
    locations = sorted(rng.choice(100, 12, replace=False).tolist())
    path = workdir / f"scene{seed}.json"
    path.write_text(json.dumps(perturbed_scene(locations, seed)))
    cal = load_calibration(path)
    specs = {name: catalogue[name] for name, _ in OBJECTS}
    keys = pd.DataFrame([(f"{o}_{s}_3x3_lighton", o, s, loc) for o, s in OBJECTS for loc in locations], columns=["set", "object", "size", "location"])
    dummy = C.Captures(np.zeros((len(keys), REPEATS, C.GRID, C.GRID, BINS), np.float32), keys, CROP)
    problem = C.Problem(C.Model(cal, specs, keys, SETTINGS, AXIS), dummy, SETTINGS)
    truth = draw_truth(rng)
    m = problem.twins(truth)
    gains = rng.uniform(0.5, 2, C.ZONES) * 1e3 / m.max()
    peak = float((gains[None, :, None] * m).max())
    captures = C.planted_captures(problem, truth, gains, noise * peak, REPEATS, rng)
    result, _, _ = C.calibrate(cal, specs, captures, SETTINGS, AXIS, seed)
    want, got = coordinates(C.to_physical(truth, SETTINGS)), coordinates(C.to_physical(result.x, SETTINGS))
    interval = coordinates(result.interval)
    rows = []
    for name in C.coordinate_names(SETTINGS):
        lo, hi = interval[name]
        rows.append({
            "planting": seed, "name": name, "truth": float(want[name]), "estimate": float(got[name]), "low": lo, "high": hi,
            "covered": bool(lo <= want[name] <= hi), "flagged": name in result.not_identified,
            "group": "footprint" if "[" in name else "global", "converged": result.fit["converged"],
        })  # fmt: skip
    return pd.DataFrame(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plantings", type=int, default=10)
    ap.add_argument("--noise", type=float, default=0.01, help="noise sd per repeat and bin, as a share of the brightest bin")
    ap.add_argument("--seed", type=int, default=0, help="the first planting's seed; the others follow it")
    args = ap.parse_args()
    catalogue = load_catalogue(REPO / "config" / "objects.tsv")
    frames = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seed, args.seed + args.plantings):
            t0 = time.process_time()
            f = planting(seed, args.noise, catalogue, Path(tmp))
            frames.append(f)
            ok = f[~f["flagged"]]
            print(
                f"planting {seed}: {f['covered'].mean():.0%} covered ({ok['covered'].mean():.0%} of the {len(ok)} identified), "
                f"flagged {f.loc[f['flagged'], 'name'].tolist()}, converged {bool(f['converged'].iloc[0])}, {time.process_time() - t0:.0f} CPU-s",
                flush=True,
            )
    df = pd.concat(frames, ignore_index=True)
    level = SETTINGS["calibration"]["level"]
    print(f"\n{args.plantings} plantings, noise {args.noise:.1%} of the peak, {level:.0%} intervals:")
    print(f"  all coordinates: {df['covered'].mean():.1%} of {len(df)} hold the truth")
    ok = df[~df["flagged"]]
    print(f"  identified (not flagged): {ok['covered'].mean():.1%} of {len(ok)}; flagged: {int(df['flagged'].sum())}")
    for group, g in ok.groupby("group"):
        print(f"  identified {group}s: {g['covered'].mean():.1%} of {len(g)}")
    for name, g in ok[ok["group"] == "global"].groupby("name", sort=False):
        print(f"    {name}: {g['covered'].mean():.0%} of {len(g)}")


if __name__ == "__main__":
    main()
