"""Calibration of the twin from the captures (`denali twin-calibration`):
what the paper set by hand, fitted by least squares.

Parameters:
- per zone of the 3x3 grid, its footprint's centre offset on the wall
  (offset_u, offset_v, m along the wall's u and v) and its size scale (the
  zone's iFoV against the design FoV's ninth);
- a global time offset (bins, added to every path: the captures' time zero
  against the twin's);
- with `twin.material: retroreflective`, the object's diffuse share and,
  under the spot, its lobe width (deg; under the flood the lobe's narrow
  limit holds and its width drops out, `twin.analytic`);
- under `twin.illumination: flood`, the emission (`layout.Emission`): the
  flood's half widths (deg, horizontal and vertical), the core's share of
  the on-axis intensity and its half width (deg): how much light each part
  of the wall gets, which sets each zone's retroreflected return against
  the light every zone's footprint sends the object;
- the receiver's glare share (`core.glare`): the share of all the light
  reaching the receiver that its optics spread over the whole SPAD array,
  so that every zone holds the others' returns at their times. A zone far
  from the object's brightest return holds that return, through the glare,
  as well as its own; a twin without it bends its emission to light the far
  zones instead (the demo's flood went to its 90 deg bound).
Nuisances, fitted beside them but not part of the twin: each zone's gain
(counts per unit of the twin's radiance: the sensor's illumination and
response pattern, solved in closed form at every step) and the sensor's
pulse (`denali_pipe.core.pulse`: the jitter's sd and the SPAD tail's time
constant; the transforms model the pulse). The pulse's slow part is left
out: background subtraction leaves too little of it to identify (fitted
on the demo, its share went to its 0.25 % bound and its time constant to
its bound, with the held-out residual unchanged).

The model of zone z of capture i is glare(gain * (k * h_i))_z[b], h the
analytic twin (tent filter, `twin.calibration` film and samples) of each
zone's footprint, k the pulse shifted by time_offset bins, the gains the
light each zone's own footprint sends it and `glare` the receiver's mixing
(equal SPAD groups: `GLARE_SPADS`). A SPAD's response rises
within a bin or two and decays over many; a symmetric pulse cannot follow a
bump of that shape, and the geometry then bends to make up for it. The data
are the background-subtracted 3x3 light-on captures of the training split
(`transforms.split_pairs`: the Fig 9 test captures are never read), mean
over repeats, each capture's floor offset taken out (`core.floor`,
`Problem.take_floor_offsets`), each zone weighted by its noise (the
repeats' pooled variance of the mean over the bins it keeps). A share
`validation_fraction` of the training captures is held out of the fit:
each zone's residual on them before (the design twin, with its gains and
pulse fitted) and after calibration says what the fit bought, beside the
residual the noise alone leaves (`zone_residuals`). Uncertainties: a bootstrap over captures drawn
with replacement, as transforms.json's, each resample's refit linearised
about the fit (`linearised_bootstrap`), its intervals holding the estimate
and the coordinates the captures do not pin down named (`uncertainty`).

The 8x8 grid's footprints follow from the 3x3 fit: an affine map of the
zone centres on the wall (nominal -> fitted, least squares over the 9
zones) and the zones' mean size scale (64 zones are too many to fit from
captures with 8x8's few photons).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import least_squares, nnls

from denali_pipe.core import pulse
from denali_pipe.core.atomic import atomic_file
from denali_pipe.core.floor import common_offset, kept_bins, offset_spread
from denali_pipe.core.geometry import TimeAxis
from denali_pipe.core.glare import glare
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.core.pulse import Pulse
from denali_pipe.twin.analytic import AnalyticRenderer
from denali_pipe.twin.layout import Calibration, Emission, Material, TwinScene, ZoneGeometry, flood, material_of, twin_scene, zone_footprints

log = logging.getLogger(__name__)

GRID = 3  # the grid the captures calibrate
ZONES = GRID * GRID
# 5: the emission's core; 4: the receiver's glare; 3: the flood's emission widths; 2: the SPAD pulse (jitter and tail) in place of a Gaussian
CALIBRATION_VERSION = 5
PULSE = ("pulse_sigma", "pulse_tail")  # the pulse's parameters, as named in the file
GLOBALS = ("time_offset", *PULSE)  # the fit coordinates after the zones', before the material's
# Finite-difference steps of the Jacobian, in the fit's own coordinates (see `_unpack`).
STEP = 1e-3
# The fit stops when a step lowers its cost by less than this share of it. On the
# demo (200 training captures) the fit reached it after 38 evaluations (140 CPU-s);
# at scipy's default (1e-8) it crawled on along a valley to its budget of 200
# (820 CPU-s), lowering the cost by another 0.4 % and moving no zone's held-out
# nl2 by more than 0.004: the twin's mismatch, not the optimiser, sets the fit.
COST_TOLERANCE = 1e-4
# Bounds of the fit's coordinates: offsets within +-10 cm, scales 0.3-3x, time offset +-20 bins,
# the pulse's jitter 0.2-15 bins and tail 0.1-15, lobe 0.5-60 deg, the flood's half widths 3-90 deg,
# the core's 0.3-15 deg (0.3 deg: 3 mm on the wall, a point to every object and footprint).
OFFSET_CM_BOUND = 10.0
SCALE_BOUNDS = (0.3, 3.0)
TIME_OFFSET_BOUND_BINS = 20.0
PULSE_BOUNDS = ((0.2, 15.0), (0.1, 15.0))
HWHM_BOUNDS_DEG = (3.0, 90.0)
CORE_HWHM_BOUNDS_DEG = (0.3, 15.0)
EMISSION = ("beam_hwhm_h_deg", "beam_hwhm_v_deg", "core_share", "core_hwhm_deg")  # the emission's parameters, as named in the file
GLARE = "glare_share"  # the receiver's, as named in the file
# The share of the glare each zone takes: its SPADs' share of the array. The
# twin takes the 3x3 map's zones as equal SPAD groups; a zone's gain carries
# what its own footprint's light costs it, not what the glare brings.
GLARE_SPADS = np.ones(ZONES)
# A share's logit bounds (the object's diffuse share, the emission's core): 0.25 % to 99.75 %.
SHARE_LOGIT_BOUNDS = (-6.0, 6.0)
# The glare share's logit bounds: 1e-4 (none to speak of) to 0.5.
GLARE_LOGIT_BOUNDS = (-9.2, 0.0)


@dataclass(frozen=True)
class Fitted:
    """A calibration: offsets (3, 3, 2) m, scales (3, 3), time_offset
    (bins), the pulse, gains (3, 3) counts per radiance, material, the
    illumination it was fitted under, for the flood its emission
    (`layout.Emission`), and the receiver's glare share."""

    offsets: np.ndarray
    scales: np.ndarray
    time_offset: float
    pulse: Pulse
    gains: np.ndarray
    material: Material
    illumination: str
    emission: Emission | None
    glare_share: float

    def receive(self, hist: np.ndarray) -> np.ndarray:
        """A 3x3 twin (..., 3, 3, T) in radiance as each zone collects it once
        the receiver's glare has mixed every zone's light (`core.glare`):
        glare(gains * hist) / gains, zone by zone. A zone whose gain is 0 (its
        captures held no return of its own the fit could follow) takes the
        median of the others' for this: its own footprint's light then counts
        as much as a typical zone's, and the glare it holds as any zone's."""
        gains = self.gains.reshape(ZONES)
        own = np.where(gains > 0, gains, np.median(gains[gains > 0]) if (gains > 0).any() else 1.0)[:, None]
        light = hist.reshape(*hist.shape[:-3], ZONES, hist.shape[-1]) * own
        return (np.einsum("zk,...kt->...zt", mixing(self.glare_share), light) / own).reshape(hist.shape)

    def zones(self, cal: Calibration, n: int) -> ZoneGeometry:
        """The footprints of an n x n grid: the fit itself for 3x3, its affine
        map of zone centres and mean scale for others."""
        if n == GRID:
            return ZoneGeometry(self.offsets, self.scales)
        centres = np.array([[(r.centre - cal.wall.centre) @ cal.wall.u, (r.centre - cal.wall.centre) @ cal.wall.v] for r in zone_footprints(cal, GRID)])
        design = np.c_[centres, np.ones(ZONES)]
        affine, *_ = np.linalg.lstsq(design, centres + self.offsets.reshape(-1, 2), rcond=None)
        target = np.array([[(r.centre - cal.wall.centre) @ cal.wall.u, (r.centre - cal.wall.centre) @ cal.wall.v] for r in zone_footprints(cal, n)])
        moved = np.c_[target, np.ones(len(target))] @ affine
        return ZoneGeometry((moved - target).reshape(n, n, 2), np.full((n, n), float(self.scales.mean())))

    def twin_scene(self, cal: Calibration, mesh, settings: dict, axis: TimeAxis, n: int, spec: ObjectSpec) -> TwinScene:
        """The calibrated twin of `mesh` on the n x n grid, on `axis` (the
        captures' it was fitted to; non-RR objects stay Lambertian)."""
        rr = spec.material == "retroreflective"
        material = self.material if rr else material_of(settings, False)
        return twin_scene(
            cal, mesh, {**settings, "illumination": self.illumination}, axis, n, zones=self.zones(cal, n), material=material,
            time_offset_opl=self.time_offset * axis.bin_width_opl, emission=self.emission,
        )  # fmt: skip


