#!/usr/bin/env python
"""Fit the rig's photometry to the real sensor's zones; prints the fit,
writes nothing.

    python scripts/fit_zones.py                  # start from the config's rig
    python scripts/fit_zones.py --config other.yaml
    python scripts/fit_zones.py --features ../shared/denali-assets/feature_stats
    python scripts/fit_zones.py --features ../shared/denali-assets/feature_stats --family-floor

How `rig.photometry`'s emission, flux, saturation, floor and slow tail were
fitted (docs/rig_zones.md): least squares on the nine zones' log mean counts
against REFERENCE Part 5's (a 7 % scale, so a zone 15 % off costs about two),
with Part 4's centre-zone checks as one-sided penalties that cost nothing
inside their ranges: (b) the floor 1.2-5 % of the direct peak and the late
bins at 0.25-0.48 of it, (c) an 8 in square's bump at mid gantry 4-7 % of
the peak and 1.55-2.2x the floor, the bump of the release's located 8 in "8"
at location 90 4.2-5.8 bins wide, the pooled log1p mean 7.0-7.2 and spread
0.70-0.86, and the far column's early return over its own peak
(`rig.measure.early_share`) 0.45-0.8 in the far corners and 0.05-0.2 beside
the centre, as `capture_setup.png` shows it. Expected counts, no nuisances;
the zone means over 3 locations x 2 objects (A, square; 8 in) x 2
lightings. The same figure's nine zones, read bar by bar (its hexagon at
location 84, lights off), add one-sided checks on every zone's direct
return: its half-maximum width within 1.5 bins of the figure's, its rise
against the centre's within 2.5. The flood keeps the receiver's 52:41
aspect and the core is round, so 8 parameters: the flood's width, the
core's share and width, the yaw, the flux, the saturation count, the dark
floor (room light twice it) and the slow tail's share. The pulse's fast part, the slow tail's time
constant, the dead time, the glare and the vignetting stay as configured.
A few minutes on one core.

With `--features DIR` (the release's 1D CNN statistics, REFERENCE Part 7)
the fit adds Part 7's targets on the same expected counts: each zone's mean
of z = (log1p(counts) - 7.108) / 0.785 against Part 7's (a 0.05 z scale), and
the layer-1 channel variances of the raw-count and the log-input nets (every
channel's log(var / running_var), a 0.15 scale shared by each group's
channels so that a group weighs as five residuals); and frees seven more
physical terms: the room light apart from the dark counts, the slow tail's
time constant, the SPADs' dead time, the receiver's glare, the flood's
profile order, its vertical width apart from the receiver's aspect and its
contours' exponent.
Layers 2 and 3 are not fitted: the final report gives them, held out
(`rig.feature_moments`). `--max-nfev` bounds the evaluations.

`--family-floor` (with `--features`) is a diagnostic, never the config's
fit: it frees four more terms (the pulse's jitter and fast tail, the beam's
pitch, the vignetting power) and adds every net's and layer's distance to
the objective, layers 2 and 3 included, so the fit reports how close the
rig's physical terms can come to the real moments at all, and which fitted
yardstick and check they give up to get there.

Cited by docs/rig_zones.md, "Every zone's photometry" (the fit) and
"The feature statistics" (`--family-floor`).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import yaml
from scipy.optimize import least_squares
from scipy.special import expit, logit

from denali_pipe.core import geometry as geo
from denali_pipe.core.objects import load_catalogue
from denali_pipe.report.paper import REAL_FIGURE_CAPTURE, REAL_FIGURE_ZONES, REAL_LOG_ZONE_MEANS, REAL_ZONE_MEANS
from denali_pipe.report.rig_vs_real import zone_pattern
from denali_pipe.rig import feature_moments as fm
from denali_pipe.rig import histograms as H
from denali_pipe.rig.measure import SHAPE_FLOOR_BINS, early_share, measure
from denali_pipe.rig.scene import design_scene

REPO = Path(__file__).resolve().parents[1]
ZONE_SCALE = 0.07
# Part 7's targets (with --features): z zone means, every layer-1 channel's log variance ratio
LOG_ZONE_SCALE = 0.05
VAR_SCALE = 0.15
GROUP_WEIGHT = 5
# --family-floor: every (net, layer)'s sqrt(distance) times this
FAMILY_WEIGHT = 3.0
ASPECT = geo.SENSOR_FOV_DEG[1] / geo.SENSOR_FOV_DEG[0]
# (name, low, high, scale) of each centre-zone check's penalty
CHECKS = (
    ("floor / peak", 0.012, 0.05, 0.003),
    ("late / floor", 0.25, 0.48, 0.02),
    ("bump / peak", 0.04, 0.07, 0.002),
    ("bump / floor", 1.55, 2.2, 0.03),
    ("FWHM at 90", 4.2, 5.8, 0.2),
    ("log1p mean", 7.0, 7.2, 0.05),
    ("log1p sd", 0.70, 0.86, 0.03),
    # capture_setup.png's far column: the early return over the zone's own
    # peak, pixels 1 and 7 (the far corners) 0.56 and 0.67, pixel 4 0.11
    ("early share, far corners", 0.45, 0.8, 0.03),
    ("early share, far edge", 0.05, 0.2, 0.03),
)
# capture_setup.png's nine zones read bar by bar (paper.REAL_FIGURE_ZONES on
# paper.REAL_FIGURE_CAPTURE, lights off): each zone's direct return's
# half-maximum width within 1.5 bins of the figure's, its rise against the
# centre's within 2.5 (tests/test_histograms.py holds the integer readings
# to 2 and 3)
FIGURE_CHECKS = tuple((f"width, zone {z}", w - 1.5, w + 1.5, 0.2) for z, w in enumerate(REAL_FIGURE_ZONES["width"]) if not np.isnan(w)) + tuple(
    (f"rise, zone {z}", r - 2.5, r + 2.5, 0.3) for z, r in enumerate(REAL_FIGURE_ZONES["half_rise"]) if z != 4
)


def to_photometry(base: H.Photometry, v: np.ndarray) -> H.Photometry:
    """The 8 zone parameters, then (with --features) room light, slow tail's
    time constant, dead time, glare, the flood's order, vertical width and
    contour exponent, then (with --family-floor) the pulse's jitter and fast tail, the beam's
    pitch and the vignetting power."""
    flood, core_logit, core, yaw, flux, sat, dark, slow_logit = v[:8]
    vertical = np.exp(flood) * ASPECT
    more = {}
    if len(v) > 8:
        ambient, slow_bins, dead, glare_logit, order, vertical_log, contour = v[8:15]
        vertical = np.exp(vertical_log)
        more = {
            "ambient_counts": float(np.exp(ambient)),
            "slow_tail_bins": float(np.exp(slow_bins)),
            "dead_time_counts": float(np.exp(dead)),
            "glare_share": float(expit(glare_logit)),
            "beam_order": float(np.exp(order)),
            # contours stay convex: q > 1
            "beam_contour": float(1.0 + np.exp(contour)),
        }
    if len(v) > 15:
        sigma, fast, pitch, vignetting = v[15:]
        more |= {
            "pulse_sigma_bins": float(np.exp(sigma)),
            "pulse_tail_bins": float(np.exp(fast)),
            "beam_pitch_deg": float(pitch),
            "vignetting_power": float(np.exp(vignetting)),
        }
    phot = dataclasses.replace(
        base,
        beam_hwhm_deg=(float(np.exp(flood)), float(vertical)),
        core_share=float(expit(core_logit)),
        core_hwhm_deg=float(np.exp(core)),
        beam_yaw_deg=float(yaw),
        direct_peak_counts=float(np.exp(flux)),
        saturation_counts=float(np.exp(sat)),
        dark_counts=float(np.exp(dark)),
        ambient_counts=float(2 * np.exp(dark)),
        slow_tail_fraction=float(expit(slow_logit)),
    )
    return dataclasses.replace(phot, **more)


def from_photometry(p: H.Photometry, features: bool = False, family: bool = False) -> np.ndarray:
    more = (
        [
            np.log(p.ambient_counts),
            np.log(p.slow_tail_bins),
            np.log(p.dead_time_counts),
            logit(p.glare_share),
            np.log(p.beam_order),
            np.log(p.beam_hwhm_deg[1]),
            np.log(p.beam_contour - 1.0),
        ]
        if features
        else []
    )
    if family:
        more += [np.log(p.pulse_sigma_bins), np.log(p.pulse_tail_bins), p.beam_pitch_deg, np.log(p.vignetting_power)]
    return np.array(
        [
            np.log(p.beam_hwhm_deg[0]),
            logit(p.core_share),
            np.log(p.core_hwhm_deg),
            p.beam_yaw_deg,
            np.log(p.direct_peak_counts),
            np.log(p.saturation_counts),
            np.log(p.dark_counts),
            logit(p.slow_tail_fraction),
            *more,
        ]
    )


# The light transport depends on the photometry only through the beam and
# the receiver: kept for the latest beam, so steps in the other terms reuse it.
BEAM = ("beam_hwhm_deg", "beam_order", "beam_contour", "core_share", "core_hwhm_deg", "beam_yaw_deg", "beam_pitch_deg", "vignetting_power")
_transports: dict = {}


def transport(catalogue: dict, name: str, location: int, phot: H.Photometry, mount_only: bool = False, size: str = "8inch") -> H.Transport:
    """The object `name` of `size` (or its mount alone) at `location`'s design pose."""
    beam = tuple(getattr(phot, k) for k in BEAM)
    if _transports.get("beam") != beam:
        _transports.clear()
        _transports["beam"] = beam
    key = (name, size, location, mount_only)
    if key not in _transports:
        scene = design_scene(catalogue[name], size, location)
        _transports[key] = H.transport("3x3", scene[:1] if mount_only else scene, phot)
    return _transports[key]


