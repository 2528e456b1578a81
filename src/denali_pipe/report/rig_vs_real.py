"""`results/rig_vs_real.png` + CSV: the capture source's raw centre-zone
histograms beside the numbers read off the release's figures of real 3x3
captures (REFERENCE Part 4, `paper.REAL_CENTRE_ZONE`).

For one object at 8 in and 4 in, each lighting, at the captured gantry
location nearest the grid's centre: one capture (repeat 0, as the figures
show single captures) and the mean of the `NOOBJECT` background at the same
location, measured by `rig.measure` (floor before and after the direct
return, direct peak, bump excess, FWHM). Each panel is zoomed, as the
release's figures are, to the lower part of the direct peak.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe import geometry as geo
from denali_pipe.io.store import open_set
from denali_pipe.report.figure import plt, save_figure
from denali_pipe.report.paper import REAL_CENTRE_ZONE
from denali_pipe.rig.measure import measure

CENTRE_ZONE = (1, 1)
# The panels show counts up to this fraction of the direct peak: the bump lives there.
ZOOM = 0.25
COLUMNS = (
    "source",
    "set",
    "location",
    "floor_before",
    "floor_after",
    "late_over_floor",
    "direct_peak",
    "floor_fraction",
    "bump_excess",
    "bump_fraction",
    "bump_over_floor",
    "bump_bin",
    "bump_fwhm",
)


def mid_location(locations: list[int]) -> int:
    """The captured location whose object-tag position is nearest the grid's centre."""
    centre = geo.tag1_position(np.arange(geo.N_LOCATIONS)).mean(0)
    return min(locations, key=lambda k: float(np.linalg.norm(geo.tag1_position(k) - centre)))


def real_summary(values: dict) -> str:
    """What one real figure lets one read, in words."""
    words = {
        "floor_fraction": lambda v: f"floor {100 * v:.0f} % of peak",
        "floor_before": lambda v: f"floor {v:.0f} counts",
        "bump_excess": lambda v: f"bump {v:.0f} counts",
        "bump_fraction": lambda v: f"bump {100 * v:.0f} % of peak",
        "bump_over_floor": lambda v: f"bump {v:.1f}x floor",
        "late_over_floor": lambda v: f"late/floor {v:.2f}",
        "bump_fwhm": lambda v: f"FWHM {v:.1f} bins",
    }
    return ", ".join(words[key](v) for key, v in values.items())


def real_rows() -> list[dict]:
    return [{"source": f"real ({name})", **values} for name, values in REAL_CENTRE_ZONE.items()]


def rig_vs_real(pairs: list[tuple[Path, Path]], out_png: Path, out_csv: Path) -> pd.DataFrame:
    """Measure each (object set store, NOOBJECT store) pair's centre zone and
    plot it; write the PNG and the CSV (rig rows, then the real figures' rows)."""
    rows, panels = [], []
    for obj_path, bg_path in pairs:
        obj, bg = open_set(obj_path), open_set(bg_path)
        shared = sorted(set(obj.locations) & set(bg.locations))
        if not shared:
            raise ValueError(f"{obj_path} and {bg_path} share no gantry location")
        k = mid_location(shared)
        capture = obj.histogram(obj.index_of(k))[0][CENTRE_ZONE].astype(float)
        background = bg.histogram(bg.index_of(k)).mean(0)[CENTRE_ZONE]
        m = measure(capture, background)
        rows.append({"source": "capture source", "set": obj.capture_set.name, "location": k, **m.to_dict()})
        panels.append((obj.capture_set, k, capture, background, m))
    table = pd.DataFrame(rows + real_rows()).reindex(columns=list(COLUMNS))

    ncols = min(2, len(panels))
    nrows = -(-len(panels) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(5.2 * ncols, 3.6 * nrows + 0.6), squeeze=False)
    bins = np.arange(geo.N_BINS)
    for ax in axes.flat[len(panels) :]:
        ax.set_visible(False)
    for ax, (cs, k, capture, background, m) in zip(axes.flat, panels):
        ax.bar(bins, capture, width=1.0, color="tab:blue", alpha=0.6, label="one capture")
        ax.plot(bins, background, color="k", lw=1, label="NOOBJECT (mean)")
        ax.axhline(m.floor_before, color="tab:gray", ls=":", lw=1, label="pre-peak floor")
        ax.axvline(m.bump_bin, color="tab:red", ls="--", lw=0.8, label="bump peak")
        ax.set_ylim(0, ZOOM * m.direct_peak)
        ax.set_xlim(0, geo.N_BINS)
        ax.set_xlabel("bin (3/128 m optical path, 78 ps)")
        ax.set_ylabel("counts")
        ax.set_title(f"{cs.object} {cs.size} {cs.light}, location {k}", fontsize=9)
        text = (
            f"direct peak {m.direct_peak:,.0f} (off scale)\n"
            f"floor {100 * m.floor_fraction:.1f} % of peak; late/floor {m.late_over_floor:.2f}\n"
            f"bump {m.bump_excess:,.0f} = {100 * m.bump_fraction:.1f} % of peak = {m.bump_over_floor:.1f}x floor\n"
            f"bump FWHM {m.bump_fwhm:.1f} bins"
        )
        ax.text(0.98, 0.97, text, transform=ax.transAxes, ha="right", va="top", fontsize=7, bbox=dict(fc="white", alpha=0.8, lw=0))
    axes[0][0].legend(fontsize=7, loc="center right")
    real = "\n".join(f"{name}: {real_summary(v)}" for name, v in REAL_CENTRE_ZONE.items())
    fig.suptitle(f"Raw centre-zone histograms, zoomed to {ZOOM:.0%} of the direct peak. Real captures, read off the release's figures:\n{real}", fontsize=8)
    fig.tight_layout()
    save_figure(fig, out_png, table, out_csv)
    return table