# --- the data ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Captures:
    """Real 3x3 captures: real (N, R, 3, 3, T) background-subtracted counts
    of bins crop_start .. crop_start + T - 1; keys (N rows: set, object,
    size, location)."""

    real: np.ndarray
    keys: pd.DataFrame
    crop_start: int

    def subset(self, rows) -> Captures:
        return Captures(self.real[rows], self.keys.iloc[rows].reset_index(drop=True), self.crop_start)


# --- the model --------------------------------------------------------------------------


class Model:
    """The analytic twins of a set of captures, zone by zone, under changing
    parameters. specs: {object name: ObjectSpec}; settings: the `twin`
    section (its `calibration` part: film, samples); axis: the captures'
    time axis."""

    def __init__(self, cal: Calibration, specs: dict, keys: pd.DataFrame, settings: dict, axis: TimeAxis):
        self.cal, self.settings, self.keys = cal, settings, keys
        self.meshes = {(name, size): object_mesh(specs[name], size) for (name, size), _ in keys.groupby(["object", "size"], sort=False)}
        c = settings["calibration"]
        scene = {**settings, "footprint": {**settings["footprint"], "film": c["film"]}}
        design = _unpack(initial(settings), settings)[4]  # the design's light, as the fit's first step computes it
        self.renderers = {
            key: AnalyticRenderer(twin_scene(cal, mesh, scene, axis, GRID, emission=design), c["samples"], "tent") for key, mesh in self.meshes.items()
        }
        self._object_terms(design)

    def _light(self, emission: Emission) -> None:
        """Every renderer lit by the flood of `emission`, and the object terms under it."""
        lit = flood(self.cal, emission, self.settings["flood"]["grid"])
        for r in self.renderers.values():
            r.set_light(lit)
        self._object_terms(emission)

    def _object_terms(self, emission: Emission | None) -> None:
        """The object terms of every capture under the renderers' light, `emission` (None: the spot)."""
        self.terms = [
            ((name, size), int(location), self.renderers[(name, size)].object_terms(int(location)))
            for name, size, location in zip(self.keys["object"], self.keys["size"], self.keys["location"])
        ]
        self.emission = emission

    def zone(self, z: int, zones: ZoneGeometry, material: Material, emission: Emission | None) -> np.ndarray:
        """(N, N_BINS) zone z's twin (mean over its film) for every capture,
        under the flood of `emission` (None: the spot)."""
        if emission != self.emission:
            self._light(emission)
        rect = zone_footprints(self.cal, GRID, zones)[z]
        out = []
        for key, location, terms in self.terms:
            r = self.renderers[key]
            if r.relays[0] is not rect:  # a renderer renders many captures: its film's emission once per footprint
                r.set_relays([rect])
            out.append(r.render(location, material, terms)[0].mean(axis=(0, 1)))
        return np.array(out)


