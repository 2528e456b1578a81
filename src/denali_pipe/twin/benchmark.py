"""Cost vs fidelity of the twin's renderers on a fixed sample of scenes.

Every configuration renders every zone's transient of the 3x3 grid for the
same scenes (object, size, gantry location); its error per zone is the
normalised L2 distance ||h - h_ref|| / ||h_ref|| to a converged reference
(mitransient over each zone's footprint patch at `reference_spp`), in the
common units of both renderers, so no scale is fitted. Configurations (the
`twin.benchmark` config):

- `paper`: the paper's film, 64x64 pixels over the whole wall at
  `paper_spp`, averaged over the 8x8 block of pixels centred on the
  centre zone's footprint (the reference twin's readout; the centre zone
  only). The block (~12 x 8 cm) is smaller than the footprint, so its error
  is mostly that patch mismatch;
- `paper, footprint pixels`: the same renders averaged over every pixel
  whose centre falls in each zone's footprint instead (~180 pixels a zone):
  what the paper's film gives at best. Its error is noise plus the
  difference between its sampling of the patch and the zone film's;
- `footprint <spp>`: each zone's relay surface is its footprint patch
  itself, with the configured film, at each of `footprint_spp`;
- `analytic`: the closed-form three-bounce model (scenes without a table).

Every configuration is lit by the paper's one laser spot whatever
`twin.illumination` says: mitransient's NLOS integrator traces from one
laser point, and the flood the analytic twin renders is a sum of such
spots (`twin.analytic`), so the spot's formula is what the reference checks.

A configuration's error is the mean over its zones and scenes; the
per-zone means are the summary's `error_zone_<row><col>` columns.

Scenes come in groups of SCENES_PER_OBJECT locations of one (object, size),
as a twin job renders many locations of one scene: the first render of a
group also compiles its kernels, so time per scene is the median over the
other renders, and the first renders' mean is reported apart. Seeds differ
per configuration, so their noise is independent of the reference's.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from denali_pipe.core.geometry import Rect, TimeAxis
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.core.seeds import derive_seed, rng_for
from denali_pipe.twin.layout import Calibration, material_of, pixels_inside, twin_scene, zone_footprints
from denali_pipe.twin.render import make_renderer

log = logging.getLogger(__name__)

PAPER_FILM = 64  # the paper's whole-wall film, pixels per side
PAPER_BLOCK = 8  # the reference twin averages an 8 x 8 block of it
SCENES_PER_OBJECT = 4  # locations per (object, size) group of scenes
GRID = 3  # the benchmark's zone grid
CENTRE_ZONE = GRID * GRID // 2


@dataclass(frozen=True)
class Scene:
    spec: ObjectSpec
    size: str
    location: int

    @property
    def label(self) -> str:
        return f"{self.spec.name}_{self.size}@{self.location}"


@dataclass(frozen=True)
class Configuration:
    """name; renderer (`analytic` or `mitransient`); film: `footprint` or
    `wall`; spp (None for analytic)."""

    name: str
    renderer: str
    film: str
    spp: int | None


def centre_block(relay: Rect, film: int, centre: np.ndarray, n: int) -> np.ndarray:
    """(film, film) bool: the n x n block of pixels centred nearest `centre`."""
    rel = centre - relay.centre
    col = (rel @ relay.u / relay.size[0] + 0.5) * film - 0.5  # fractional pixel index of the centre
    row = (rel @ relay.v / relay.size[1] + 0.5) * film - 0.5
    c0, r0 = (int(np.clip(round(x - (n - 1) / 2), 0, film - n)) for x in (col, row))
    mask = np.zeros((film, film), bool)
    mask[r0 : r0 + n, c0 : c0 + n] = True
    return mask


def benchmark_scenes(specs: list[ObjectSpec], sizes: list[str], locations: list[int], n: int, seed: int) -> list[Scene]:
    """`n` scenes in groups of SCENES_PER_OBJECT distinct locations of one
    (object, size): pairs in a seeded random order (cycled if needed),
    locations drawn with the same seed."""
    pairs = [(s, size) for s in specs for size in s.sizes if size in sizes]
    if not pairs or not locations:
        raise ValueError(f"no scene to benchmark: {len(pairs)} object sizes, {len(locations)} locations")
    rng = rng_for(seed, "render_benchmark")
    order = [pairs[i] for i in rng.permutation(len(pairs))]
    per = min(SCENES_PER_OBJECT, len(locations))
    scenes = []
    for g in range(-(-n // per)):
        spec, size = order[g % len(order)]
        picks = rng.choice(np.asarray(locations), size=per, replace=False)
        scenes += [Scene(spec, size, int(k)) for k in picks]
    return scenes[:n]


def configurations(bench: dict, with_analytic: bool) -> list[Configuration]:
    configs = [Configuration("paper", "mitransient", "wall", int(bench["paper_spp"]))]
    configs += [
        Configuration(f"footprint {spp // 1000}k" if spp % 1000 == 0 else f"footprint {spp}", "mitransient", "footprint", int(spp))
        for spp in bench["footprint_spp"]
    ]
    if with_analytic:
        configs.append(Configuration("analytic", "analytic", "footprint", None))
    return configs


def nl2(h: np.ndarray, ref: np.ndarray) -> float:
    """Normalised L2 error of histogram h (B,) against ref (B,)."""
    return float(np.linalg.norm(h - ref) / np.linalg.norm(ref))


class _Renderers:
    """One renderer per (configuration, object, size), built on first use."""

    def __init__(self, cal: Calibration, settings: dict, axis: TimeAxis, seed: int):
        self.cal, self.settings, self.axis, self.seed = cal, {**settings, "illumination": "spot"}, axis, seed  # the spot: see the module
        self.footprints = zone_footprints(cal, GRID)
        self.cache: dict = {}

    def get(self, config: Configuration, spec: ObjectSpec, size: str):
        """(renderer, {readout name: {zone: pixel mask (relays, film, film)}}, whether it was just built)."""
        key = (config, spec.name, size)
        fresh = key not in self.cache
        if fresh:
            self.cache.clear()  # one live Mitsuba scene at a time keeps memory flat
            mesh = object_mesh(spec, size)
            material = material_of(self.settings, spec.material == "retroreflective")
            if config.film == "wall":
                twin = twin_scene(self.cal, mesh, self.settings, self.axis, relays=(self.cal.wall,), film=PAPER_FILM, material=material)
                fps = self.footprints
                readouts = {
                    config.name: {CENTRE_ZONE: centre_block(self.cal.wall, PAPER_FILM, fps[CENTRE_ZONE].centre, PAPER_BLOCK)[None]},
                    f"{config.name}, footprint pixels": {z: pixels_inside(self.cal.wall, PAPER_FILM, fp)[None] for z, fp in enumerate(fps)},
                }
            else:
                twin = twin_scene(self.cal, mesh, self.settings, self.axis, GRID, material=material)
                readouts = {config.name: {z: np.arange(len(twin.relays))[:, None, None] == z for z in range(len(twin.relays))}}
                readouts[config.name] = {z: np.broadcast_to(m, (len(twin.relays), twin.film, twin.film)) for z, m in readouts[config.name].items()}
            settings = {**self.settings, "renderer": config.renderer, "mitransient": {**self.settings["mitransient"], "spp": config.spp}}
            renderer = make_renderer(twin, settings, derive_seed(self.seed, config.name))
            self.cache[key] = (renderer, readouts)
        return (*self.cache[key], fresh)


def run_benchmark(cal: Calibration, specs: list[ObjectSpec], sizes: list[str], settings: dict, axis: TimeAxis, seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Render every configuration on the benchmark's scenes, on `axis`.

    settings: the `twin` config section (with its `benchmark`, `analytic`
    and `mitransient` parts). Returns (summary, per_scene): per_scene has
    one row per (readout, scene) with seconds and error (the two readouts of
    the paper's film share one render and its time); summary one row per
    readout (see `summarise`)."""
    bench = settings["benchmark"]
    scenes = benchmark_scenes(specs, sizes, cal.locations, int(bench["n_scenes"]), seed)
    renderers = _Renderers(cal, settings, axis, seed)
    reference = Configuration("reference", "mitransient", "footprint", int(bench["reference_spp"]))
    refs = {}
    for sc in scenes:
        renderer, readouts, _ = renderers.get(reference, sc.spec, sc.size)
        image = renderer.render(sc.location)
        refs[sc] = {z: image[mask].mean(axis=0) for z, mask in readouts["reference"].items()}
        log.info("reference %s done", sc.label)
    rows = []
    for config in configurations(bench, with_analytic=not settings["table"]):
        for sc in scenes:
            renderer, readouts, fresh = renderers.get(config, sc.spec, sc.size)
            t0 = time.perf_counter()
            image = renderer.render(sc.location)
            seconds = time.perf_counter() - t0
            for name, masks in readouts.items():
                for z, mask in masks.items():
                    h, ref = image[mask].mean(axis=0), refs[sc][z]
                    rows.append({
                        "configuration": name, "renderer": config.renderer, "film": config.film, "spp": config.spp,
                        "pixels": int(mask.sum()), "scene": sc.label, "zone": z, "first": fresh, "seconds": seconds,
                        "error_nl2": nl2(h, ref), "correlation": float(np.corrcoef(h, ref)[0, 1]), "scale": float(h.sum() / ref.sum()),
                    })  # fmt: skip
                log.info("%s %s: %.3f s, error %.4f (mean over zones)", name, sc.label, seconds, np.mean([r["error_nl2"] for r in rows[-len(masks) :]]))
    per_scene = pd.DataFrame(rows)
    return summarise(per_scene, int(bench["reference_spp"])), per_scene