def half_crossings(h: np.ndarray) -> tuple[float, float]:
    """Where a zone's direct return (N_BINS,) first rises through half its
    peak above the floor and how long it stays above, in fractional bins
    (linear between bins): `zone_shape`'s half_rise and width made smooth
    in the parameters, so that a least-squares step sees them move."""
    above = h - np.median(h[:SHAPE_FLOOR_BINS])
    half = 0.5 * above.max()
    over = np.nonzero(above >= half)[0]
    i, j = over[0], over[-1]
    rise = i - 1 + (half - above[i - 1]) / (above[i] - above[i - 1])
    fall = j + (above[j] - half) / (above[j] - above[j + 1])
    return float(rise), float(fall - rise)


def figure_checks(phot: H.Photometry, catalogue: dict) -> dict[str, float]:
    """FIGURE_CHECKS' values on the figure's capture, by their names."""
    name, size, location = REAL_FIGURE_CAPTURE
    zones = H.counts_from_transport("3x3", False, transport(catalogue, name, location, phot, size=size), phot).reshape(9, -1)
    crossings = [half_crossings(h) for h in zones]
    out = {f"width, zone {z}": crossings[z][1] for z in range(9)}
    out |= {f"rise, zone {z}": crossings[z][0] - crossings[4][0] for z in range(9)}
    return {name: out[name] for name, *_ in FIGURE_CHECKS}