# --- the fit ----------------------------------------------------------------------------


def _rr(settings: dict) -> bool:
    return settings.get("material", "lambertian") == "retroreflective"


def _flood(settings: dict) -> bool:
    return settings.get("illumination", "spot") == "flood"


def tail_names(settings: dict) -> list[str]:
    """The fit's coordinates after the zones', by name: `GLOBALS`, the
    material's (the lobe width under the spot only), the flood's emission,
    the receiver's glare."""
    names = list(GLOBALS)
    if _rr(settings):
        names += ["diffuse_share"] if _flood(settings) else ["lobe_width_deg", "diffuse_share"]
    return names + (list(EMISSION) if _flood(settings) else []) + [GLARE]


def initial(settings: dict) -> np.ndarray:
    """The design twin in the fit's coordinates: offsets 0 cm, log scale of
    `footprint.scale`, time offset 0, the log times of `calibration.pulse`,
    with a retroreflective object the logit diffuse share (and under the
    spot the log lobe width) of `twin.retroreflective`, under the flood the
    log half widths of `flood.beam_hwhm_deg`, the logit of its `core_share`
    and the log of its `core_hwhm_deg`, and the logit of
    `calibration.glare_share`."""
    p = settings["calibration"]["pulse"]
    x = [
        *np.zeros(2 * ZONES),
        *np.full(ZONES, np.log(settings["footprint"]["scale"])),
        0.0,
        *np.log([p["sigma_bins"], p["tail_bins"]]),
    ]
    if _rr(settings):
        lobe = settings["retroreflective"]
        x += ([] if _flood(settings) else [np.log(lobe["lobe_width_deg"])]) + [_logit(lobe["diffuse_share"])]
    if _flood(settings):
        f = settings["flood"]
        x += [*np.log(f["beam_hwhm_deg"]), _logit(f["core_share"]), np.log(f["core_hwhm_deg"])]
    return np.array(x + [_logit(settings["calibration"]["glare_share"])], float)


def _logistic(v: float) -> float:
    return float(1 / (1 + np.exp(-v)))


def _logit(share: float) -> float:
    return float(np.log(share / (1 - share)))


def _unpack(x: np.ndarray, settings: dict) -> tuple[ZoneGeometry, float, Pulse, Material, Emission | None, float]:
    """Fit coordinates -> (zone geometry, time offset bins, pulse, material,
    the flood's emission or None under the spot, the glare share).
    Offsets in cm, scales, times and widths as logs, the shares as logits: steps of
    similar effect, and the bounds of the physical parameters hold by construction."""
    off = x[: 2 * ZONES].reshape(GRID, GRID, 2) / 100
    scales = np.exp(x[2 * ZONES : 3 * ZONES]).reshape(GRID, GRID)
    g = 3 * ZONES
    t0 = float(x[g])
    p = Pulse(*(float(v) for v in np.exp(x[g + 1 : g + len(GLOBALS)])))
    material = material_of(settings)
    tail = dict(zip(tail_names(settings), x[g:]))
    if _rr(settings):
        width = float(np.exp(tail["lobe_width_deg"])) if "lobe_width_deg" in tail else material.lobe_width_deg
        material = Material("retroreflective", material.albedo, width, _logistic(tail["diffuse_share"]))
    emission = None
    if _flood(settings):
        h, v, share, core = (tail[k] for k in EMISSION)
        emission = Emission((float(np.exp(h)), float(np.exp(v))), _logistic(share), float(np.exp(core)))
    return ZoneGeometry(off, scales), t0, p, material, emission, _logistic(tail[GLARE])


# The trust-region solver keeps its iterates strictly inside the bounds and
# only approaches one it is pushed against: on the demo two footprints
# stopped at 2.99999x and 2.9992x of their 3x bound (1.5e-6 and 2.7e-4
# inside in log scale), which an absolute 1e-6 missed. 0.1 % of a
# coordinate's range is 0.23 % of a scale, 0.02 cm of an offset and 0.04
# bins of the time offset: no physical difference from the bound.
BOUND_TOLERANCE = 1e-3
# A bin is dark to the twins where they render less than this share of the
# zone's peak (over its captures): there the captures hold their floor offset
# and noise only (`Problem.take_floor_offsets`).
TWIN_FREE_SHARE = 1e-3
# Bins kept clear of the twins' onset: the fit's time offset and the pulse's
# rise may move the return earlier than the twins at the fit's start show it
# (the demo's time offset: -0.13 bins).
DARK_MARGIN_BINS = 3
# A coordinate whose bootstrap interval spans more than this share of its
# range is not identified: the captures narrow it less than 4x from what the
# bounds allow (a scale's 90 % interval over 1.8x, a width's over 2.3x, an
# offset's over 5 cm). Planted under a 5 x 4 deg flood, whose off-centre
# zones hold no signal above the noise, the fit put a width at 31 deg with
# an interval of 9-183 deg that missed the truth and spanned 0.9 of its range.
IDENTIFIED_SPAN = 0.25


