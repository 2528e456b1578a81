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

from denali_pipe import geometry as geo
from denali_pipe.io.store import CaptureStore, open_set
from denali_pipe.meshes import object_mesh
from denali_pipe.objects import spec_from_dict
from denali_pipe.preprocess import subtract_background
from denali_pipe.report.figure import plt, save_figure
from denali_pipe.seeds import derive_seed, rng_for
from denali_pipe.twin.layout import Calibration, load_calibration, twin_scene
from denali_pipe.twin.render import Twin, read_twin

CENTRE = (1, 1)  # the centre zone of the 3x3 grid
SMOOTH_BINS = 5  # a box mean shows the ~10-bin bump above the shot noise of one bin


def real_centre_histogram(store: CaptureStore, background: CaptureStore, location: int) -> np.ndarray:
    """(N_BINS,) float32: the centre zone at `location`, mean over repeats,
    minus the background's mean at the same location."""
    if store.n_zones != 3 or background.n_zones != 3:
        raise ValueError(f"{store.path}, {background.path}: Fig 18 needs 3x3 captures")
    h = store.histogram(store.index_of(location))[None]
    bg = background.histogram(background.index_of(location))[None]
    return subtract_background(h, bg)[0].mean(axis=0)[CENTRE]


def twin_view(mi, cal: Calibration, twin: Twin, location: int, frame_shape: tuple[int, int], spp: int, seed: int) -> np.ndarray:
    """(H, W, 3) uint8 RGB render of the tracking camera's view at `location`."""
    from denali_pipe.twin.scene import render_rgb, rgb_scene

    spec = spec_from_dict(twin.attrs["object"])
    scene = twin_scene(cal, object_mesh(spec, twin.attrs["size"]), twin.attrs["config"])
    h, w = frame_shape
    camera = dataclasses.replace(cal.tracking_camera, intrinsics=cal.tracking_camera.intrinsics.scaled_to(w, h))
    return render_rgb(mi, rgb_scene(mi, cal, scene, location, camera, spp), seed)


def fig18(captures: list[tuple[Path, Path, Path]], scene_json: Path, crop: int, config: dict, out_png: Path) -> None:
    """captures: (set store, its NOOBJECT store, the object's twin store) per
    row; crop: the features' first kept bin (results/features/crop_3x3.json). config: {"seed": int, "fig18": {"rgb_spp": int}, "variant": str}.
    The location of each row is drawn from the locations all three share."""
    from denali_pipe.twin.variant import load_mitsuba

    mi = load_mitsuba(config["variant"])
    cal = load_calibration(scene_json)
    rng = rng_for(config["seed"], "fig18")
    rows = []
    fig, axes = plt.subplots(len(captures), 3, figsize=(14, 3.3 * len(captures)), squeeze=False)
    for ax_row, (set_path, bg_path, twin_path) in zip(axes, captures):
        store, bg, twin = open_set(set_path), open_set(bg_path), read_twin(twin_path)
        shared = sorted(set(store.locations) & set(bg.locations) & set(twin.locations))
        if not shared:
            raise ValueError(f"{set_path}, {bg_path} and {twin_path} share no gantry location")
        location = int(rng.choice(shared))
        real = real_centre_histogram(store, bg, location)
        sim = twin.histogram(location)
        frame = store.frame("tracking_rgb", store.index_of(location))[..., ::-1]  # BGR -> RGB
        view = twin_view(
            mi, cal, twin, location, frame.shape[:2], config["fig18"]["rgb_spp"], derive_seed(config["seed"], "fig18", store.name, location) % 2**32
        )

        ax_row[0].imshow(frame)
        ax_row[0].set_title(f"{store.name} @ {location}: tracking frame", fontsize=8)
        ax_row[1].imshow(view)
        ax_row[1].set_title(f"Mitsuba render ({twin.attrs['renderer']} twin)", fontsize=8)
        for ax in ax_row[:2]:
            ax.axis("off")
        bins = np.arange(geo.N_BINS)
        kept = bins >= crop
        ax = ax_row[2]
        smooth = np.convolve(real, np.ones(SMOOTH_BINS) / SMOOTH_BINS, mode="same")
        ax.plot(bins[kept], real[kept], color="tab:blue", lw=0.6, alpha=0.5, label="real (bg-subtracted)")
        ax.plot(bins[kept], smooth[kept], color="tab:blue", lw=1.6, label=f"real, {SMOOTH_BINS}-bin mean")
        ax.set_xlabel("bin (3/128 m optical path)")
        ax.set_ylabel("counts", color="tab:blue")
        twin_ax = ax.twinx()
        twin_ax.plot(bins[kept], sim[kept], color="tab:orange", lw=1.2, label="simulated")
        twin_ax.set_ylabel("simulated (radiance / unit intensity)", color="tab:orange")
        ax.set_title(f"centre pixel, bins >= {crop}", fontsize=8)
        ax.legend(handles=ax.get_lines() + twin_ax.get_lines(), fontsize=7, loc="upper right")
        rows.append(pd.DataFrame({"set": store.name, "location": location, "bin": bins, "real_counts": real, "sim": sim, "kept": kept}))
    fig.tight_layout()
    save_figure(fig, out_png, pd.concat(rows, ignore_index=True))
