"""The twin job: one (object, size) rendered at every calibrated location into
`results/twin/<object>_<size>.zarr`, and its reader.

Store layout (Zarr v3, one group):

    location   (L,)       int16    gantry location, ascending
    histogram  (L, 128)   float32  the centre pixel's simulated transient: the
                                   footprint film averaged over its pixels, in
                                   radiance per unit laser intensity per bin,
                                   sensor-relative optical path like the real
                                   data (bin b covers HIST_START_OPL + [b, b+1) w)

Root attributes: denali_twin (format version), object (its sheet row), size,
renderer, config (the `twin` settings used), seed, bin_width_opl,
start_opl, footprint (centre, u, v, size), laser_spot, sensor, scene_json
(path and sha256), seconds (wall time per location).
"""

from __future__ import annotations

import hashlib
import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zarr

from denali_pipe import geometry as geo
from denali_pipe.atomic import atomic_dir
from denali_pipe.meshes import object_mesh
from denali_pipe.objects import ObjectSpec
from denali_pipe.seeds import derive_seed
from denali_pipe.twin.layout import TwinScene, load_calibration, twin_scene

log = logging.getLogger(__name__)

TWIN_VERSION = 1
RENDERERS = ("analytic", "mitransient")


def make_renderer(twin: TwinScene, settings: dict, seed: int):
    """The renderer named by settings["renderer"] (`twin` config section),
    drawing `twin`; `seed` seeds mitransient's sampler per location."""
    name = settings["renderer"]
    if name == "analytic":
        from denali_pipe.twin.analytic import AnalyticRenderer

        return AnalyticRenderer(twin, settings["analytic"]["samples"])
    if name == "mitransient":
        from denali_pipe.twin.mitransient import MitransientRenderer

        m = settings["mitransient"]
        return MitransientRenderer(twin, m["spp"], m["max_depth"], seed, m["variant"])
    raise ValueError(f"unknown twin renderer {name!r}; expected one of {list(RENDERERS)}")


def twin_seed(seed: int, spec: ObjectSpec, size: str) -> int:
    return derive_seed(seed, "twin", spec.name, size)


def render_twin(spec: ObjectSpec, size: str, scene_json: Path, config: dict, out: Path) -> Path:
    """Render object `spec` at `size` at every location of the calibrated
    scene `scene_json` and write the twin store `out` atomically.

    config: {"seed": int, "twin": the twin section (renderer, albedos,
    footprint, table and the chosen renderer's settings)}."""
    settings = config["twin"]
    cal = load_calibration(scene_json)
    twin = twin_scene(cal, object_mesh(spec, size), settings)
    seed = twin_seed(config["seed"], spec, size)
    renderer = make_renderer(twin, settings, seed)
    hist, seconds = [], []
    for i, location in enumerate(cal.locations):
        t0 = time.perf_counter()
        hist.append(renderer.render(location).mean(axis=(0, 1)))
        seconds.append(time.perf_counter() - t0)
        log.info("%s %s location %d (%d/%d): %.3f s", spec.name, size, location, i + 1, len(cal.locations), seconds[-1])
    attrs = {
        "denali_twin": TWIN_VERSION,
        "object": spec.to_dict(),
        "size": size,
        "renderer": renderer.name,
        "config": settings,
        "seed": seed,
        "bin_width_opl": geo.BIN_WIDTH_OPL,
        "start_opl": geo.HIST_START_OPL,
        "footprint": {"centre": twin.relay.centre.tolist(), "u": twin.relay.u.tolist(), "v": twin.relay.v.tolist(), "size": list(twin.relay.size)},
        "laser_spot": twin.spot.tolist(),
        "sensor": twin.sensor.tolist(),
        "scene_json": {"path": str(scene_json), "sha256": hashlib.sha256(Path(scene_json).read_bytes()).hexdigest()},
        "seconds": seconds,
    }
    write_twin(out, np.array(cal.locations), np.array(hist), attrs)
    return out


def write_twin(out: Path, locations: np.ndarray, histograms: np.ndarray, attrs: dict) -> None:
    """Write a twin store atomically: locations (L,), histograms (L, N_BINS)."""
    if histograms.shape != (len(locations), geo.N_BINS):
        raise ValueError(f"{out}: histograms {histograms.shape}, expected ({len(locations)}, {geo.N_BINS})")
    with atomic_dir(Path(out)) as tmp:
        group = zarr.open_group(tmp, mode="w", zarr_format=3)
        group.create_array("location", data=np.asarray(locations, np.int16), dimension_names=("location",))
        group.create_array("histogram", data=np.asarray(histograms, np.float32), dimension_names=("location", "bin"))
        group.attrs.update(attrs)


@dataclass(frozen=True)
class Twin:
    """A twin store read back: locations (L,) int64, histograms (L, N_BINS) float32, attrs."""

    locations: np.ndarray
    histograms: np.ndarray
    attrs: dict

    def histogram(self, location: int) -> np.ndarray:
        hit = np.flatnonzero(self.locations == int(location))
        if not len(hit):
            raise KeyError(f"twin of {self.attrs['object']['name']} {self.attrs['size']} has no location {location} (it has {self.locations.tolist()})")
        return self.histograms[hit[0]]


def read_twin(path: Path) -> Twin:
    """Read a twin store. Raises ValueError naming the path when it is not one."""
    path = Path(path)
    try:
        group = zarr.open_group(path, mode="r", zarr_format=3)
    except Exception as e:  # noqa: BLE001 -- zarr raises several types for a non-store
        raise ValueError(f"{path}: not a Zarr v3 twin store ({type(e).__name__}: {e})") from None
    attrs = dict(group.attrs)
    if attrs.get("denali_twin") != TWIN_VERSION:
        raise ValueError(f"{path}: not a twin store (attribute denali_twin={attrs.get('denali_twin')!r}, expected {TWIN_VERSION})")
    return Twin(np.asarray(group["location"][:], np.int64), np.asarray(group["histogram"][:]), attrs)
