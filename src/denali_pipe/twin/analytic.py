"""Renderer `analytic`: the twin's three-bounce transient in closed form.

Path: laser at the sensor s -> spot p on the wall -> object point o -> film
pixel centre x on the wall -> sensor. With Lambertian wall (albedo rho_w) and
object (rho_o) and a laser of unit radiant intensity, the radiance leaving x
toward the sensor is

    L(x) = rho_w/pi  sum_o  A_o  L_o  cos_o' cos_x / |o - x|^2
    L_o  = rho_o/pi  E_o,   E_o = L_p cos_p cos_o / |p - o|^2
    L_p  = rho_w/pi  cos_l / |s - p|^2

(cos_l at p toward the laser, cos_p/cos_o at p/o along p-o, cos_o'/cos_x at
o/x along o-x; the spot counts as one unit of area, as in mitransient's laser
sampling). Each term lands in the bin of its sensor-relative optical path
|s - p| + |p - o| + |o - x| + |x - s| (a box filter, as the mitransient
renderer's). The object is quadrature points on its wall-facing face
(`meshes.front_samples`); a plane plate cannot shadow itself and nothing
else is in the scene, so the sum is exact up to quadrature.

Units: radiance per unit laser intensity, per bin; the mitransient renderer
gives the same numbers (its projector is set to unit intensity).
"""

from __future__ import annotations

import numpy as np

from denali_pipe import geometry as geo
from denali_pipe.meshes import front_samples
from denali_pipe.twin.layout import TwinScene, pixel_centres


class AnalyticRenderer:
    """`render(location)` -> (film, film, N_BINS) float64 transient per pixel.

    samples: quadrature points across the object's largest dimension."""

    name = "analytic"

    def __init__(self, twin: TwinScene, samples: int):
        if twin.tables:
            raise ValueError("the analytic renderer has no table (object-table interreflections): set twin.table false or use renderer mitransient")
        self.twin = twin
        extent = np.ptp(twin.vertices[:, :2], axis=0).max()
        self.points, self.area = front_samples(twin.mesh, extent / samples)
        self.x = pixel_centres(twin.relay, twin.film).reshape(-1, 3)
        nw = twin.relay.normal
        d_sp = twin.spot - twin.sensor
        self.r_sp = float(np.linalg.norm(d_sp))
        cos_l = float(-(d_sp @ nw) / self.r_sp)
        self.radiance_spot = twin.wall_albedo / np.pi * cos_l / self.r_sp**2
        self.r_xs = np.linalg.norm(self.x - twin.sensor, axis=1)
        self.xx = np.einsum("pk,pk->p", self.x, self.x)

    def render(self, location: int) -> np.ndarray:
        tw = self.twin
        pose = tw.poses[location]
        o = pose.apply(self.points)  # (N, 3)
        n_o = pose.R @ np.array([0.0, 0.0, -1.0])  # the face's normal, toward the wall
        nw = tw.relay.normal
        d_po = o - tw.spot
        r_po = np.linalg.norm(d_po, axis=1)
        cos_p = (d_po @ nw) / r_po
        cos_o = -(d_po @ n_o) / r_po
        e_o = self.radiance_spot * np.clip(cos_p, 0, None) * np.clip(cos_o, 0, None) / r_po**2
        flux_o = tw.object_albedo / np.pi * e_o * self.area  # radiance x area, (N,)

        # o -> x terms as (P, N) outer expressions: no (P, N, 3) temporaries
        r2 = self.xx[:, None] - 2 * (self.x @ o.T) + np.einsum("nk,nk->n", o, o)[None, :]
        r_ox = np.sqrt(r2)
        along_o = (self.x @ n_o)[:, None] - (o @ n_o)[None, :]  # (x - o) . n_o = |x - o| cos_o'
        along_x = (o @ nw)[None, :] - (self.x @ nw)[:, None]  # -(x - o) . n_w = |x - o| cos_x
        w = tw.wall_albedo / np.pi * flux_o[None, :] * np.clip(along_o, 0, None) * np.clip(along_x, 0, None) / r2**2
        opl = self.r_xs[:, None] + r_ox + (r_po + self.r_sp)[None, :]
        return _bin(opl, w).reshape(tw.film, tw.film, geo.N_BINS)


def _bin(opl: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Box-filter weights (P, N) at sensor-relative paths opl (P, N) into (P, N_BINS)."""
    p = opl.shape[0]
    b = np.floor(geo.opl_to_bin(opl)).astype(np.int64)
    keep = (b >= 0) & (b < geo.N_BINS) & (weight > 0)
    idx = (np.arange(p)[:, None] * geo.N_BINS + b)[keep]
    return np.bincount(idx, weight[keep], p * geo.N_BINS).reshape(p, geo.N_BINS)
