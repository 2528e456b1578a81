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

Units: radiance per unit laser intensity, per bin; the mitransient renderer
gives the same numbers (its projector is set to unit intensity).
"""

from __future__ import annotations

import numpy as np

from denali_pipe import geometry as geo
from denali_pipe.meshes import front_samples
from denali_pipe.twin.layout import Material, TwinScene, pixel_centres

FILTERS = ("box", "tent")


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
        self.set_relays(twin.relays)

    def set_relays(self, relays) -> None:
        """Render onto these patches from now on (same film): the calibration moves them."""
        self.relays = tuple(relays)
        self.x = np.concatenate([pixel_centres(r, self.twin.film).reshape(-1, 3) for r in self.relays])
        self.r_xs = np.linalg.norm(self.x - self.twin.sensor, axis=1)
        self.xx = np.einsum("pk,pk->p", self.x, self.x)

    def object_terms(self, location: int) -> tuple:
        """What a location's render needs that no relay patch changes:
        points o (N, 3), normal n_o (3,), unit directions to the spot (N, 3),
        |p - o| (N,), irradiance x area (N,)."""
        tw = self.twin
        pose = tw.poses[location]
        o = pose.apply(self.points)
        n_o = pose.R @ np.array([0.0, 0.0, -1.0])  # the face's normal, toward the wall
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
        o, n_o, to_spot, r_po, flux_o = terms if terms is not None else self.object_terms(location)
        # o -> x terms as (P, N) outer expressions: no (P, N, 3) temporaries
        r2 = self.xx[:, None] - 2 * (self.x @ o.T) + np.einsum("nk,nk->n", o, o)[None, :]
        r_ox = np.sqrt(r2)
        along_o = (self.x @ n_o)[:, None] - (o @ n_o)[None, :]  # (x - o) . n_o = |x - o| cos_o'
        along_x = (o @ self.nw)[None, :] - (self.x @ self.nw)[:, None]  # -(x - o) . n_w = |x - o| cos_x
        if material.kind == "lambertian":
            f = material.albedo / np.pi
        else:  # cos of the angle between w_o = (x - o)/|x - o| and w_i (toward the spot)
            f = brdf(material, ((self.x @ to_spot.T) - np.einsum("nk,nk->n", o, to_spot)[None, :]) / r_ox)
        w = tw.wall_albedo / np.pi * flux_o[None, :] * f * np.clip(along_o, 0, None) * np.clip(along_x, 0, None) / r2**2
        opl = self.r_xs[:, None] + r_ox + (r_po + self.r_sp + tw.time_offset_opl)[None, :]
        return _bin(opl, w, self.filter).reshape(len(self.relays), tw.film, tw.film, geo.N_BINS)


def _bin(opl: np.ndarray, weight: np.ndarray, filter: str = "box") -> np.ndarray:
    """Weights (P, N) at sensor-relative paths opl (P, N) into (P, N_BINS),
    box filtered (into the bin holding the path) or tent filtered (shared
    between the two bin centres around it, linearly)."""
    p = opl.shape[0]
    pos = geo.opl_to_bin(opl)
    rows = np.arange(p)[:, None] * geo.N_BINS
    if filter == "box":
        parts = [(np.floor(pos).astype(np.int64), weight)]
    else:
        c = pos - 0.5  # in units of bin centres
        b = np.floor(c)
        frac = c - b
        parts = [(b.astype(np.int64), weight * (1 - frac)), (b.astype(np.int64) + 1, weight * frac)]
    out = np.zeros(p * geo.N_BINS)
    for b, wt in parts:
        keep = (b >= 0) & (b < geo.N_BINS) & (wt > 0)
        out += np.bincount((rows + b)[keep], wt[keep], p * geo.N_BINS)
    return out.reshape(p, geo.N_BINS)