def _bounds(settings: dict) -> tuple[np.ndarray, np.ndarray]:
    lo = [*np.full(2 * ZONES, -OFFSET_CM_BOUND), *np.full(ZONES, np.log(SCALE_BOUNDS[0])), -TIME_OFFSET_BOUND_BINS, *np.log([b[0] for b in PULSE_BOUNDS])]
    hi = [*np.full(2 * ZONES, OFFSET_CM_BOUND), *np.full(ZONES, np.log(SCALE_BOUNDS[1])), TIME_OFFSET_BOUND_BINS, *np.log([b[1] for b in PULSE_BOUNDS])]
    tail = {
        "lobe_width_deg": np.log([0.5, 60.0]),
        "diffuse_share": SHARE_LOGIT_BOUNDS,
        **dict.fromkeys(EMISSION[:2], np.log(HWHM_BOUNDS_DEG)),
        "core_share": SHARE_LOGIT_BOUNDS,
        "core_hwhm_deg": np.log(CORE_HWHM_BOUNDS_DEG),
        GLARE: GLARE_LOGIT_BOUNDS,
    }
    for name in tail_names(settings)[len(GLOBALS) :]:
        lo.append(tail[name][0])
        hi.append(tail[name][1])
    return np.array(lo), np.array(hi)


class Problem:
    """Least squares of the twins against real means: y (N, Z, T) repeat
    means, sigma (Z,) each zone's noise sd of a mean."""

    def __init__(self, model: Model, captures: Captures, settings: dict):
        self.model, self.settings = model, settings
        self.crop, self.T = captures.crop_start, captures.real.shape[-1]
        R = captures.real.shape[1]
        real = captures.real.reshape(len(captures.real), R, ZONES, self.T).astype(np.float64)
        self.y = real.mean(axis=1)
        # (1, Z, T): the bins each zone keeps, as its captures show them: the
        # preprocessing zeroes a later-starting zone's bins before its start
        # (a zone of all-zero captures, as the twins' own renders start from, keeps every bin)
        kept = kept_bins(self.y, axis=0)
        self.kept = (kept | ~kept.any(axis=1, keepdims=True))[None]
        n_kept = len(self.y) * self.kept.sum(axis=(0, 2))
        # (N, Z): each capture's expected squared noise in its repeat mean over
        # its kept bins (the repeats' unbiased variance / R); None without repeats
        self.noise_energy = None
        if R > 1:
            self.noise_energy = (real.var(axis=1, ddof=1) * self.kept).sum(axis=2) / R
            self.sigma = np.sqrt(self.noise_energy.sum(axis=0) / n_kept)
        else:
            self.sigma = np.sqrt((self.y**2 * self.kept).sum(axis=(0, 2)) / n_kept)
        self.sigma = np.maximum(self.sigma, 1e-9)
        self.offsets = np.zeros(self.y.shape[:2])
        self.cache: dict = {}

    def take_floor_offsets(self, x: np.ndarray) -> None:
        """Take each capture's floor offset out of its zones' means: the mean
        of its kept bins before the object's return can reach them (the twins
        at x below `TWIN_FREE_SHARE` of the zone's peak over the captures,
        less `DARK_MARGIN_BINS`; not the late bins, which the pulse's tail
        the fit is yet to find may reach). A capture's
        room light and dark level drift from its background's, the same in
        every repeat and bin (transforms.sim_to_real: the demo's dim zones
        hold offsets of sd ~35 counts against an object return of 10-20),
        which no twin renders. Each capture's reading holds the noise of its
        few dark bins, so it is shrunk toward the zone's mean by the share of
        their spread that is the offsets' own (tau^2 / (tau^2 + s_i^2),
        `core.floor.offset_spread`: no offsets, no change), and the zone's
        mean is taken out only where it stands 3 standard errors from 0
        (`core.floor.common_offset`);
        captures without a dark kept bin get that mean."""
        m = self.twins(x)
        lit = m >= TWIN_FREE_SHARE * m.max(axis=(0, 2), keepdims=True)
        onset = np.where(lit.any(axis=2), lit.argmax(axis=2), self.T)
        free = self.kept & (np.arange(self.T) < onset[..., None] - DARK_MARGIN_BINS)
        n = free.sum(axis=2)
        self.offsets = np.zeros(n.shape)
        for z in range(ZONES):
            has = n[:, z] > 0
            if has.sum() < 2:
                continue
            o = np.where(free[:, z], self.y[:, z], 0.0).sum(axis=1)[has] / n[has, z]
            s2 = self.sigma[z] ** 2 / n[has, z]
            tau2 = offset_spread(o, s2)
            mean = common_offset(o)
            self.offsets[:, z] = mean
            self.offsets[has, z] = mean + (o - o.mean()) * tau2 / (tau2 + s2)
        self.y = self.y - self.offsets[..., None] * self.kept
        self.cache.clear()

    def zone_twin(self, z: int, zones: ZoneGeometry, material: Material, emission: Emission | None) -> np.ndarray:
        key = (z, *zones.offsets[divmod(z, GRID)].round(12), round(float(zones.scales[divmod(z, GRID)]), 12), material, emission)
        if key not in self.cache:
            if len(self.cache) > 4 * ZONES:
                self.cache.clear()
            self.cache[key] = self.model.zone(z, zones, material, emission)
        return self.cache[key]

    def twins(self, x: np.ndarray) -> np.ndarray:
        """(N, Z, T) the twins blurred by the pulse, in the real bins the
        captures keep (0 in the others, as the preprocessing left the
        captures), before the gains."""
        zones, t0, p, material, emission, _ = _unpack(x, self.settings)
        h = np.stack([self.zone_twin(z, zones, material, emission) for z in range(ZONES)], axis=1)
        return pulse.convolve(h, pulse.kernel(p, t0))[..., self.crop : self.crop + self.T] * self.kept

    def gains(self, m: np.ndarray, share: float) -> np.ndarray:
        """(Z,) the zones' least-squares gains for twins m (N, Z, T) against y
        under a glare of `share`, non-negative: a zone counts photons.
        (Unconstrained, a zone whose data hold no return the twin can follow,
        such as a dim corner's background residue, took a negative gain and an
        upside-down twin.) The glare couples the zones, so the gains are one
        non-negative least squares over all of them, solved on its 9 x 9
        normal equations; without glare each zone's stands alone."""
        mix = mixing(share)  # (Z, Z): zone z collects mix[z, k] of zone k's light
        w = mix / self.sigma[:, None] ** 2
        gram = np.einsum("nkt,nlt->kl", m, m) * (mix.T @ w)
        rhs = np.einsum("zk,nkt,nzt->k", w, m, self.y)
        scale = np.sqrt(np.maximum(np.diagonal(gram), 1e-300))
        root = np.linalg.cholesky(gram / np.outer(scale, scale) + 1e-12 * np.eye(ZONES))
        return nnls(root.T, np.linalg.solve(root, rhs / scale))[0] / scale

    def expected(self, x: np.ndarray, gains: np.ndarray | None = None) -> np.ndarray:
        """(N, Z, T) the counts the model puts in each kept bin at x: the
        gains (fitted unless given) times the twins, mixed by the glare."""
        m = self.twins(x)
        share = _unpack(x, self.settings)[-1]
        g = self.gains(m, share) if gains is None else gains
        return np.einsum("zk,nkt->nzt", mixing(share), g[None, :, None] * m)

    def residuals(self, x: np.ndarray, gains: np.ndarray | None = None) -> np.ndarray:
        """(N, Z, T) noise-weighted residuals, gains fitted unless given."""
        return (self.y - self.expected(x, gains)) / self.sigma[None, :, None]


