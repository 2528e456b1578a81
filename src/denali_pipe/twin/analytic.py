"""Renderer `analytic`: the twin's three-bounce transient in closed form.

Path: laser at the sensor s -> spot p on the wall -> object point o -> film
pixel centre x on the wall -> sensor. With a Lambertian wall (albedo rho_w),
an object of BRDF f_o and a laser of unit radiant intensity, the radiance
leaving x toward the sensor is

    L(x) = rho_w/pi  sum_o  A_o  L_o(o -> x)  cos_o' cos_x / |o - x|^2
    L_o  = f_o(w_i, w_o)  E_o,   E_o = L_p cos_p cos_o / |p - o|^2
    L_p  = rho_w/pi  cos_l / |s - p|^2

(cos_l at p toward the laser, cos_p/cos_o at p/o along p-o, cos_o'/cos_x at
o/x along o-x; w_i, w_o the unit directions from o to p and to x; the spot
counts as one unit of area, as in mitransient's laser sampling). f_o is
rho_o/pi (Lambertian), or for retroreflective sheeting
rho_o [d/pi + (1 - d) exp(-theta^2 / 2 sigma^2) / (2 pi sigma^2)] with
theta the angle between w_i and w_o (`layout.Material`; the lobe holds
(1 - d) rho_o cos_i of the light for sigma well below a radian). Each term
lands in the bin of its sensor-relative optical path
|s - p| + |p - o| + |o - x| + |x - s| plus the twin's time offset, with a
box filter (as the mitransient renderer's) or a tent filter (`filter`:
linear between the two nearest bin centres, same mean; the calibration's
fit needs a model that moves smoothly with the geometry). The object is
quadrature points on its wall-facing face (`meshes.front_samples`); a
plane plate cannot shadow itself and nothing else is in the scene, so the
sum is exact up to quadrature.

Under the sensor's flood (`TwinScene.flood`) every lit wall point p is a
spot of its own, weighted by the light the emission sends it (the flood
lobe's grid points and the core's one spot, `layout.Flood.lit`); light
transport is linear, so the render is the sum over them, with two
reductions that keep its cost near one spot's:

- the Lambertian part (all of a Lambertian object, the share d of the
  sheeting) sees the lit wall through its irradiance E_o, summed over the
  flood's points; each object point's paths from the laser to it are
  placed at their irradiance-weighted mean |s - p| + |p - o|, and the
  spread of that first leg about its mean is put back as one kernel per
  location (the object points' spreads pooled, weighted by the light each
  receives);
- the retroreflective lobe is taken in its narrow limit: sheeting returns
  light within ~1 deg of where it came from (ASTM E810's observation
  angles), under which the emission and the wall vary little, so
  L_o(o -> x) = (1 - d) rho_o cos_o' L_p(x): the object sends back to
  each wall point x the light x sent it, along 2 |s - x| + 2 |x - o|. The
  lobe's width then drops out. A film pixel's light is the emission's mean
  over the pixel (`layout.Flood.pixel_intensity`): the core can be narrower
  than a pixel.

Units: radiance per unit laser intensity (the flood's: on its axis), per
bin; with the spot, the mitransient renderer gives the same numbers (its
projector is set to unit intensity).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.ndimage import convolve1d

from denali_pipe.core import geometry as geo
from denali_pipe.core.meshes import front_samples
from denali_pipe.twin.layout import Flood, Material, TwinScene, pixel_centres

FILTERS = ("box", "tent")
# Half width (bins) of the flood's first-leg spread kernel. On the demo's
# scene the lit wall's first legs spread with an sd of 0.6-1.6 bins about
# their mean (beam 7 x 5 to 26 x 20 deg); none of their light falls beyond 16.
SPREAD_BINS = 16


def brdf(material: Material, cos_theta: np.ndarray) -> np.ndarray:
    """The object's BRDF (1/sr) at cos_theta, the cosine of the angle between
    the incident and outgoing directions (any shape)."""
    if material.kind == "lambertian":
        return np.full_like(cos_theta, material.albedo / np.pi)
    sigma = np.deg2rad(material.lobe_width_deg)
    theta = np.arccos(np.clip(cos_theta, -1.0, 1.0))
    lobe = np.exp(-(theta**2) / (2 * sigma**2)) / (2 * np.pi * sigma**2)
    return material.albedo * (material.diffuse_share / np.pi + (1 - material.diffuse_share) * lobe)


class AnalyticRenderer:
    """`render(location)` -> (zones, film, film, N_BINS) float64 transient
    per pixel of each relay patch of the twin.

    samples: quadrature points across the object's largest dimension;
    filter: `box` or `tent` (see the module)."""

    name = "analytic"

    def __init__(self, twin: TwinScene, samples: int, filter: str = "box"):
        if twin.tables:
            raise ValueError("the analytic renderer has no table (object-table interreflections): set twin.table false or use renderer mitransient")
        if filter not in FILTERS:
            raise ValueError(f"unknown filter {filter!r}; expected one of {FILTERS}")
        self.twin, self.filter = twin, filter
        extent = np.ptp(twin.vertices[:, :2], axis=0).max()
        self.points, self.area = front_samples(twin.mesh, extent / samples)
        self.nw = twin.relays[0].normal
        d_sp = twin.spot - twin.sensor
        self.r_sp = float(np.linalg.norm(d_sp))
        cos_l = float(-(d_sp @ self.nw) / self.r_sp)
        self.radiance_spot = twin.wall_albedo / np.pi * cos_l / self.r_sp**2
        self.relays = tuple(twin.relays)
        self.set_light(twin.flood)

    def set_light(self, flood: Flood | None) -> None:
        """Light the wall with `flood` from now on (None: the spot alone):
        the calibration changes the emission, not the object's quadrature."""
        tw = self.twin = dataclasses.replace(self.twin, flood=flood)
        if flood is not None:
            self.lit, solid = flood.lit()
            self.r_lit = np.linalg.norm(self.lit - tw.sensor, axis=1)
            self.power_lit = tw.wall_albedo / np.pi * solid  # radiance x area of each lit spot
        self.set_relays(self.relays)

    def set_relays(self, relays) -> None:
        """Render onto these patches from now on (same film): the calibration moves them."""
        tw = self.twin
        self.relays = tuple(relays)
        self.x = np.concatenate([pixel_centres(r, tw.film).reshape(-1, 3) for r in self.relays])
        self.r_xs = np.linalg.norm(self.x - tw.sensor, axis=1)
        self.xx = np.einsum("pk,pk->p", self.x, self.x)
        if tw.flood is not None:  # each film pixel's radiance under the flood: its mean emission, lit at its centre
            emission = np.concatenate([tw.flood.pixel_intensity(r, tw.film).reshape(-1) for r in self.relays])
            cos_l = ((tw.sensor - self.x) @ self.nw) / self.r_xs
            self.radiance_x = tw.wall_albedo / np.pi * emission * np.clip(cos_l, 0, None) / self.r_xs**2

    def object_terms(self, location: int) -> tuple:
        """What a location's render needs that no relay patch changes:
        points o (N, 3), normal n_o (3,), then with the spot the unit
        directions to it (N, 3), |p - o| (N,) and irradiance x area (N,);
        with the flood the irradiance x area (N,), the mean first leg
        |s - p| + |p - o| (N,) m and the legs' spread about it, a kernel
        (2 SPREAD_BINS + 1,) summing to 1."""
        tw = self.twin
        pose = tw.poses[location]
        o = pose.apply(self.points)
        n_o = pose.R @ np.array([0.0, 0.0, -1.0])  # the face's normal, toward the wall
        if tw.flood is not None:
            d = o[:, None, :] - self.lit[None, :, :]  # (N, M, 3)
            r = np.linalg.norm(d, axis=2)
            cos_p, cos_o = (d @ self.nw) / r, -(d @ n_o) / r
            e = self.power_lit[None, :] * np.clip(cos_p, 0, None) * np.clip(cos_o, 0, None) / r**2
            e_o = e.sum(axis=1)
            leg = r + self.r_lit[None, :]
            lead = (e * leg).sum(axis=1) / np.maximum(e_o, 1e-300)
            spread = _bin((leg - lead[:, None]).reshape(1, -1), (e * self.area[:, None]).reshape(1, -1), tw.time_axis, "tent", SPREAD_BINS)[0]
            return o, n_o, e_o * self.area, lead, spread / max(spread.sum(), 1e-300)
        d_po = o - tw.spot
        r_po = np.linalg.norm(d_po, axis=1)
        cos_p = (d_po @ self.nw) / r_po
        cos_o = -(d_po @ n_o) / r_po
        e_o = self.radiance_spot * np.clip(cos_p, 0, None) * np.clip(cos_o, 0, None) / r_po**2
        return o, n_o, -d_po / r_po[:, None], r_po, e_o * self.area

    def render(self, location: int, material: Material | None = None, terms: tuple | None = None) -> np.ndarray:
        """The transient of every pixel; `material` overrides the twin's,
        `terms` reuses `object_terms(location)`."""
        tw = self.twin
        material = material or tw.material
        terms = terms if terms is not None else self.object_terms(location)
        o, n_o = terms[:2]
        # o -> x terms as (P, N) outer expressions: no (P, N, 3) temporaries
        r2 = self.xx[:, None] - 2 * (self.x @ o.T) + np.einsum("nk,nk->n", o, o)[None, :]
        r_ox = np.sqrt(r2)
        along_o = np.clip((self.x @ n_o)[:, None] - (o @ n_o)[None, :], 0, None)  # (x - o) . n_o = |x - o| cos_o'
        along_x = np.clip((o @ self.nw)[None, :] - (self.x @ self.nw)[:, None], 0, None)  # -(x - o) . n_w = |x - o| cos_x
        if tw.flood is not None:
            return self._render_flood(material, terms, r2, r_ox, along_o, along_x)
        _, _, to_spot, r_po, flux_o = terms
        if material.kind == "lambertian":
            f = material.albedo / np.pi
        else:  # cos of the angle between w_o = (x - o)/|x - o| and w_i (toward the spot)
            f = brdf(material, ((self.x @ to_spot.T) - np.einsum("nk,nk->n", o, to_spot)[None, :]) / r_ox)
        w = tw.wall_albedo / np.pi * flux_o[None, :] * f * along_o * along_x / r2**2
        opl = self.r_xs[:, None] + r_ox + (r_po + self.r_sp + tw.time_offset_opl)[None, :]
        return _bin(opl, w, tw.time_axis, self.filter).reshape(len(self.relays), tw.film, tw.film, geo.N_BINS)

    def _render_flood(self, material: Material, terms: tuple, r2, r_ox, along_o, along_x) -> np.ndarray:
        """The flood's render (module docstring) from the (P, N) o -> x terms."""
        tw = self.twin
        _, _, flux_o, lead, spread = terms
        share = material.diffuse_share if material.kind == "retroreflective" else 1.0
        geometry = tw.wall_albedo / np.pi * along_o * along_x / r2**2  # rho_w/pi cos_o' cos_x / |x - o|^2
        opl = self.r_xs[:, None] + r_ox + (lead + tw.time_offset_opl)[None, :]
        out = _bin(opl, geometry * (share * material.albedo / np.pi) * flux_o[None, :], tw.time_axis, self.filter)
        out = convolve1d(out, spread, axis=1, mode="constant")
        if share < 1:
            back = geometry * ((1 - share) * material.albedo * self.area)[None, :] * (along_o / r_ox) * self.radiance_x[:, None]
            out += _bin(2 * (self.r_xs[:, None] + r_ox) + tw.time_offset_opl, back, tw.time_axis, self.filter)
        return out.reshape(len(self.relays), tw.film, tw.film, geo.N_BINS)


