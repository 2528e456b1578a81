#!/usr/bin/env python
"""Per-zone three-bounce matched-filter SNR of one capture at 3x3 and 8x8;
prints figures, asserts nothing.

    python scripts/bench_snr.py                      # the config's rig
    python scripts/bench_snr.py --objects A 1 --locations 5 45 94

For each object (8 in), gantry location and lighting: the expected capture
and NOOBJECT background of the configured rig (no nuisances), the object's
signal = capture - background, and each zone's matched-filter SNR against
the capture's Poisson and read noise (`rig.measure.matched_filter_snr`).
Printed per zone: the median over scenes, and each zone's photon budget
(mean counts per bin of the capture, lights off); and the whole capture's
SNR (every zone's matched filter together, root sum of squares).

Cited by docs/rig_zones.md, "The 8x8 mode".
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from denali_pipe.core import geometry as geo
from denali_pipe.core.objects import load_catalogue
from denali_pipe.rig import histograms as H
from denali_pipe.rig.measure import matched_filter_snr
from denali_pipe.rig.scene import mount_scatterer, object_scatterer

REPO = Path(__file__).resolve().parents[1]


def zone_grid(values: np.ndarray, fmt: str) -> str:
    return "\n".join("    " + " ".join(format(v, fmt) for v in row) for row in values)


def bench(resolution: str, objects: list[str], locations: list[int], phot: H.Photometry, catalogue: dict) -> None:
    snr, budget = [], []
    for k in locations:
        mount = [mount_scatterer(geo.object_pose(k).t)]
        bg_light = H.transport(resolution, mount, phot)
        for name in objects:
            light = H.transport(resolution, mount + [object_scatterer(catalogue[name], "8inch", geo.object_pose(k))], phot)
            for on in (True, False):
                capture = H.counts_from_transport(resolution, on, light, phot)
                signal = capture - H.counts_from_transport(resolution, on, bg_light, phot)
                snr.append(matched_filter_snr(signal, capture, phot.read_noise_counts))
                if not on:
                    budget.append(capture.mean(-1))
    whole = np.median([np.sqrt((z**2).sum()) for z in snr])  # all zones' matched filters together
    snr, budget = np.median(snr, 0), np.mean(budget, 0)
    sub = geo.zone_subcapture(resolution).reshape(snr.shape)
    print(f"{resolution}: three-bounce matched-filter SNR per zone (median over {len(locations)} locations x {len(objects)} objects x 2 lightings)")
    print(zone_grid(snr, "6.1f"))
    print(f"  min {snr.min():.1f}, median {np.median(snr):.1f}, max {snr.max():.1f}; all zones together {whole:.1f}")
    print("  mean counts per bin per zone (lights off):")
    print(zone_grid(budget, "7.0f"))
    if sub.max() > 0:
        print("  median SNR per subcapture: " + ", ".join(f"{s}: {np.median(snr[sub == s]):.1f}" for s in range(sub.max() + 1)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--objects", nargs="+", default=["A", "1", "square"])
    ap.add_argument("--locations", nargs="+", type=int, default=[5, 45, 94])
    args = ap.parse_args()
    with open(args.config) as f:
        config = yaml.safe_load(f)
    phot = H.Photometry.from_config(config["rig"]["photometry"], geo.TimeAxis.from_config(config["sensor"]["time_axis"]))
    catalogue = load_catalogue(REPO / "config" / "objects.tsv")
    for resolution in geo.RESOLUTIONS:
        bench(resolution, args.objects, args.locations, phot, catalogue)


if __name__ == "__main__":
    main()