def mixing(share: float) -> np.ndarray:
    """(Z, Z) the receiver's glare as a matrix over zones (`core.glare`):
    row z, what zone z collects of each zone's light."""
    return glare(np.eye(ZONES), share, GLARE_SPADS)


def planted_captures(problem: Problem, truth: np.ndarray, gains: np.ndarray, noise_sd: float, repeats: int, rng: np.random.Generator) -> Captures:
    """Captures the twin itself renders at fit coordinates `truth`: the
    twins of `problem`'s captures times each zone's gain (Z,), mixed by the
    truth's glare (`Problem.expected`), `repeats` repeats with Gaussian noise of sd `noise_sd` (counts)
    each, in `problem`'s bins. For the recovery tests and the coverage
    script (scripts/calibration_coverage.py)."""
    mean = problem.expected(truth, gains)
    n, _, t = mean.shape
    real = mean[:, None] + rng.normal(0, noise_sd, (n, repeats, ZONES, t))
    return Captures(real.reshape(n, repeats, GRID, GRID, t).astype(np.float32), problem.model.keys, problem.crop)


def fit(problem: Problem, x0: np.ndarray, max_evaluations: int) -> tuple[np.ndarray, dict]:
    """The least-squares parameters (fit coordinates) from x0 (trust region
    reflective, bounded; forward-difference Jacobian with STEP), and a record
    of the fit: its evaluations (Jacobians not counted) and whether it
    converged before `max_evaluations`."""
    lo, hi = _bounds(problem.settings)
    x0 = np.clip(x0, lo + 1e-9, hi - 1e-9)
    res = least_squares(
        lambda x: problem.residuals(x).ravel(), x0, bounds=(lo, hi), diff_step=STEP, x_scale=1.0, ftol=COST_TOLERANCE, max_nfev=max_evaluations, method="trf"
    )
    log.info("calibration fit: cost %.4g after %d evaluations (%s)", res.cost, res.nfev, res.message)
    if res.status == 0:
        log.warning("calibration fit stopped at twin.calibration.max_evaluations (%d) before converging", max_evaluations)
    return res.x, {"evaluations": int(res.nfev), "converged": bool(res.status > 0)}


def coordinate_names(settings: dict) -> list[str]:
    """The fit coordinates' names, in order (per-zone ones as name[row, col])."""
    names = [f"offset_{'uv'[i % 2]}[{i // 2 // GRID}, {i // 2 % GRID}]" for i in range(2 * ZONES)]
    return names + [f"scale[{z // GRID}, {z % GRID}]" for z in range(ZONES)] + tail_names(settings)


def at_bound(x: np.ndarray, settings: dict, interval: np.ndarray | None = None) -> list[str]:
    """The fit coordinates at or near a bound, by name (`coordinate_names`):
    pinned (within `BOUND_TOLERANCE` of the coordinate's range of it: there
    the data push past the range the twin's geometry allows, and the
    bootstrap's spread says nothing), or, given their bootstrap intervals
    (P, 2) in fit coordinates, whose interval reaches past a bound (the
    captures do not keep it inside its range)."""
    lo, hi = _bounds(settings)
    tol = BOUND_TOLERANCE * (hi - lo)
    near = (x - lo < tol) | (hi - x < tol)
    if interval is not None:
        near |= (interval[:, 0] < lo) | (interval[:, 1] > hi)
    return [n for n, k in zip(coordinate_names(settings), near) if k]


def to_physical(x: np.ndarray, settings: dict) -> dict:
    """The fit coordinates as the named physical parameters: the zones'
    footprints, `GLOBALS`, the material's lobe, the flood's emission and the glare (`tail_names`)."""
    zones, t0, p, material, emission, share = _unpack(x, settings)
    tail = {"time_offset": t0, **dict(zip(PULSE, (p.sigma_bins, p.fast_tail_bins)))}
    tail |= {"lobe_width_deg": material.lobe_width_deg, "diffuse_share": material.diffuse_share, GLARE: share}
    if emission is not None:
        tail |= dict(zip(EMISSION, (*emission.hwhm_deg, emission.core_share, emission.core_hwhm_deg)))
    out = {"offset_u": zones.offsets[..., 0], "offset_v": zones.offsets[..., 1], "scale": zones.scales}
    return out | {k: tail[k] for k in tail_names(settings)}