def measures(phot: H.Photometry, catalogue: dict) -> tuple[np.ndarray, dict, np.ndarray]:
    """The zone means (3, 3), the checks by CHECKS' and FIGURE_CHECKS'
    names, and the expected counts the zone means come from (12, 9, N_BINS)."""

    rng = np.random.default_rng(0)
    means, logs, hists = [], [], []
    for k in (5, 45, 94):
        for name in ("A", "square"):
            light = transport(catalogue, name, k, phot)
            for on in (True, False):
                expected = H.counts_from_transport("3x3", on, light, phot)
                means.append(expected.mean(-1))
                hists.append(expected.reshape(9, -1))
                logs.append(np.log1p(H.sample_counts(expected, phot, rng)))
    mount = H.counts_from_transport("3x3", False, transport(catalogue, "square", 45, phot, mount_only=True), phot)
    background = mount[1, 1]
    b = measure(background, background)
    zones = mount.reshape(9, -1)
    corners = np.mean([early_share(zones, z) for z in (0, 6)])
    c = measure(H.counts_from_transport("3x3", False, transport(catalogue, "square", 45, phot), phot)[1, 1], background)
    eight = H.counts_from_transport("3x3", False, transport(catalogue, "8", 90, phot), phot)[1, 1]
    width = measure(eight, H.counts_from_transport("3x3", False, transport(catalogue, "8", 90, phot, mount_only=True), phot)[1, 1]).bump_fwhm
    values = (b.floor_fraction, b.late_over_floor, c.bump_fraction, c.bump_over_floor, width, np.mean(logs), np.std(logs), corners, early_share(zones, 3))
    checks = dict(zip([name for name, *_ in CHECKS], values)) | figure_checks(phot, catalogue)
    return np.mean(means, 0), checks, np.asarray(hists)


def layer1_log_ratios(nets: list[fm.Backbone], hist: np.ndarray) -> dict[str, np.ndarray]:
    """log(var / running_var) of every layer-1 channel, pooled per input kind."""
    out: dict[str, list] = {}
    for net in nets:
        _, var = fm.layer_moments(net, hist, depth=1)[0]
        out.setdefault(net.input, []).append(np.log(var / net.layers[0].running_var))
    return {k: np.concatenate(v) for k, v in out.items()}