def summarise(per_scene: pd.DataFrame, reference_spp: int) -> pd.DataFrame:
    """One row per configuration: time per scene (median over the renders
    that are not a group's first; over all if every render is), the first
    renders' mean time (with kernel compilation), error mean/std/max over
    zones and scenes and the mean per zone (`error_zone_<row><col>`, empty
    for zones a configuration does not read out), the lowest correlation,
    mean scale against the reference, speed-up over `paper`, and whether it
    is on the Pareto front of (time, error)."""
    rows = []
    for name, g in per_scene.groupby("configuration", sort=False):
        one = g.drop_duplicates("scene")  # the zones of a scene share one render and its time
        by_zone = g.groupby("zone").error_nl2.mean()
        rows.append({
            "configuration": name, "renderer": g.renderer.iloc[0], "film": g.film.iloc[0],
            "spp": g.spp.iloc[0], "pixels": int(g.pixels.iloc[0]), "n_scenes": len(one), "n_zones": int(g.zone.nunique()),
            "time_per_scene_s": float((one.seconds[~one["first"]] if (~one["first"]).any() else one.seconds).median()),
            "first_render_s": float(one.seconds[one["first"]].mean()),
            "error_nl2": float(g.error_nl2.mean()), "error_nl2_std": float(g.error_nl2.std(ddof=1)) if len(g) > 1 else 0.0,
            "error_nl2_max": float(g.error_nl2.max()), "correlation_min": float(g.correlation.min()),
            "scale_mean": float(g.scale.mean()), "reference_spp": reference_spp,
            **{f"error_zone_{z // GRID}{z % GRID}": float(by_zone.get(z, np.nan)) for z in range(GRID * GRID)},
        })  # fmt: skip
    df = pd.DataFrame(rows)
    paper = df.loc[df.configuration == "paper", "time_per_scene_s"]
    df["speedup_vs_paper"] = float(paper.iloc[0]) / df.time_per_scene_s if len(paper) else np.nan
    df["pareto"] = pareto_front(df.time_per_scene_s.to_numpy(), df.error_nl2.to_numpy())
    return df


def pareto_front(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """(N,) bool: points no other point beats on both cost and error."""
    cost, error = np.asarray(cost), np.asarray(error)
    better = (cost[None, :] <= cost[:, None]) & (error[None, :] <= error[:, None])
    strictly = (cost[None, :] < cost[:, None]) | (error[None, :] < error[:, None])
    return ~(better & strictly).any(axis=1)