def nl2_net_of_noise(err2: np.ndarray, signal2: np.ndarray, noise2: np.ndarray) -> np.ndarray:
    """The twin's own residual, the noise's share taken out, squared and
    signed: (||y - t||^2 - E||noise||^2) / (||y||^2 - E||noise||^2), an
    unbiased-numerator estimate of ||mu - t||^2 / ||mu||^2 for the captures'
    expected histograms mu, since a held-out capture's noise is independent
    of its twin (E||y - t||^2 = ||mu - t||^2 + E||noise||^2, and likewise
    ||y||^2). Below 0 where the residual is within the noise (kept signed so
    that its bootstrap is not clipped); nan where the noise holds all of y.
    Arguments summed over captures, any matching shape."""
    signal = signal2 - noise2
    return np.where(signal > 0, (err2 - noise2) / np.where(signal > 0, signal, 1.0), np.nan)


def zone_residuals(problem: Problem, x: np.ndarray, gains: np.ndarray, rng: np.random.Generator) -> dict:
    """Per zone (3, 3): nl2 = ||y - g m|| / ||y||; nl2_noise, the nl2 the
    noise of the repeat means alone leaves (what a twin exact to the last
    photon would score: sqrt(kept bins) sigma / ||y||, so a zone whose
    captures hold little object return cannot score below it); nl2_net, the
    twin's own nl2 with the noise's share taken out (the square root of
    `nl2_net_of_noise`, from each capture's repeats, 0 within the noise),
    and nl2_net_interval (3, 3, 2), its bootstrap percentile interval over
    the captures at `calibration.level`, holding the estimate (`calibration.bootstrap_resamples`
    draws from rng; None both, without repeats); and chi2 = mean squared
    noise-weighted residual over the kept bins (1: as close as the noise
    allows). A floor offset's misreading (`Problem.take_floor_offsets`) is
    not in the repeats' noise, so it counts against the twin in nl2_net."""
    r = problem.residuals(x, gains)  # 0 in the bins the captures do not keep
    kept = len(problem.y) * problem.kept[0].sum(axis=1)
    err2 = ((r * problem.sigma[None, :, None]) ** 2).sum(axis=2)  # (N, Z)
    signal2 = (problem.y**2).sum(axis=2)
    nl2 = np.sqrt(err2.sum(axis=0) / signal2.sum(axis=0))
    noise = np.sqrt(kept) * problem.sigma / np.sqrt(signal2.sum(axis=0))
    chi2 = (r**2).transpose(1, 0, 2).reshape(ZONES, -1).sum(axis=1) / np.maximum(kept, 1)
    grid = lambda v: None if v is None else np.where(np.isfinite(v), v, None).reshape(GRID, GRID, *v.shape[1:]).tolist()  # noqa: E731
    net = interval = None
    if problem.noise_energy is not None:
        c, noise2 = problem.settings["calibration"], problem.noise_energy
        root = lambda v: np.sqrt(np.clip(v, 0.0, None))  # noqa: E731
        net = root(nl2_net_of_noise(err2.sum(axis=0), signal2.sum(axis=0), noise2.sum(axis=0)))
        draw = rng.integers(0, len(err2), (c["bootstrap_resamples"], len(err2)))
        boots = nl2_net_of_noise(err2[draw].sum(axis=1), signal2[draw].sum(axis=1), noise2[draw].sum(axis=1))
        tails = (50 * (1 - c["level"]), 50 * (1 + c["level"]))
        q = root(np.stack([np.nanpercentile(b, tails) if np.isfinite(b).any() else [np.nan] * 2 for b in boots.T]))
        interval = np.stack([np.fmin(q[:, 0], net), np.fmax(q[:, 1], net)], axis=1)  # widened to hold the estimate, as `uncertainty`'s
    return {"nl2": grid(nl2), "nl2_noise": grid(noise), "nl2_net": grid(net), "nl2_net_interval": grid(interval), "chi2": grid(chi2)}


def nuisance_fit(problem: Problem, x: np.ndarray) -> np.ndarray:
    """x with only the pulse's shape refitted (the design twin's best showing)."""
    i = slice(3 * ZONES + 1, 3 * ZONES + len(GLOBALS))
    lo, hi = _bounds(problem.settings)

    def r(p):
        y = x.copy()
        y[i] = p
        return problem.residuals(y).ravel()

    out = x.copy()
    out[i] = least_squares(r, x[i], bounds=(lo[i], hi[i]), diff_step=STEP).x
    return out


@dataclass(frozen=True)
class Result:
    x: np.ndarray
    gains: np.ndarray
    before: dict
    after: dict
    se: dict
    interval: dict
    not_identified: dict
    at_bound: list
    x_before: np.ndarray
    gains_before: np.ndarray
    fit: dict


def calibrate(cal: Calibration, specs: dict, captures: Captures, settings: dict, axis: TimeAxis, seed: int) -> tuple[Result, Problem, Problem]:
    """Fit the twin on `captures` (the training split's, on `axis`), holding out
    `calibration.validation_fraction` of them (by capture, seeded) to score
    the fit. Returns the result and the fit and validation problems."""
    c = settings["calibration"]
    n = len(captures.real)
    if n < 3:
        raise ValueError(f"twin calibration: {n} training captures; the fit needs at least 2 and its validation 1")
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    n_val = min(max(int(round(c["validation_fraction"] * n)), 1), n - 2)
    val, train = np.sort(order[:n_val]), np.sort(order[n_val:])
    if c["max_captures"] and len(train) > c["max_captures"]:
        train = np.sort(rng.choice(train, c["max_captures"], replace=False))
    fit_cap, val_cap = captures.subset(train), captures.subset(val)
    problem = Problem(Model(cal, specs, fit_cap.keys, settings, axis), fit_cap, settings)
    held = Problem(Model(cal, specs, val_cap.keys, settings, axis), val_cap, settings)
    x0 = initial(settings)
    for p in (problem, held):
        p.take_floor_offsets(x0)
    x_before = nuisance_fit(problem, x0)
    gains_before = problem.gains(problem.twins(x_before), _unpack(x_before, settings)[-1])
    x, fit_record = fit(problem, x_before, c["max_evaluations"])
    gains = problem.gains(problem.twins(x), _unpack(x, settings)[-1])
    boots = linearised_bootstrap(problem, x, gains, c["bootstrap_resamples"], rng)
    u = uncertainty(x, boots, settings, c["level"])
    result = Result(
        x, gains, zone_residuals(held, x_before, gains_before, rng), zone_residuals(held, x, gains, rng), u.se, u.interval, u.not_identified, u.at_bound,
        x_before, gains_before, fit_record,
    )  # fmt: skip
    return result, problem, held


