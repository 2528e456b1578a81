"""Figure 12: AprilTag tracking. Left, one tracking frame with every detected
tag outlined and its estimated pose drawn as axes (cv2.drawFrameAxes: x red,
y green, z blue, z pointing into the tag); right, the filtered tag positions
in the world frame seen from above (x-y) and from the side (x-z): the static
tags' means and the object tag's position at every gantry location.

The PNG is written with the CSV of its data beside it (same name, .csv), both
atomically. CSV columns: panel (image | world), set, location, tag_id,
component, status, u_px, v_px (image: the tag centre), x_m, y_m, z_m (world
position; image rows carry the frame's own estimate), n_estimates.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.core.figure import plt, save_figure
from denali_pipe.io.store import open_set

COMPONENT_COLOURS = {"table": "tab:brown", "relay_wall": "tab:blue", "lidar": "tab:green", "object": "tab:red", "unknown": "tab:gray"}
AXIS_LENGTH_M = geo.TAG_SIZE
CSV_COLUMNS = ("panel", "set", "location", "tag_id", "component", "status", "u_px", "v_px", "x_m", "y_m", "z_m", "n_estimates")


def annotate_frame(frame: np.ndarray, rows: pd.DataFrame, axis_length: float = AXIS_LENGTH_M) -> np.ndarray:
    """A copy of a BGR frame with each detected tag's outline (green: located,
    red: detected but not located) and the axes of its estimated pose."""
    img = np.ascontiguousarray(np.asarray(frame, np.uint8).copy())
    scale = max(1, round(img.shape[1] / 640))
    for r in rows.itertuples():
        if not r.detected or r.corners is None:
            continue
        c = np.asarray(r.corners, float).reshape(4, 2)
        ok = r.status == "ok"
        cv2.polylines(img, [np.round(c).astype(np.int32)], True, (0, 200, 0) if ok else (0, 0, 255), scale, cv2.LINE_AA)
        if ok and r.camera_R is not None and r.R is not None:
            K = np.array([[r.fx, 0, r.cx], [0, r.fy, r.cy], [0, 0, 1.0]])
            Rcw = np.asarray(r.camera_R, float).reshape(3, 3)
            C = np.array([r.cam_x, r.cam_y, r.cam_z])
            R_tc = Rcw.T @ np.asarray(r.R, float).reshape(3, 3)
            t_c = Rcw.T @ (np.array([r.x, r.y, r.z]) - C)
            rvec, _ = cv2.Rodrigues(R_tc)
            cv2.drawFrameAxes(img, K, np.zeros(5), rvec, t_c, axis_length, scale)
        org = tuple(int(v) for v in np.round(c.min(axis=0) - [0, 3 * scale]))
        cv2.putText(img, str(r.tag_id), org, cv2.FONT_HERSHEY_SIMPLEX, 0.35 * scale, (255, 255, 0), scale, cv2.LINE_AA)
    return img


def fig12_data(frame_rows: pd.DataFrame, filtered: pd.DataFrame, objects: pd.DataFrame | None = None) -> pd.DataFrame:
    """The plotted data (CSV_COLUMNS): the frame's detections, the static tags'
    filtered means and the object tag's position per location."""
    img = pd.DataFrame(
        {
            "panel": "image", "set": frame_rows["set"], "location": frame_rows["location"], "tag_id": frame_rows["tag_id"],
            "component": frame_rows["component"], "status": frame_rows["status"], "u_px": frame_rows["u"], "v_px": frame_rows["v"],
            "x_m": frame_rows["x"], "y_m": frame_rows["y"], "z_m": frame_rows["z"], "n_estimates": 1,
        }
    )[frame_rows["detected"].to_numpy()]  # fmt: skip
    kept = filtered[filtered["kept"]] if "kept" in filtered else filtered[filtered["status"] == "ok"]
    static = kept[kept["tag_id"] != geo.OBJECT_TAG_ID].groupby("tag_id")
    world = static[["x", "y", "z"]].mean().rename(columns=lambda a: f"{a}_m")
    world["n_estimates"] = static.size()
    world = world.reset_index()
    world["location"] = -1
    if objects is None:
        g = kept[kept["tag_id"] == geo.OBJECT_TAG_ID].groupby("location")
        objects = g[["x", "y", "z"]].mean().assign(n_estimates=g.size()).reset_index()
    obj = objects.rename(columns={"x": "x_m", "y": "y_m", "z": "z_m"})[["location", "x_m", "y_m", "z_m", "n_estimates"]].assign(tag_id=geo.OBJECT_TAG_ID)
    world = pd.concat([world, obj], ignore_index=True)
    world["panel"], world["set"], world["status"] = "world", "", "ok"
    world["component"] = world["tag_id"].map(lambda t: geo.TAG_COMPONENT.get(int(t), "unknown"))
    out = pd.concat([img, world], ignore_index=True)
    return out[list(CSV_COLUMNS)].astype({"location": "int64", "tag_id": "int64", "n_estimates": "int64"})


