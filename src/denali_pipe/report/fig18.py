"""Figure 18 (paper supplement): real captures beside their digital twins.

One row per capture (a light-on 3x3 set and one of its gantry locations,
drawn with a seed): the tracking camera's frame; the Mitsuba `path` render
of the calibrated scene from the same camera with the object at that
location; the real background-subtracted centre-pixel histogram (mean over
repeats minus the NOOBJECT set's mean at the same location) and its running
mean, overlaid with the twin's simulated transient on its own axis (absolute
scale is not modelled: the sim-to-real transforms fit it). Bins before the end of the direct wall
return (the features' crop window, `results/features/crop_3x3.json`) are dropped, as the paper
crops them.

The PNG is written with its data beside it as CSV (same stem): set,
location, bin, real_counts, sim, kept.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core import pulse
from denali_pipe.core.figure import plt, save_figure
from denali_pipe.core.meshes import object_mesh
from denali_pipe.core.objects import spec_from_dict
from denali_pipe.core.seeds import derive_seed, rng_for
from denali_pipe.io.store import CaptureStore, open_set
from denali_pipe.preprocess.histograms import background_means, subtract_background
from denali_pipe.twin.calibrate import read_calibration
from denali_pipe.twin.layout import Calibration, load_calibration, material_of, twin_scene
from denali_pipe.twin.render import Twin, read_twin

GRID = 3
SMOOTH_BINS = 5  # a box mean shows the ~10-bin bump above the shot noise of one bin


def real_histograms(store: CaptureStore, background: CaptureStore, location: int) -> np.ndarray:
    """(3, 3, N_BINS) float32: every zone at `location`, mean over repeats,
    minus the background at the same location (`background_means`, as the
    features have it)."""
    if store.n_zones != GRID or background.n_zones != GRID:
        raise ValueError(f"{store.path}, {background.path}: Fig 18 needs 3x3 captures")
    h = store.histogram(store.index_of(location))[None]
    bg = background_means(background.histograms[...])[background.index_of(location)][None]
    return subtract_background(h, bg)[0].mean(axis=0)


def twin_view(mi, cal: Calibration, twin: Twin, axis: geo.TimeAxis, location: int, frame_shape: tuple[int, int], spp: int, seed: int) -> np.ndarray:
    """(H, W, 3) uint8 RGB render of the tracking camera's view at `location`
    (`axis`: the time axis a twin scene holds; the view draws no histogram)."""
    from denali_pipe.twin.scene import render_rgb, rgb_scene

    spec = spec_from_dict(twin.attrs["object"])
    scene = twin_scene(
        cal, object_mesh(spec, twin.attrs["size"]), twin.attrs["config"], axis, material=material_of(twin.attrs["config"], spec.material == "retroreflective")
    )
    h, w = frame_shape
    camera = dataclasses.replace(cal.tracking_camera, intrinsics=cal.tracking_camera.intrinsics.scaled_to(w, h))
    return render_rgb(mi, rgb_scene(mi, cal, scene, location, camera, spp), seed)


def fig18(captures: list[tuple[Path, Path, Path]], scene_json: Path, calibration: Path, crop: int, config: dict, axis: geo.TimeAxis, out_png: Path) -> None:
    """captures: (set store, its NOOBJECT store, the object's calibrated twin
    store) per row; calibration: twin_calibration.json (the zones' gains and
    the pulse); crop: the features' first kept bin (results/features/crop_3x3.json).
    config: {"seed": int, "fig18": {"rgb_spp": int}, "variant": str};
    axis: the captures' time axis. The location of each row is drawn from
    the locations all three share."""
    from denali_pipe.twin.variant import load_mitsuba

    mi = load_mitsuba(config["variant"])
    cal = load_calibration(scene_json)
    fitted = read_calibration(calibration)
    kernel = pulse.kernel(fitted.pulse)  # the twin holds the time offset already
    rng = rng_for(config["seed"], "fig18")
    rows = []
    fig = plt.figure(figsize=(16, 4.2 * len(captures)), constrained_layout=True)
    for sub, (set_path, bg_path, twin_path) in zip(fig.subfigures(len(captures), 1, squeeze=False)[:, 0], captures):
        store, bg, twin = open_set(set_path), open_set(bg_path), read_twin(twin_path)
        shared = sorted(set(store.locations) & set(bg.locations) & set(twin.locations))
        if not shared:
            raise ValueError(f"{set_path}, {bg_path} and {twin_path} share no gantry location")
        location = int(rng.choice(shared))
        real = real_histograms(store, bg, location)
        sim = fitted.gains[..., None] * pulse.convolve(twin.histogram(location, "3x3").astype(np.float64), kernel)
        frame = store.frame("tracking_rgb", store.index_of(location))[..., ::-1]  # BGR -> RGB
        view = twin_view(
            mi, cal, twin, axis, location, frame.shape[:2], config["fig18"]["rgb_spp"], derive_seed(config["seed"], "fig18", store.name, location) % 2**32
        )
        left, right = sub.subfigures(1, 2, width_ratios=[1.3, 1])
        img_axes = left.subplots(1, 2)
        img_axes[0].imshow(frame)
        img_axes[0].set_title(f"{store.name} @ {location}: tracking frame", fontsize=8)
        img_axes[1].imshow(view)
        img_axes[1].set_title(f"Mitsuba render ({twin.attrs['renderer']} twin)", fontsize=8)
        for ax in img_axes:
            ax.axis("off")
        bins = np.arange(geo.N_BINS)
        kept = bins >= crop
        zone_axes = right.subplots(GRID, GRID, sharex=True)
        for (r, c), ax in np.ndenumerate(zone_axes):
            smooth = np.convolve(real[r, c], np.ones(SMOOTH_BINS) / SMOOTH_BINS, mode="same")
            ax.plot(bins[kept], real[r, c][kept], color="tab:blue", lw=0.5, alpha=0.4, label="real (bg-subtracted)")
            ax.plot(bins[kept], smooth[kept], color="tab:blue", lw=1.2, label=f"real, {SMOOTH_BINS}-bin mean")
            ax.plot(bins[kept], sim[r, c][kept], color="tab:orange", lw=1.2, label="calibrated twin x zone gain")
            ax.axhline(0, color="k", lw=0.4)
            ax.set_title(f"zone ({r}, {c})", fontsize=7, pad=2)
            ax.tick_params(labelsize=6)
            rows.append(
                pd.DataFrame(
                    {
                        "set": store.name,
                        "location": location,
                        "zone_row": r,
                        "zone_col": c,
                        "bin": bins,
                        "real_counts": real[r, c],
                        "twin_counts": sim[r, c],
                        "kept": kept,
                    }
                )
            )
        zone_axes[-1, 1].set_xlabel(f"{axis.label()}, bins >= {crop}", fontsize=7)
        zone_axes[1, 0].set_ylabel("counts", fontsize=7)
        handles, labels = zone_axes[0, 0].get_legend_handles_labels()
        right.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=7, frameon=False)
    save_figure(fig, out_png, pd.concat(rows, ignore_index=True))