def capture_jacobian(problem: Problem, x: np.ndarray, gains: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each capture's noise-weighted residuals r (N, Z*T) and their Jacobian
    J (N, Z*T, P + Z) in the fit coordinates x (P) and the zones' gains (Z),
    at (x, gains): forward differences of step STEP as the fit's (backward
    where a bound is within a step), the gains' columns exact."""
    lo, hi = _bounds(problem.settings)
    r0 = problem.residuals(x, gains)
    n, zones, t = r0.shape
    jac = np.zeros((n, zones, t, len(x) + zones))
    for k in range(len(x)):
        h = STEP * max(1.0, abs(x[k]))
        h = -h if x[k] + h > hi[k] else h
        xk = x.copy()
        xk[k] += h
        jac[..., k] = (problem.residuals(xk, gains) - r0) / h
    m = problem.twins(x)
    mix = mixing(_unpack(x, problem.settings)[-1])
    for k in range(zones):
        jac[:, :, :, len(x) + k] = -mix[None, :, k, None] * m[:, k, None] / problem.sigma[None, :, None]
    return r0.reshape(n, -1), jac.reshape(n, zones * t, -1)


def linearised_bootstrap(problem: Problem, x: np.ndarray, gains: np.ndarray, resamples: int, rng: np.random.Generator) -> np.ndarray:
    """(resamples, P) bootstrap estimates in the fit coordinates (unbounded:
    offsets, log scales and times, logit share): x plus each resample's
    `one_step_deviations` from the capture Jacobian at the fit (x, gains).
    To first order this is the refit's estimate (a resample moves the fit by
    O(1/sqrt(N))); it costs one Jacobian for all resamples where refits cost
    one fit each (1.5 min a refit on the demo's 400 captures)."""
    r, jac = capture_jacobian(problem, x, gains)
    lo, hi = _bounds(problem.settings)
    return x + one_step_deviations(r, jac, resamples, rng, hi - lo)[:, : len(x)]


def one_step_deviations(r: np.ndarray, jac: np.ndarray, resamples: int, rng: np.random.Generator, spans: np.ndarray) -> np.ndarray:
    """(resamples, Q) how far a refit on captures drawn with replacement
    moves from the fit, linearised: the Gauss-Newton step on the resample's
    residuals r (N, M) and Jacobian jac (N, M, Q), less the same step on all
    the captures.

    The fit is not at an exact minimum of the full data: it stops at
    `COST_TOLERANCE`, along a valley, or with a coordinate pinned at a bound,
    and there the full data's own Gauss-Newton step can be long. A resample's
    step from the fit carries that step too, so uncentred every resample
    moved the same way, past a bound, and clipped to it (the demo's widths:
    a 90 % interval [3.0, 3.0] deg about 4.14 deg, SE 0). A resample's refit
    would stop short of it as the fit did; its difference from the fit is the
    difference of the two steps. No bound is applied: a deviation is capped
    at its coordinate's whole range (`spans`, (P,) for the first P of Q; the
    gains' are not capped), past which it says no more than that the
    captures leave the coordinate anywhere in it."""
    a = np.einsum("nip,niq->npq", jac, jac)
    b = np.einsum("nip,ni->np", jac, r)
    # Jacobi scaling: the gains' columns are orders of magnitude off the geometry's
    d = np.sqrt(np.maximum(np.diagonal(a.sum(axis=0)), 1e-300))

    def step(w: np.ndarray) -> np.ndarray:
        aw, bw = np.tensordot(w, a, 1) / np.outer(d, d), np.tensordot(w, b, 1) / d
        return np.linalg.lstsq(aw, -bw, rcond=1e-10)[0] / d

    full = step(np.ones(len(r)))
    out = np.array([step(np.bincount(rng.integers(0, len(r), len(r)), minlength=len(r)).astype(float)) - full for _ in range(resamples)])
    cap = np.r_[spans, np.full(out.shape[1] - len(spans), np.inf)]
    return np.clip(out, -cap, cap)


@dataclass(frozen=True)
class Uncertainty:
    """The calibration's uncertainties, physical units (`to_physical`'s
    names and shapes): se, the bootstrap's sd; interval, [low, high] of
    coverage `level` (trailing axis 2), always holding the estimate;
    not_identified, {coordinate name: why} for each coordinate the captures
    do not pin down; at_bound, `at_bound`'s names."""

    se: dict
    interval: dict
    not_identified: dict
    at_bound: list


