"""`results/rig_vs_real.png` + CSV: the capture source's raw 3x3 histograms
beside what is known of real ones: the centre zone's shape read off the
release's figures (`paper.REAL_CENTRE_ZONE`) and every
zone's mean counts recovered from the release's trained models (Part 5,
`paper.REAL_ZONE_MEANS`).

For one object at 8 in and 4 in, each lighting, at the captured gantry
location nearest the grid's centre: one capture (repeat 0, as the figures
show single captures) and the mean of the `NOOBJECT` background at the same
location, measured by `rig.measure` (floor before and after the direct
return, direct peak, bump excess, FWHM). Each panel is zoomed, as the
release's figures are, to the lower part of the direct peak. Below them,
each zone's mean counts per bin over every capture of those object sets
(all locations, repeats and bins) beside Part 5's, with the centre/edge and
centre/corner ratios, the right/left column ratio, the pooled spread of
log1p(counts) and each zone's mean of Part 7's log transform z beside the
real one. When the release's feature statistics are given (config
`rig_vs_real.feature_stats`), a panel per layer below holds Part 7's
feature-moment distance of the same captures for each of the 18 release
nets (`rig.feature_moments`); without them there are no such panels and the
figure and the log say so. Given the release's 15 trained networks' scores on
this run's captures (`results/release_models.csv`,
experiments.release_models), a last row sets each network's score per
lighting beside its baseline, per task, with the correlation of its location
predictions' x and y with the true ones; where no network was scored, the
title says why.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.figure import plt, save_figure
from denali_pipe.io.store import open_set
from denali_pipe.report.paper import REAL_CENTRE_ZONE, REAL_LOG_ZONE_MEANS, REAL_ZONE_MEANS
from denali_pipe.rig import feature_moments as fm
from denali_pipe.rig.measure import measure
from denali_pipe.train.cells import TASKS
from denali_pipe.train.runs import HEADLINE

log = logging.getLogger(__name__)

CENTRE_ZONE = geo.centre_zone("3x3")
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
    "zone_row",
    "zone_col",
    "mean_counts",
    "real_mean_counts",
    "mean_z",
    "real_mean_z",
    "network",
    "task",
    "light",
    "metric",
    "value",
    "baseline",
    "n_samples",
    "corr_x",
    "corr_y",
) + fm.COLUMNS
# Source labels of the per-zone rows.
ZONE_SOURCE = "capture source, every zone"
REAL_ZONE_SOURCE = "real, every zone (release's models)"
FEATURE_SOURCE = "capture source, feature moments"
RELEASE_SOURCE = "capture source, release networks"
LIGHT_COLOURS = {"lightoff": "tab:blue", "lighton": "tab:orange"}
# The real captures' pooled spread of log1p(counts) (the release's generalisation checkpoints).
REAL_LOG_SPREAD = 0.78


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


def zone_pattern(means: np.ndarray) -> dict:
    """Centre/edge and centre/corner ratios and the right/left column ratio of (3, 3) zone means."""
    edge = means[[0, 1, 1, 2], [1, 0, 2, 1]].mean()
    corner = means[[0, 0, 2, 2], [0, 2, 0, 2]].mean()
    return {"centre/edge": means[1, 1] / edge, "centre/corner": means[1, 1] / corner, "column 2/column 0": means[:, 2].sum() / means[:, 0].sum()}


def object_histograms(paths: list[Path]) -> np.ndarray:
    """Every capture of the stores at `paths` (locations, repeats) as
    (N, 9, N_BINS) int32 raw counts, zones row-major as stored."""
    parts = [h.reshape(h.shape[0], -1, h.shape[-1]) for path in paths for _, h in open_set(path).iter_histograms()]
    return np.concatenate(parts)


def zone_means(hist: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean counts per bin of every zone (3, 3) over captures (N, 9, N_BINS)
    and bins, and the pooled standard deviation of log1p(counts) over them."""
    return hist.mean(axis=(0, -1)).reshape(3, 3), float(np.log1p(hist.astype(float)).std())


def zone_rows(means: np.ndarray, mean_z: np.ndarray) -> list[dict]:
    """The rig's zone means (counts and Part 7's z) beside the real ones, then the real ones as their own rows."""
    real, real_z = np.asarray(REAL_ZONE_MEANS), np.asarray(REAL_LOG_ZONE_MEANS)
    zones = [(r, c) for r in range(3) for c in range(3)]
    rig = [
        {
            "source": ZONE_SOURCE,
            "zone_row": r,
            "zone_col": c,
            "mean_counts": means[r, c],
            "real_mean_counts": real[r, c],
            "mean_z": mean_z[r, c],
            "real_mean_z": real_z[r, c],
        }
        for r, c in zones
    ]
    return rig + [{"source": REAL_ZONE_SOURCE, "zone_row": r, "zone_col": c, "mean_counts": real[r, c], "mean_z": real_z[r, c]} for r, c in zones]


