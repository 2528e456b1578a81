#!/usr/bin/env python
"""The rig's 3x3 photometry against the real sensor's; prints figures,
asserts nothing.

    python scripts/bench_zones.py                 # the config's rig
    python scripts/bench_zones.py --config other.yaml

Expected counts (no nuisances) over 5 gantry locations x 3 objects (A,
square, 1) x 2 sizes x 2 lightings: every zone's mean counts per bin beside
the real sensor's (docs/rig_zones.md), the centre/edge, centre/corner and right/left ratios, the
pooled log1p(counts) mean and spread of one noisy draw each (real 7.1, 0.78),
and Part 4's centre-zone checks on the 8 in square at location 45, lights
off: (b) floor / direct peak and late / pre-peak floor on the background,
(c) the bump's excess over the peak and over the floor and its per-bin SNR in
one noisy capture, and the bump's FWHM (expected counts).

Cited by docs/rig_zones.md, "Every zone's photometry".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from denali_pipe.core.geometry import TimeAxis
from denali_pipe.core.objects import load_catalogue
from denali_pipe.report.paper import REAL_ZONE_MEANS
from denali_pipe.report.rig_vs_real import REAL_LOG_SPREAD, zone_pattern
from denali_pipe.rig import histograms as H
from denali_pipe.rig.measure import measure
from denali_pipe.rig.scene import design_scene

REPO = Path(__file__).resolve().parents[1]
LOCATIONS = (5, 27, 45, 72, 94)
OBJECTS = ("A", "square", "1")
MID = 45


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    args = ap.parse_args()
    with open(args.config) as f:
        config = yaml.safe_load(f)
    phot = H.Photometry.from_config(config["rig"]["photometry"], TimeAxis.from_config(config["sensor"]["time_axis"]))
    catalogue = load_catalogue(REPO / "config" / "objects.tsv")

    rng = np.random.default_rng(0)
    means, logs = [], []
    for k in LOCATIONS:
        for name in OBJECTS:
            for size in ("8inch", "4inch"):
                light = H.transport("3x3", design_scene(catalogue[name], size, k), phot)
                for on in (True, False):
                    expected = H.counts_from_transport("3x3", on, light, phot)
                    means.append(expected.mean(-1))
                    logs.append(np.log1p(H.sample_counts(expected, phot, rng)))
    m, real = np.mean(means, 0), np.asarray(REAL_ZONE_MEANS)
    print("mean counts per bin per zone (rig / real, error):")
    for r in range(3):
        print("   " + "   ".join(f"{m[r, c]:6.0f} / {real[r, c]:4.0f} ({100 * (m[r, c] / real[r, c] - 1):+4.0f} %)" for c in range(3)))
    rig, ref = zone_pattern(m), zone_pattern(real)
    print("   " + "; ".join(f"{key} {rig[key]:.2f} (real {ref[key]:.2f})" for key in rig))
    print(f"pooled log1p(counts): mean {np.mean(logs):.2f} (real 7.1), sd {np.std(logs):.2f} (real {REAL_LOG_SPREAD})")

    square = design_scene(catalogue["square"], "8inch", MID)
    background = H.expected_counts("3x3", False, square[:1], phot)[1, 1]
    b = measure(background, background)
    expected = H.expected_counts("3x3", False, square, phot)[1, 1]
    capture = H.sample_counts(expected, phot, np.random.default_rng(1))
    c, e = measure(capture, background), measure(expected, background)
    print(f"(b) floor {100 * b.floor_fraction:.1f} % of the direct peak ({b.direct_peak:,.0f}); late / pre-peak floor {b.late_over_floor:.2f}")
    print(
        f"(c) 8 in square: bump {100 * c.bump_fraction:.1f} % of the peak, {c.bump_over_floor:.2f}x the floor, "
        f"per-bin SNR {c.bump_excess / np.sqrt(capture[c.bump_bin]):.0f}; FWHM {e.bump_fwhm:.1f} bins at bin {e.bump_bin}"
    )


if __name__ == "__main__":
    main()
