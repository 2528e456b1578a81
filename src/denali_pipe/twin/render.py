"""The twin job: one (object, size) rendered at every calibrated location into
`results/twin/<object>_<size>.zarr`, and its reader.

Store layout (Zarr v3, one group), per rendered grid n x n (3x3, 8x8):

    location         (L,)             int16    gantry location, ascending
    histogram_<n>x<n> (L, n, n, 128)  float32  each zone's simulated transient:
                                   its footprint film averaged over its pixels,
                                   in radiance per unit laser intensity per
                                   bin, sensor-relative optical path like the
                                   real data (bin b covers start_opl +
                                   [b, b+1) bin_width_opl); zones in the
                                   captures' order;
                                   a calibrated 3x3 grid as each zone collects
                                   it through the receiver's glare
                                   (`calibrate.Fitted.receive`)

Root attributes: denali_twin (format version), object (its sheet row), size,
resolutions, renderer, config (the `twin` settings used), material,
calibration (twin_calibration.json's path and sha256, or None for the
design geometry), seed, bin_width_opl, start_opl, time_offset_opl,
footprints ({grid: [centre, u, v, size] per zone}), laser_spot, sensor,
illumination ("spot" or "flood") and emission (the flood's `layout.Emission`
as a dict: hwhm_deg (h, v), core_share, core_hwhm_deg; None under the spot),
glare_share (the receiver's, from the calibration; None for the design),
scene_json (path and sha256), seconds (wall time per location, all grids).

Version 1 stores (the centre zone only) are refused: rerender them.
"""

from __future__ import annotations

import hashlib
import logging
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import zarr

from denali_pipe.core import geometry as geo
from denali_pipe.core.atomic import atomic_dir
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.core.seeds import derive_seed
from denali_pipe.twin.layout import TwinScene, load_calibration, material_of, twin_scene
from denali_pipe.twin.selection import RESOLUTION

log = logging.getLogger(__name__)

TWIN_VERSION = 2  # 2: every zone of each grid; 1: the centre zone only
RENDERERS = ("analytic", "mitransient")


def make_renderer(twin: TwinScene, settings: dict, seed: int):
    """The renderer named by settings["renderer"] (`twin` config section),
    drawing `twin`; `seed` seeds mitransient's sampler per location."""
    name = settings["renderer"]
    if name == "analytic":
        from denali_pipe.twin.analytic import AnalyticRenderer

        return AnalyticRenderer(twin, settings["analytic"]["samples"], settings["analytic"].get("filter", "box"))
    if name == "mitransient":
        from denali_pipe.twin.mitransient import MitransientRenderer

        m = settings["mitransient"]
        return MitransientRenderer(twin, m["spp"], m["max_depth"], seed, m["variant"])
    raise ValueError(f"unknown twin renderer {name!r}; expected one of {list(RENDERERS)}")


def twin_seed(seed: int, spec: ObjectSpec, size: str) -> int:
    return derive_seed(seed, "twin", spec.name, size)