def plot_zones(ax, means: np.ndarray, spread: float, mean_z: np.ndarray) -> None:
    """Grouped bars of each zone's mean counts, the rig's beside the real ones."""
    real = np.asarray(REAL_ZONE_MEANS)
    x = np.arange(9)
    ax.bar(x - 0.2, means.ravel(), width=0.4, color="tab:blue", label="capture source")
    ax.bar(x + 0.2, real.ravel(), width=0.4, color="k", alpha=0.7, label="real (the release's checkpoints)")
    for i, (m, rv) in enumerate(zip(means.ravel(), real.ravel())):
        ax.text(i - 0.2, m, f"{100 * (m / rv - 1):+.0f} %", ha="center", va="bottom", fontsize=7, color="tab:blue")
    ax.set_xticks(x, [f"({r}, {c})" for r in range(3) for c in range(3)])
    ax.set_xlabel("zone (row, column) as stored; (1, 1) is the centre")
    ax.set_ylabel("mean counts per bin")
    ax.set_xlim(-0.6, 8.6)
    ax.set_ylim(0, 1.15 * max(means.max(), real.max()))
    rig, ref = zone_pattern(means), zone_pattern(real)
    words = "; ".join(f"{k} {rig[k]:.2f} (real {ref[k]:.2f})" for k in rig)
    dz = (mean_z - np.asarray(REAL_LOG_ZONE_MEANS)).ravel()
    zwords = " ".join(f"{d:+.2f}" for d in dz)
    ax.set_title(
        f"Every zone's mean counts per bin over the object sets' captures (percentages: capture source against real)\n{words}; pooled log1p(counts) sd {spread:.2f} (real {REAL_LOG_SPREAD})\n"
        f"zone means of z = (log1p(counts) - {fm.LOG_MEAN}) / {fm.LOG_STD}, capture source minus real (REFERENCE Part 7), zone by zone: {zwords}",
        fontsize=8,
    )
    ax.legend(fontsize=7, loc="upper right")


def plot_layer(ax, table: pd.DataFrame, layer: int) -> None:
    """One layer's feature-moment distance per release net: the mean term
    stacked under the variance term (0: the real moments)."""
    t = table[table.layer == layer].sort_values(["input", "net"], ascending=[False, True])
    x = np.arange(len(t))
    ax.bar(x, t.mean_term, color="tab:blue", label="mean term")
    ax.bar(x, t.var_term, bottom=t.mean_term, color="tab:orange", label="variance term")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(x, [f"{n} ({i})" for n, i in zip(t.net, t.input)], rotation=90, fontsize=6)
    ax.set_xlim(-0.6, len(t) - 0.4)
    ax.set_ylim(0, 1.3 * t.distance.max())  # room for the legend
    ax.set_ylabel("distance (0 = the real moments)")
    by_input = t.groupby("input").distance.mean()
    low = (t.var_log_ratio < 0).sum()
    ax.set_title(
        f"layer {layer}: distance {t.distance.mean():.2f} (raw-count nets {by_input.get('raw', np.nan):.2f}, log-input {by_input.get('log_z', np.nan):.2f})\n"
        f"variance below the real in {low} of {len(t)} nets (median channel)",
        fontsize=8,
    )
    ax.legend(fontsize=7, loc="upper right")


def release_scores(table: pd.DataFrame) -> tuple[pd.DataFrame, str]:
    """The per-lighting rows of the release networks' table
    (experiments.release_models.COLUMNS) that scored captures, as this
    figure's CSV rows, and a line for the title: how many networks beat
    their baseline on both lightings together, or why none was scored."""
    scored = table[table.n_samples > 0]
    if scored.empty:
        notes = table.note.dropna().unique()
        return pd.DataFrame(columns=list(COLUMNS)), f"release networks: none scored ({notes[0] if len(notes) else 'no captures'})"
    both = scored[scored.light == "both"]
    higher = both.task.map(lambda task: HEADLINE[task][1])
    better = np.where(higher, both.value > both.baseline, both.value < both.baseline)
    rows = scored[scored.light != "both"].assign(source=RELEASE_SOURCE)
    return rows.reindex(columns=list(COLUMNS)), f"release networks: {int(better.sum())} of {len(both)} beat their baseline on these captures (both lightings)"