def _bin(opl: np.ndarray, weight: np.ndarray, axis: geo.TimeAxis, filter: str = "box", centred: int | None = None) -> np.ndarray:
    """Weights (P, N) at sensor-relative paths opl (P, N, m) into (P, N_BINS)
    of `axis`, box filtered (into the bin holding the path) or tent filtered
    (shared between the two bin centres around it, linearly). With
    `centred`, opl are path differences binned into 2 centred + 1 bins of
    the axis's width about 0 instead."""
    p = opl.shape[0]
    pos = axis.opl_to_bin(opl) if centred is None else opl / axis.bin_width_opl + centred + 0.5
    n_bins = geo.N_BINS if centred is None else 2 * centred + 1
    rows = np.arange(p)[:, None] * n_bins
    if filter == "box":
        parts = [(np.floor(pos).astype(np.int64), weight)]
    else:
        c = pos - 0.5  # in units of bin centres
        b = np.floor(c)
        frac = c - b
        parts = [(b.astype(np.int64), weight * (1 - frac)), (b.astype(np.int64) + 1, weight * frac)]
    out = np.zeros(p * n_bins)
    for b, wt in parts:
        keep = (b >= 0) & (b < n_bins) & (wt > 0)
        out += np.bincount((rows + b)[keep], wt[keep], p * n_bins)
    return out.reshape(p, n_bins)