def write_fig12(
    frame: np.ndarray,
    frame_rows: pd.DataFrame,
    filtered: pd.DataFrame,
    out_png: Path,
    *,
    objects: pd.DataFrame | None = None,
    out_csv: Path | None = None,
) -> pd.DataFrame:
    """Draw Figure 12 to `out_png` (and its data to `out_csv`, default the PNG's
    name with .csv). frame: BGR tracking frame; frame_rows: that frame's rows
    of its set's pose table; filtered: `filter_estimates` output of every set;
    objects: `object_positions` (default: means of the kept object-tag
    estimates per location). Returns the plotted data."""
    data = fig12_data(frame_rows, filtered, objects)
    img = annotate_frame(frame, frame_rows)
    fig = plt.figure(figsize=(14, 5.2), constrained_layout=True)
    gs = fig.add_gridspec(2, 2, width_ratios=[1.7, 1.0])
    ax_img = fig.add_subplot(gs[:, 0])
    ax_img.imshow(img[..., ::-1])
    rows = frame_rows.iloc[:1]
    title = f"{rows['set'].iloc[0]}, location {int(rows['location'].iloc[0])}" if len(rows) else "tracking frame"
    ax_img.set_title(f"Detected tags and poses: {title}")
    ax_img.axis("off")
    world = data[data["panel"] == "world"]
    for k, (a, b, label) in enumerate((("x_m", "y_m", "top view (x-y)"), ("x_m", "z_m", "side view (x-z)"))):
        ax = fig.add_subplot(gs[k, 1])
        for comp, grp in world.groupby("component"):
            moving = grp["tag_id"] == geo.OBJECT_TAG_ID
            ax.scatter(grp[a], grp[b], s=np.where(moving, 8, 30), c=COMPONENT_COLOURS.get(comp, "tab:gray"), label=comp)
        labelled = world[world["tag_id"] != geo.OBJECT_TAG_ID]
        if k == 1:  # the table tags stack up in the side view: label them from above only
            labelled = labelled[labelled["component"] != "table"]
        for r in labelled.itertuples():
            ax.annotate(str(r.tag_id), (getattr(r, a), getattr(r, b)), textcoords="offset points", xytext=(3, 3), fontsize=7)
        ax.set_xlabel(a[0] + " (m)")
        ax.set_ylabel(b[0] + " (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
        ax.set_title(label, fontsize=9)
        if k == 0:
            ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    save_figure(fig, out_png, data, out_csv, float_format="%.6g")
    return data


def write_fig12_from_store(store: Path, estimates: pd.DataFrame, filtered: pd.DataFrame, out_png: Path, *, location: int | None = None, **kw) -> pd.DataFrame:
    """Figure 12 for a frame of the capture store `store`: `estimates` must hold
    that set's rows (a pooled table will do); location: which frame (default:
    the set's first)."""
    cs = open_set(store)
    k = int(cs.locations[0]) if location is None else int(location)
    frame = cs.frame("tracking_rgb", cs.index_of(k))
    rows = estimates[(estimates["set"] == cs.name) & (estimates["location"] == k)]
    if rows.empty:
        raise ValueError(f"{cs.path}: no pose rows for set {cs.name} at location {k}")
    return write_fig12(frame, rows, filtered, out_png, **kw)