def uncertainty(x: np.ndarray, boots: np.ndarray, settings: dict, level: float) -> Uncertainty:
    """The uncertainties of the fit x (P,) from bootstrap estimates boots
    (B, P), both in fit coordinates.

    Percentile intervals are taken in the fit coordinates, where every
    coordinate is unbounded, and mapped to physical units through
    `to_physical` (increasing in each coordinate). A coordinate is not
    identified when it is pinned at a bound, when its interval has no width
    (no resample moves it: the captures do not depend on it, as a zone
    whose gain is 0), when its interval misses the estimate (the resamples
    all move one way: the fit is not where the data would put it), or when
    its interval spans more than `IDENTIFIED_SPAN` of its range. An interval
    that misses the estimate is reported widened to hold it, and flagged."""
    lo, hi = _bounds(settings)
    span = hi - lo
    names = coordinate_names(settings)
    tails = (50 * (1 - level), 50 * (1 + level))
    q = np.percentile(boots, tails, axis=0).T  # (P, 2)
    why = dict.fromkeys(at_bound(x, settings), "pinned at a bound of its range: its spread says nothing")
    width = q[:, 1] - q[:, 0]
    for i, n in enumerate(names):
        if width[i] <= 1e-9 * span[i]:
            why.setdefault(n, "its interval has no width: no resample of the captures moves it")
        elif not q[i, 0] <= x[i] <= q[i, 1]:
            why.setdefault(n, "its interval misses the estimate: every resample moves it one way")
        elif width[i] > IDENTIFIED_SPAN * span[i]:
            why.setdefault(n, f"its interval spans {width[i] / span[i]:.0%} of its range (more than {IDENTIFIED_SPAN:.0%})")
    q = np.c_[np.minimum(q[:, 0], x), np.maximum(q[:, 1], x)]
    low, high = to_physical(q[:, 0], settings), to_physical(q[:, 1], settings)
    phys = [to_physical(xb, settings) for xb in boots]
    se = {k: np.std([np.asarray(p[k]) for p in phys], axis=0, ddof=1).tolist() for k in low}
    interval = {k: np.stack([np.asarray(low[k]), np.asarray(high[k])], axis=-1).tolist() for k in low}
    return Uncertainty(se, interval, why, at_bound(x, settings, q))


# --- the file ---------------------------------------------------------------------------


def write_calibration(path: Path, result: Result, settings: dict, record: dict) -> None:
    """twin_calibration.json: the parameters (physical units), their
    bootstrap standard errors and intervals, the gains, the held-out
    residuals before and after, and `record`."""
    phys = to_physical(result.x, settings)
    body = {
        "denali_twin_calibration": CALIBRATION_VERSION,
        "grid": f"{GRID}x{GRID}",
        "material": material_of(settings).kind,
        "object_albedo": float(settings["object_albedo"]),
        "illumination": settings.get("illumination", "spot"),
        # the twin's settings it needs and the fit left alone: under the flood the lobe's width
        "fixed": {"lobe_width_deg": float(settings["retroreflective"]["lobe_width_deg"])},
        "parameters": {k: np.asarray(v).tolist() for k, v in phys.items()},
        "units": {
            "offset_u": "m",
            "offset_v": "m",
            "scale": "x design",
            "time_offset": "bins",
            "pulse_sigma": "bins",
            "pulse_tail": "bins",
            "lobe_width_deg": "deg",
            "diffuse_share": "1",
            **dict(zip(EMISSION, ("deg", "deg", "1", "deg"))),
            GLARE: "1",
        },
        "se": result.se,
        "interval": result.interval,
        "gains": result.gains.reshape(GRID, GRID).tolist(),
        "before": {
            "parameters": {k: np.asarray(v).tolist() for k, v in to_physical(result.x_before, settings).items()},
            "gains": result.gains_before.reshape(GRID, GRID).tolist(),
        },
        "residual": {"before": result.before, "after": result.after},
        "at_bound": result.at_bound,
        "not_identified": result.not_identified,
        "fit": result.fit,
        **record,
    }
    with atomic_file(Path(path)) as tmp:
        tmp.write_text(json.dumps(body, indent=1) + "\n")


def read_calibration(path: Path) -> Fitted:
    """twin_calibration.json -> Fitted; ValueError naming the file when it is not one."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
        if d.get("denali_twin_calibration") != CALIBRATION_VERSION:
            raise ValueError(f"version {d.get('denali_twin_calibration')!r}, expected {CALIBRATION_VERSION}")
        p = d["parameters"]
        offsets = np.stack([np.asarray(p["offset_u"], float), np.asarray(p["offset_v"], float)], axis=-1)
        lobe = {**d["fixed"], **{k: p[k] for k in ("lobe_width_deg", "diffuse_share") if k in p}}
        material = material_of({"material": d["material"], "object_albedo": d["object_albedo"], "retroreflective": lobe})
        pulse_of = Pulse(*(float(p[k]) for k in PULSE))
        emission = None
        if d["illumination"] == "flood":
            emission = Emission((float(p["beam_hwhm_h_deg"]), float(p["beam_hwhm_v_deg"])), float(p["core_share"]), float(p["core_hwhm_deg"]))
        return Fitted(
            offsets, np.asarray(p["scale"], float), float(p["time_offset"]), pulse_of, np.asarray(d["gains"], float), material, d["illumination"], emission,
            float(p[GLARE]),
        )  # fmt: skip
    except (OSError, KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a twin calibration ({type(e).__name__}: {e})") from None


@dataclass(frozen=True)
class FitStatus:
    """How twin_calibration.json's fit ended: the coordinates pinned at a
    bound (`at_bound`'s names), how many coordinates it fitted, and whether
    it converged within `twin.calibration.max_evaluations` (evaluations used)."""

    at_bound: tuple[str, ...]
    n_coordinates: int
    converged: bool
    evaluations: int


def read_fit_status(path: Path) -> FitStatus:
    """twin_calibration.json's `FitStatus`; ValueError naming the file when it is not a calibration."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
        if d.get("denali_twin_calibration") != CALIBRATION_VERSION:
            raise ValueError(f"version {d.get('denali_twin_calibration')!r}, expected {CALIBRATION_VERSION}")
        n = sum(int(np.size(v)) for v in d["parameters"].values())
        return FitStatus(tuple(str(a) for a in d["at_bound"]), n, bool(d["fit"]["converged"]), int(d["fit"]["evaluations"]))
    except (OSError, KeyError, TypeError, ValueError) as e:
        raise ValueError(f"{path}: not a twin calibration ({type(e).__name__}: {e})") from None
