#!/usr/bin/env python
"""What DENALI's release shows of its own sensor, held against the sensor
fitted to the real TMF8820 sweep (docs/sensor.md, "The bin width on
DENALI's own evidence" and "Pile-up at DENALI's settings"); prints, writes
nothing.

    python scripts/denali_sensor_evidence.py --fit results/sensor_fit.json

The time axis: each zone's direct wall return in the release's plotted
real capture (`capture_setup.png`, read as scripts/read_figure_zones.py
reads it: each panel's highest bar; and as docs/rig_zones.md reads it: a
double-peaked zone's own later peak) against the zone's wall path in the
release's scene (the rig's pulse-free wall transport): for each bin width,
the zero bin that fits and the residual; and the width a free slope gives.

Pile-up: under the first-photon law with N cycles, a histogram of C
counts leaves its late floor at 1 - C / N of its floor before the return
(the floor's own share neglected). The release's zone means (REFERENCE
Part 5: C = 128 x the mean) and the figure's late floors (Part 4) give the
N each zone needs, against the sweep's cycles per iteration scaled to
DENALI's 10,000 kilo-iterations.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml
from read_figure_zones import FIGURE, REPO, panels
from scipy.stats import linregress

from denali_pipe.core import geometry as geo
from denali_pipe.report.paper import REAL_FIGURE_ZONES, REAL_ZONE_MEANS
from denali_pipe.rig import histograms as H

WIDTHS_PS = (78.2, 92.0, 93.0, 100.0)
# docs/rig_zones.md, "The captures' column order": each zone's own direct peak, zones in the captures' order
DOCS_PEAKS = np.array([60, 55, 52, 61, 55, 53, 61, 58, 54])
SWEEP_KILO_ITERATIONS, DENALI_KILO_ITERATIONS = 4_000, 10_000


def wall_paths(config: Path) -> np.ndarray:
    """(9,) each 3x3 zone's optical path (m) at its pulse-free wall return's peak (sub-bin, parabola)."""
    # drawn on the paper's axis: any axis gives the same paths; this one starts at zero path
    with open(config) as f:
        phot = H.Photometry.from_config(yaml.safe_load(f)["rig"]["photometry"], geo.PAPER_TIME_AXIS)
    wall = H.transport("3x3", [], phot).hist.reshape(9, -1)
    b = wall.argmax(-1)
    y0, y1, y2 = (wall[np.arange(9), b + j] for j in (-1, 0, 1))
    peak = b + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)
    return (peak + 0.5) * geo.PAPER_TIME_AXIS.bin_width_opl + geo.PAPER_TIME_AXIS.start_opl  # the bin's centre


def time_axis(opl: np.ndarray, peaks: np.ndarray, name: str) -> None:
    print(f"direct peaks as {name}: {peaks.tolist()}")
    for ps in WIDTHS_PS:
        position = opl / (ps * 1e-12 * geo.SPEED_OF_LIGHT)
        zero = np.mean(peaks - position)
        residual = peaks - zero - position
        spread = position.reshape(3, 3).mean(0)
        real = peaks.reshape(3, 3).mean(0)
        print(f"  {ps:5.1f} ps: zero distance peaks at bin {zero:5.2f}; residual sd {residual.std(ddof=2):.2f} bins; "
              f"far minus near column {spread[0] - spread[2]:.1f} bins (real {real[0] - real[2]:.1f})")  # fmt: skip
    fit = linregress(opl, peaks)
    ps = lambda slope: 1e12 / (slope * geo.SPEED_OF_LIGHT)  # noqa: E731
    print(f"  free slope: {ps(fit.slope):.0f} ps a bin ({ps(fit.slope + 2 * fit.stderr):.0f}-{ps(fit.slope - 2 * fit.stderr):.0f} at two standard errors)")


def pile_up(cycles_per_iteration: float) -> None:
    counts = 128 * np.asarray(REAL_ZONE_MEANS, float).ravel()
    late = np.asarray(REAL_FIGURE_ZONES["late_over_floor"], float)
    n = cycles_per_iteration * DENALI_KILO_ITERATIONS * 1000
    print(f"pile-up: the sweep's {cycles_per_iteration:.3f} cycles an iteration at {DENALI_KILO_ITERATIONS:,} kilo-iterations: N = {n / 1e6:.2f} M cycles")
    print(f"  counts a histogram (k):      {np.round(counts / 1e3).astype(int).tolist()}")
    print(f"  late / early floor, figure:  {late.tolist()}")
    print(f"  ... the law at N:            {np.round(1 - counts / n, 3).tolist()}")
    measurable = late < 0.9
    print(f"  N that each zone with a drop (< 0.9) needs, M cycles: {np.round(counts[measurable] / (1 - late[measurable]) / 1e6, 2).tolist()}")
    for scale in (8, 9):
        print(f"  ... the law at N with the counts {scale}x the release's: {np.round(1 - scale * counts / n, 2).tolist()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", type=Path, default=REPO / "results" / "sensor_fit.json", help="the sensor fitted to the real sweep (rule sensor_fit)")
    ap.add_argument("--figure", type=Path, default=FIGURE)
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    args = ap.parse_args()
    opl = wall_paths(args.config)
    print(f"wall paths at the zones' direct peaks (m): {np.round(opl, 3).tolist()}")
    time_axis(opl, panels(args.figure).argmax(-1), "each panel's highest bar")
    time_axis(opl, DOCS_PEAKS, "docs/rig_zones.md reads them")
    fit = json.loads(args.fit.read_text())
    if fit.get("status") != "fitted":
        raise SystemExit(f"{args.fit}: the sensor was not fitted ({fit.get('status')})")
    pile_up(fit["cycles"] / (SWEEP_KILO_ITERATIONS * 1000))


if __name__ == "__main__":
    main()