def feature_residuals(hist: np.ndarray, nets: list[fm.Backbone]) -> np.ndarray:
    dz = (fm.log_zone_means(hist) - np.ravel(REAL_LOG_ZONE_MEANS)) / LOG_ZONE_SCALE
    ratios = layer1_log_ratios(nets, hist)
    return np.concatenate([dz] + [ratios[k] / (VAR_SCALE * np.sqrt(len(ratios[k]) / GROUP_WEIGHT)) for k in ("raw", "log_z")])


def residuals(v: np.ndarray, base: H.Photometry, catalogue: dict, nets: list[fm.Backbone] | None = None, family: bool = False) -> np.ndarray:
    means, checks, hist = measures(to_photometry(base, v), catalogue)
    zones = np.log(means / np.asarray(REAL_ZONE_MEANS)).ravel() / ZONE_SCALE
    penalties = [(max(lo - checks[name], 0) + max(checks[name] - hi, 0)) / scale for name, lo, hi, scale in CHECKS + FIGURE_CHECKS]
    features = feature_residuals(hist, nets) if nets else []
    # each (net, layer)'s distance as a squared residual, so that their mean
    # weighs as FAMILY_WEIGHT^2 x 54 against the rest
    layers = FAMILY_WEIGHT * np.sqrt(fm.feature_distances(nets, hist).distance.to_numpy()) if family else []
    return np.concatenate([zones, penalties, features, layers])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--features", type=Path, default=None, help="the release's feature statistics folder: fit Part 7's targets too")
    ap.add_argument("--max-nfev", type=int, default=40)
    ap.add_argument("--family-floor", action="store_true", help="diagnostic: every layer fitted, four more terms freed (never the config's fit)")
    args = ap.parse_args()
    if args.family_floor and args.features is None:
        ap.error("--family-floor needs --features")
    with open(args.config) as f:
        config = yaml.safe_load(f)
    base = H.Photometry.from_config(config["rig"]["photometry"], geo.TimeAxis.from_config(config["sensor"]["time_axis"]))
    catalogue = load_catalogue(REPO / "config" / "objects.tsv")
    nets = fm.load_backbones(args.features) if args.features else None
    start = from_photometry(base, features=nets is not None, family=args.family_floor)
    if nets:
        print("start: " + held_out(base, catalogue, nets), flush=True)
    fit = least_squares(residuals, start, args=(base, catalogue, nets, args.family_floor), diff_step=0.03, x_scale=0.3, max_nfev=args.max_nfev)
    phot = to_photometry(base, fit.x)
    means, checks, _ = measures(phot, catalogue)
    print(f"{fit.nfev} evaluations, cost {fit.cost:.2f}, status {fit.status}")
    for name in (
        "beam_hwhm_deg",
        "core_share",
        "core_hwhm_deg",
        "beam_yaw_deg",
        "beam_pitch_deg",
        "vignetting_power",
        "direct_peak_counts",
        "saturation_counts",
        "dark_counts",
        "ambient_counts",
        "pulse_sigma_bins",
        "pulse_tail_bins",
        "slow_tail_fraction",
        "slow_tail_bins",
        "dead_time_counts",
        "glare_share",
        "beam_order",
        "beam_contour",
    ):
        value = getattr(phot, name)
        print(f"  {name}: {np.round(value, 3).tolist()}")
    print("zone error, %: " + " ".join(f"{100 * e:+.0f}" for e in (means / np.asarray(REAL_ZONE_MEANS) - 1).ravel()))
    print("  " + "; ".join(f"{k} {v:.2f}" for k, v in zone_pattern(means).items()))
    print("  " + "; ".join(f"{k} {v:.3g}" for k, v in checks.items()))
    if nets:
        print(("fitted, every layer: " if args.family_floor else "fitted: ") + held_out(phot, catalogue, nets))


def held_out(phot: H.Photometry, catalogue: dict, nets: list[fm.Backbone]) -> str:
    """Part 7's yardsticks on the fit's expected counts: the z zone offsets
    and every layer's distance (layers 2 and 3 are fitted only by --family-floor)."""
    _, _, hist = measures(phot, catalogue)
    s = fm.summary(fm.feature_distances(nets, hist))
    dz = fm.log_zone_means(hist) - np.ravel(REAL_LOG_ZONE_MEANS)
    words = "; ".join(f"{k} {v:.2f}" for k, v in s.items())
    return f"{words}; z zone offsets {' '.join(f'{d:+.2f}' for d in dz)}"


if __name__ == "__main__":
    main()