def _sha(path: Path) -> dict:
    return {"path": str(path), "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()}


def render_twin(spec: ObjectSpec, size: str, scene_json: Path, config: dict, axis: geo.TimeAxis, out: Path, calibration: Path | None = None) -> Path:
    """Render object `spec` at `size` at every location of the calibrated
    scene `scene_json`, every zone of each grid of config["resolutions"],
    on `axis`, and write the twin store `out` atomically.

    config: {"seed": int, "resolutions": ["3x3", ...], "twin": the twin
    section (renderer, albedos, material, footprint, table and the chosen
    renderer's settings)}. calibration: twin_calibration.json (`twin.calibrate`):
    its footprints, time offset, lobe and illumination replace the design's,
    and its 3x3 grid takes the receiver's glare (the gains that weigh one
    zone's light against another's are fitted on 3x3 only)."""
    settings = config["twin"]
    cal = load_calibration(scene_json)
    mesh = object_mesh(spec, size)
    fitted = None
    if calibration is not None:
        # imported only here: the calibration's module (pandas, scipy.optimize)
        # costs each design twin's job ~0.6 CPU-s it does not use
        from denali_pipe.twin.calibrate import read_calibration

        fitted = read_calibration(calibration)
    seed = twin_seed(config["seed"], spec, size)
    histograms, footprints, seconds = {}, {}, np.zeros(len(cal.locations))
    for res in config["resolutions"]:
        n = geo.RESOLUTIONS[res]
        twin = (
            fitted.twin_scene(cal, mesh, settings, axis, n, spec)
            if fitted
            else twin_scene(cal, mesh, settings, axis, n, material=material_of(settings, spec.material == "retroreflective"))
        )
        renderer = make_renderer(twin, settings, derive_seed(seed, res))
        out_res = []
        for i, location in enumerate(cal.locations):
            t0 = time.perf_counter()
            out_res.append(renderer.render(location).mean(axis=(1, 2)).reshape(n, n, geo.N_BINS))
            seconds[i] += time.perf_counter() - t0
            log.info("%s %s %s location %d (%d/%d): %.3f s", spec.name, size, res, location, i + 1, len(cal.locations), time.perf_counter() - t0)
        histograms[res] = fitted.receive(np.stack(out_res)) if fitted and n == 3 else np.stack(out_res)
        footprints[res] = [[r.centre.tolist(), r.u.tolist(), r.v.tolist(), list(r.size)] for r in twin.relays]
    attrs = {
        "denali_twin": TWIN_VERSION,
        "object": spec.to_dict(),
        "size": size,
        "resolutions": list(config["resolutions"]),
        "renderer": renderer.name,
        "config": settings,
        "material": twin.material.to_dict(),
        "calibration": _sha(calibration) if calibration is not None else None,
        "seed": seed,
        "bin_width_opl": twin.time_axis.bin_width_opl,
        "start_opl": twin.time_axis.start_opl,
        "time_offset_opl": twin.time_offset_opl,
        "footprints": footprints,
        "laser_spot": twin.spot.tolist(),
        "illumination": "spot" if twin.flood is None else "flood",
        "emission": None if twin.flood is None else asdict(twin.flood.emission),
        "glare_share": fitted.glare_share if fitted else None,
        "sensor": twin.sensor.tolist(),
        "scene_json": _sha(scene_json),
        "seconds": seconds.tolist(),
    }
    write_twin(out, np.array(cal.locations), histograms, attrs)
    return out


def write_twin(out: Path, locations: np.ndarray, histograms: dict[str, np.ndarray], attrs: dict) -> None:
    """Write a twin store atomically: locations (L,), histograms {grid: (L, n, n, N_BINS)}."""
    with atomic_dir(Path(out)) as tmp:
        group = zarr.open_group(tmp, mode="w", zarr_format=3)
        group.create_array("location", data=np.asarray(locations, np.int16), dimension_names=("location",))
        for res, h in histograms.items():
            n = geo.RESOLUTIONS[res]
            if h.shape != (len(locations), n, n, geo.N_BINS):
                raise ValueError(f"{out}: {res} histograms {h.shape}, expected ({len(locations)}, {n}, {n}, {geo.N_BINS})")
            group.create_array(f"histogram_{res}", data=np.asarray(h, np.float32), dimension_names=("location", "zone_row", "zone_col", "bin"))
        group.attrs.update(attrs)


@dataclass(frozen=True)
class Twin:
    """A twin store read back: locations (L,) int64, histograms {grid:
    (L, n, n, N_BINS) float32}, attrs."""

    path: Path
    locations: np.ndarray
    histograms: dict[str, np.ndarray]
    attrs: dict

    def histogram(self, location: int, res: str = RESOLUTION) -> np.ndarray:
        """(n, n, N_BINS): every zone of the `res` grid at `location`."""
        if res not in self.histograms:
            raise KeyError(f"{self.path}: the twin holds no {res} grid (it has {sorted(self.histograms)}); render it with resolutions including {res}")
        hit = np.flatnonzero(self.locations == int(location))
        if not len(hit):
            raise KeyError(
                f"{self.path}: twin of {self.attrs['object']['name']} {self.attrs['size']} has no location {location} (it has {self.locations.tolist()})"
            )
        return self.histograms[res][hit[0]]


def read_twin(path: Path) -> Twin:
    """Read a twin store. Raises ValueError naming the path when it is not one."""
    path = Path(path)
    try:
        group = zarr.open_group(path, mode="r", zarr_format=3)
    except Exception as e:  # noqa: BLE001 -- zarr raises several types for a non-store
        raise ValueError(f"{path}: not a Zarr v3 twin store ({type(e).__name__}: {e})") from None
    attrs = dict(group.attrs)
    version = attrs.get("denali_twin")
    if version == 1:
        raise ValueError(
            f"{path}: a version 1 twin store (the centre zone only); this pipeline reads version {TWIN_VERSION} (every zone): rerender it (delete it and rerun `denali twin` or its rule)"
        )
    if version != TWIN_VERSION:
        raise ValueError(f"{path}: not a twin store (attribute denali_twin={version!r}, expected {TWIN_VERSION})")
    hist = {res: np.asarray(group[f"histogram_{res}"][:]) for res in attrs["resolutions"]}
    return Twin(path, np.asarray(group["location"][:], np.int64), hist, attrs)