def plot_release(axes, rows: pd.DataFrame) -> None:
    """Per task (cells.TASKS) a panel: each network's score per lighting as
    bars, its baseline as a dashed line over them, and for location the
    correlations of its predicted x and y with the true ones."""
    for ax, task in zip(axes, TASKS):
        t = rows[rows.task == task]
        if t.empty:
            ax.set_visible(False)
            continue
        nets = list(dict.fromkeys(t.network))
        lights = [li for li in LIGHT_COLOURS if li in set(t.light)]
        width = 0.8 / len(lights)
        for j, light in enumerate(lights):
            r = t[t.light == light].set_index("network").reindex(nets)
            x = np.arange(len(nets)) - 0.4 + (j + 0.5) * width
            ax.bar(x, r.value, width=width, color=LIGHT_COLOURS[light], label=light)
            ax.hlines(r.baseline, x - width / 2, x + width / 2, color="k", ls="--", lw=1.2, label="baseline" if j == 0 else None)
            if task == "location":
                for xi, v, cx, cy in zip(x, r.value, r.corr_x, r.corr_y):
                    # inside the bar, upright: neighbouring bars' labels cannot overlap
                    ax.text(xi, v / 2, f"x {cx:+.2f}  y {cy:+.2f}", ha="center", va="center", rotation=90, fontsize=5.5, color="white")
        metric = t.metric.iloc[0]
        ax.set_xticks(np.arange(len(nets)), nets, rotation=60, ha="right", fontsize=6)
        ax.set_ylabel("RMSE (m), lower is better" if metric == "rmse" else "Top-1, higher is better", fontsize=8)
        ax.set_ylim(0, 1.35 * np.nanmax(np.r_[t.value, t.baseline]))
        kind = "the scored positions' mean" if metric == "rmse" else "chance, 1 / classes"
        corr = "\nin the bars: r of predicted and true x, y" if task == "location" else ""
        ax.set_title(f"release networks, {task}, per lighting\ndashed: baseline ({kind}){corr}", fontsize=8)
        ax.legend(fontsize=6, loc="upper right", ncols=3)


def rig_vs_real(
    pairs: list[tuple[Path, Path]], out_png: Path, out_csv: Path, feature_stats: Path | None = None, release_models: Path | None = None
) -> pd.DataFrame:
    """Measure each (object set store, NOOBJECT store) pair's centre zone and
    plot it; every zone's mean counts and z over the object sets' captures;
    with `feature_stats` (the folder of the release's backbones and BN
    statistics), Part 7's feature-moment distance of those captures per net
    and layer; with `release_models` (results/release_models.csv), the
    release networks' scores per task and lighting. Write the PNG and the CSV
    (rig rows, the real figures' rows, the zone rows, the feature rows, then
    the release networks' rows)."""
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
    hist = object_histograms([obj_path for obj_path, _ in pairs])
    means, spread = zone_means(hist)
    mean_z = fm.log_zone_means(hist).reshape(3, 3)
    if feature_stats is None:
        features = pd.DataFrame(columns=list(fm.COLUMNS))
        note = "feature-moment panels: none (config rig_vs_real.feature_stats is null)"
        log.info("rig_vs_real.feature_stats is not configured: no feature-moment panels or rows")
    else:
        features = fm.feature_distances(fm.load_backbones(feature_stats), hist).assign(source=FEATURE_SOURCE)
        yard = fm.summary(features)
        note = (
            f"feature-moment distance over {len(hist)} captures, 18 release nets x 3 layers: {yard['distance']:.2f} "
            f"(layers 1 / 2 / 3: {yard['layer 1']:.2f} / {yard['layer 2']:.2f} / {yard['layer 3']:.2f}; raw-count nets' layer-1 variance term {yard['raw layer-1 var']:.2f})"
        )
        log.info(note)
    if release_models is None:
        release, release_note = pd.DataFrame(columns=list(COLUMNS)), "release networks: none (no results/release_models.csv given)"
    else:
        release, release_note = release_scores(pd.read_csv(release_models))
    log.info(release_note)
    parts = [pd.DataFrame(rows + real_rows() + zone_rows(means, mean_z)), features, release]
    table = pd.concat([p for p in parts if not p.empty], ignore_index=True).reindex(columns=list(COLUMNS))

    ncols = min(2, len(panels))
    nrows = -(-len(panels) // ncols)
    extra = [kind for kind, part in (("features", features), ("release", release)) if not part.empty]
    fig = plt.figure(figsize=(max(5.2 * ncols, 13.0 if extra else 9.0), 3.6 * nrows + 3.8 + 4.6 * len(extra)))
    grid = fig.add_gridspec(nrows + 1 + len(extra), 6, height_ratios=[1.0] * nrows + [1.0] + [1.25] * len(extra))
    span = 6 // ncols
    axes = np.array([[fig.add_subplot(grid[r, c * span : (c + 1) * span]) for c in range(ncols)] for r in range(nrows)])
    plot_zones(fig.add_subplot(grid[nrows, :]), means, spread, mean_z)
    for row, kind in enumerate(extra, start=nrows + 1):
        thirds = [fig.add_subplot(grid[row, 2 * i : 2 * i + 2]) for i in range(3)]
        if kind == "features":
            for ax, layer in zip(thirds, fm.LAYERS):
                plot_layer(ax, features, layer)
        else:
            plot_release(thirds, release)
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
        ax.set_xlabel("time bin (config sensor.time_axis)")
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
    fig.suptitle(
        f"Raw centre-zone histograms, zoomed to {ZOOM:.0%} of the direct peak. Real captures, read off the release's figures:\n{real}\n{note}\n{release_note}",
        fontsize=8,
    )
    fig.tight_layout()
    save_figure(fig, out_png, table, out_csv)
    return table
