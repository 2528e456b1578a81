"""The object's BSDF in Mitsuba: `diffuse`, or the retroreflective lobe of
`layout.Material` as a Python plugin (`RETROREFLECTIVE`, registered per
variant on first use).

The plugin's BRDF is the analytic renderer's (`analytic.brdf`):
rho [d/pi + (1 - d) exp(-theta^2 / 2 sigma^2) / (2 pi sigma^2)], theta the
angle between the incident and outgoing directions. It is symmetric in the
two, as reciprocity asks. Sampling is cosine-weighted over the hemisphere:
the NLOS integrator reaches the object through hidden-geometry and laser
sampling, which call `eval` only, so sampling efficiency does not matter.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from denali_pipe.twin.layout import Material

RETROREFLECTIVE = "denali_retroreflective"
_registered: set[str] = set()  # variants with RETROREFLECTIVE registered


def register_retroreflective(mi: ModuleType) -> None:
    """Register RETROREFLECTIVE for the current Mitsuba variant (once)."""
    import drjit as dr

    if mi.variant() in _registered:
        return

    class RetroreflectiveBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.albedo = float(props["albedo"])
            self.sigma = float(np.deg2rad(props["lobe_width_deg"]))
            self.diffuse_share = float(props["diffuse_share"])
            flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def _value(self, si, wo, active):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            theta = dr.acos(dr.clip(dr.dot(si.wi, wo), -1.0, 1.0))
            lobe = dr.exp(-dr.square(theta) / (2 * self.sigma**2)) / (2 * dr.pi * self.sigma**2)
            f = self.albedo * (self.diffuse_share / dr.pi + (1 - self.diffuse_share) * lobe)
            ok = active & (cos_i > 0) & (cos_o > 0)
            return dr.select(ok, f * cos_o, 0.0), ok

        def sample(self, ctx, si, sample1, sample2, active):
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = 0
            value, ok = self._value(si, bs.wo, active)
            ok &= bs.pdf > 0
            return bs, mi.Color3f(dr.select(ok, value / bs.pdf, 0.0))

        def eval(self, ctx, si, wo, active):
            return mi.Color3f(self._value(si, wo, active)[0])

        def pdf(self, ctx, si, wo, active):
            ok = active & (mi.Frame3f.cos_theta(si.wi) > 0)
            return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"RetroreflectiveBSDF[albedo={self.albedo}, sigma={self.sigma} rad, diffuse_share={self.diffuse_share}]"

    mi.register_bsdf(RETROREFLECTIVE, lambda props: RetroreflectiveBSDF(props))
    _registered.add(mi.variant())


def object_bsdf(mi: ModuleType, material: Material) -> dict:
    """The Mitsuba BSDF dict of the object's material."""
    if material.kind == "lambertian":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [material.albedo] * 3}}
    register_retroreflective(mi)
    return {"type": RETROREFLECTIVE, "albedo": material.albedo, "lobe_width_deg": material.lobe_width_deg, "diffuse_share": material.diffuse_share}
