"""Renderer `mitransient`: transient path tracing of the twin with
mitransient's `transient_nlos_path` (laser sampling + hidden-geometry
sampling), on `llvm_ad_rgb` on CPU or `cuda_ad_rgb` on a GPU.

One Mitsuba scene per (object, size) and relay patch (each zone's
footprint is its own relay rectangle and film): the object's mesh is moved
between locations by rewriting its vertex buffer, so the kernels compile
once per scene and spp. The histograms are the radiance of the patches'
pixels in the analytic renderer's units (see `twin.scene`), averaged over RGB.

With table tops in the scene:
- mitransient's hidden-geometry sampling picks a point on a hidden shape and
  continues the path toward it even when another shape hides it, so an
  object standing in front of a table is counted once more per shape behind
  it. `TABLE_SAFE_INTEGRATOR` adds the missing visibility test, gives the
  object a fixed share of the samples (by area, the tables would take ~99 %)
  and limits that sampling to the wall vertex (deeper, it gives spiky noise
  from the 2 mm object-table contact);
- the tables' own three-bounce return is removed by rendering the same seed
  with the object moved far behind the wall (same random numbers, so the
  noise of the two renders largely cancels) and subtracting. Differences are
  kept signed: clipping would bias the mean.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from denali_pipe.core.seeds import derive_seed
from denali_pipe.twin.illumination import check_renderer
from denali_pipe.twin.layout import TwinScene
from denali_pipe.twin.scene import transient_scene
from denali_pipe.twin.variant import load_mitsuba

TABLE_SAFE_INTEGRATOR = "denali_transient_nlos_path"
OBJECT_SHARE = 0.5  # fraction of hidden-geometry samples spent on the object when tables are present
AWAY_M = 5.0  # how far behind the wall the object goes for the wall-and-table-only render
VERTICES = "object.vertex_positions"
_registered: set[str] = set()  # variants with TABLE_SAFE_INTEGRATOR registered


def _register_table_safe_integrator(mi: ModuleType) -> None:
    """Register TABLE_SAFE_INTEGRATOR for the current variant (once)."""
    import drjit as dr
    from mitransient.integrators.transientnlospath import TransientNLOSPath

    if mi.variant() in _registered:
        return

    class TableSafeNLOSPath(TransientNLOSPath):
        def prepare(self, scene, sensor, seed, spp, aovs):
            samplers = super().prepare(scene, sensor, seed, spp, aovs)
            # the same shape order as the base class's distribution, reweighted
            shapes = scene.shapes()
            relay = sensor.get_shape()
            order = np.asarray(self.hidden_geometry_shape_indices, dtype=np.int64)
            hidden = [shapes[i] for i in order]
            others = sum(s.surface_area()[0] for s in hidden if s.id() != "object" and s != relay)
            weights = [0.0 if s == relay else OBJECT_SHARE if s.id() == "object" else (1 - OBJECT_SHARE) * s.surface_area()[0] / others for s in hidden]
            self.hidden_geometries_distribution = mi.DiscreteDistribution(weights)
            return samplers

        def hidden_geometry_sample(self, scene, sampler, bsdf, bsdf_ctx, si, _, sample2, active):
            ps = self._sample_hidden_geometry_position(ref=si, scene=scene, sample2=sample2, active=active)
            d = mi.Vector3f(ps.p - si.p)
            dist = dr.norm(d)
            d /= dist
            cos_g = dr.dot(ps.n, -d)
            active = active & (dr.dot(si.n, d) > dr.epsilon(mi.Float)) & (cos_g > dr.epsilon(mi.Float))
            # the sampled point must be the first surface along d, or its density does not apply
            active &= ~scene.ray_test(si.spawn_ray_to(ps.p), active)
            wo = si.to_local(d)
            value = bsdf.eval(ctx=bsdf_ctx, si=si, wo=wo, active=active)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            bs.pdf = ps.pdf * dr.square(dist) / dr.abs(cos_g)
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.Reflection)
            bs.sampled_component = 0
            active &= bs.pdf > dr.epsilon(mi.Float)
            return bs, dr.select(active, value / bs.pdf, 0.0)

    mi.register_integrator(TABLE_SAFE_INTEGRATOR, lambda props: TableSafeNLOSPath(props))
    _registered.add(mi.variant())


class MitransientRenderer:
    """`render(location)` -> (film, film, N_BINS) float64 transient per pixel.

    spp: samples per film pixel; max_depth: mitransient's path depth (3 =
    wall-object-wall only); seed: base seed, each location renders with
    derive_seed(seed, location); variant: see `variant.load_mitsuba`."""

    name = "mitransient"

    def __init__(self, twin: TwinScene, spp: int, max_depth: int, seed: int, variant: str = "auto"):
        check_renderer(self.name, "spot" if twin.flood is None else "flood")
        self.mi = mi = load_mitsuba(variant)
        self.twin, self.spp, self.seed = twin, int(spp), int(seed)
        integrator = "transient_nlos_path"
        if twin.tables:
            _register_table_safe_integrator(mi)
            integrator = TABLE_SAFE_INTEGRATOR
        self.scenes = []
        for relay in twin.relays:
            scene = transient_scene(mi, twin, relay, max_depth, integrator, min(twin.poses))
            if twin.tables:
                scene["integrator"]["nlos_hidden_geometry_sampling_max_depth"] = 1
            loaded = mi.load_dict(scene)
            self.scenes.append((loaded, mi.traverse(loaded)))
        self.away = -twin.relays[0].normal * AWAY_M  # behind the wall, where nothing reaches the footprint

    def _transient(self, zone: int, vertices: np.ndarray, seed: int) -> np.ndarray:
        scene, params = self.scenes[zone]
        params[VERTICES] = self.mi.Float(np.asarray(vertices, np.float32).ravel())
        params.update()
        _, transient = scene.integrator().render(scene, scene.sensors()[0], seed=seed, spp=self.spp)
        return np.asarray(transient, dtype=np.float64).mean(axis=-1)  # (H, W, T, RGB) -> (H, W, T)

    def render(self, location: int) -> np.ndarray:
        """(zones, film, film, N_BINS): every relay patch's pixels at `location`."""
        vertices = self.twin.poses[location].apply(self.twin.vertices)
        out = []
        for zone in range(len(self.scenes)):
            seed = derive_seed(self.seed, location, zone) % 2**32
            h = self._transient(zone, vertices, seed)
            if self.twin.tables:
                h = h - self._transient(zone, vertices + self.away, seed)
            out.append(h)
        return np.stack(out)
