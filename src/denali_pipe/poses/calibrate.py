"""Scene calibration from the given sets' tag estimates: the object tag's
position per gantry location (the regression targets), the scene description
that the digital twin reads (scene.json), and detection rates per tag and
lighting. The workflow calibrates from the light-on background sets (fixed
whatever objects a configuration adds) and runs the same pooling over every
light-on set for Table 6 and Fig 12.

Inputs are `estimate.detect_set` tables, one per set, pooled. Steps:
1. `filtering.filter_estimates`: |z| > 2 rejection per static tag and per
   (object tag, location).
2. Summaries: `object_positions`, `scene_dict`, `detection_rates`
   (Table 6 itself is `report.table6`).

Design-drawing facts used: the wall's and the tables' extents relative to
their tags, the object mount (geometry.OBJECT_MOUNT) and the sensor's offset
from tag 0 (`sensor_mount`). Positions and orientations, the tables' heights
and tilts included, come from the estimates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.poses.estimate import STATUSES, check_object_coverage
from denali_pipe.poses.filtering import DEFAULT_METHOD, THRESHOLD, filter_estimates, summarise
from denali_pipe.poses.pnp import mean_rotation, rigid_fit

SCENE_VERSION = 2  # 2: a plane per table top (table.planes), the tag-1 rotation per location


def pool(estimates: pd.DataFrame | Iterable[pd.DataFrame]) -> pd.DataFrame:
    """One table of every set's estimates (rows keep their set name)."""
    if isinstance(estimates, pd.DataFrame):
        return estimates.reset_index(drop=True)
    frames = [e for e in estimates]
    if not frames:
        raise ValueError("no pose estimates to calibrate from (no capture sets)")
    return pd.concat(frames, ignore_index=True)


# --- the regression targets ---------------------------------------------------------------


def object_positions(filtered: pd.DataFrame, locations: Iterable[int] | None = None, estimates: pd.DataFrame | None = None) -> pd.DataFrame:
    """Object-tag (tag 1) centre per gantry location, in metres, from the
    filtered estimates (`filter_estimates`): location, gantry_row,
    gantry_col, x, y, z, x_std, y_std, z_std (ddof=1), n_raw, n_estimates,
    n_rejected, flag, n_sets.

    locations: the locations that must be covered (default: every location
    with a frame in `estimates`, else in `filtered`). A location without a
    usable estimate raises ValueError naming it and the sets searched.
    """
    obj = filtered[filtered["tag_id"] == geo.OBJECT_TAG_ID]
    source = estimates if estimates is not None else filtered
    if locations is None:
        locations = sorted(set(source["location"].astype(int)))
    locations = [int(k) for k in locations]
    sets = sorted(set(source["set"]))
    check_object_coverage(source if estimates is not None else obj, locations, f"capture set(s) {', '.join(sets)}")
    s = summarise(obj, "location", expected=locations)
    s = s.rename(columns={f"{a}_mean": a for a in "xyz"})
    kept = obj[obj["kept"]]
    s["n_sets"] = s["location"].map(kept.groupby("location")["set"].nunique()).fillna(0).astype("int64")
    row, col = geo.gantry_row_col(s["location"].to_numpy())
    s.insert(1, "gantry_row", row.astype("int64"))
    s.insert(2, "gantry_col", col.astype("int64"))
    cols = ["location", "gantry_row", "gantry_col", "x", "y", "z", "x_std", "y_std", "z_std", "n_raw", "n_estimates", "n_rejected", "flag", "n_sets"]
    return s[cols]


# --- detection rates -------------------------------------------------------------------------


def detection_rates(estimates: pd.DataFrame) -> pd.DataFrame:
    """Per lighting and tag: frames, detections, estimates and why the rest
    failed. Rows for every expected tag in every lighting present (a tag never
    seen has rate 0), plus any unexpected id detected. Columns: light, tag_id,
    component, n_frames, n_detected, detection_rate, n_ok, estimate_rate,
    n_dark_frames, n_refined, n_ippe_flipped (the lower-error IPPE solution
    had the wrong normal), and n_<status> for each failure status."""
    df = estimates
    frames = df.drop_duplicates(["set", "location"])
    out = []
    for light, fr in frames.groupby("light", sort=True):
        n_frames = len(fr)
        n_dark = int(fr["dark"].sum())
        sub = df[df["light"] == light]
        ids = sorted(set(sub["tag_id"].astype(int)))
        for tid in ids:
            t = sub[sub["tag_id"] == tid]
            det = t[t["detected"]]
            rec = {
                "light": light, "tag_id": tid, "component": geo.TAG_COMPONENT.get(tid, "unknown"),
                "n_frames": n_frames, "n_detected": len(det), "detection_rate": len(det) / n_frames if n_frames else np.nan,
                "n_ok": int((t["status"] == "ok").sum()), "n_dark_frames": n_dark,
                "n_refined": int(det["refined"].sum()), "n_ippe_flipped": int((det["ippe_solution"] == 1).sum()),
            }  # fmt: skip
            rec["estimate_rate"] = rec["n_ok"] / n_frames if n_frames else np.nan
            for st in STATUSES[1:]:
                rec[f"n_{st}"] = int((t["status"] == st).sum())
            out.append(rec)
    cols = ["light", "tag_id", "component", "n_frames", "n_detected", "detection_rate", "n_ok", "estimate_rate", "n_dark_frames", "n_refined", "n_ippe_flipped"]
    cols += [f"n_{st}" for st in STATUSES[1:]]
    return pd.DataFrame(out, columns=cols)


# --- scene.json -----------------------------------------------------------------------------


def sensor_mount() -> geo.Pose:
    """Tag 0 -> TMF8828 pose (the co-located camera's, OpenCV axes: z forward)
    from the rig's design: the fixed offset of the sensor on its mount."""
    cam = geo.COLOCATED_CAMERA
    sensor = geo.pose(cam.R_wc.T, cam.position)
    tag0 = geo.STATIC_TAGS[geo.SENSOR_TAG_ID]
    inv = geo.pose(tag0.R.T, -tag0.R.T @ tag0.t)
    return inv @ sensor


def _pose_dict(R: np.ndarray, t: np.ndarray) -> dict:
    return {"R": np.asarray(R).tolist(), "t": np.asarray(t).tolist()}


def _rect_dict(centre, u, v, size) -> dict:
    r = geo.Rect(np.asarray(centre, float), np.asarray(u, float), np.asarray(v, float), tuple(size))
    return {"centre": r.centre.tolist(), "u": r.u.tolist(), "v": r.v.tolist(), "size": list(size), "normal": r.normal.tolist(), "corners": r.corners().tolist()}


def _map_design(ids: list[int], means: dict[int, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Rigid map design -> estimated from tags `ids` (rotation from >= 3 tags,
    translation only from fewer)."""
    have = [i for i in ids if i in means]
    if not have:
        raise ValueError(f"no estimate of any of tags {ids}")
    src = np.array([geo.STATIC_TAGS[i].t for i in have])
    dst = np.array([means[i] for i in have])
    if len(have) >= 3:
        return rigid_fit(src, dst)
    return np.eye(3), (dst - src).mean(axis=0)


def _mean_rotation(rows: pd.DataFrame) -> np.ndarray:
    """Chordal mean (3, 3) of the rows' tag rotations (`R` column)."""
    return mean_rotation(np.stack(rows["R"].map(np.asarray).to_list()))


def _yaw_only(R: np.ndarray) -> tuple[np.ndarray, float]:
    """The face-up rotation rot_z(yaw) @ FACE_UP nearest R (a tag on a horizontal plane)."""
    x = R[:, 0]
    yaw = float(np.degrees(np.arctan2(x[1], x[0])))
    return geo.rot_z(yaw) @ geo.FACE_UP, yaw


def scene_dict(filtered: pd.DataFrame, objects: pd.DataFrame) -> dict:
    """The calibrated scene (JSON-ready): world frame, tags, tables, relay wall,
    sensor, tracking camera, gantry and object poses per location.

    filtered: `filter_estimates` output (kept rows are used); objects:
    `object_positions` output.
    """
    kept = filtered[filtered["kept"]]
    static = kept[kept["tag_id"].isin(list(geo.STATIC_TAGS))]
    means = {int(t): g[["x", "y", "z"]].mean().to_numpy() for t, g in static.groupby("tag_id")}
    rots = {int(t): _mean_rotation(g) for t, g in static.groupby("tag_id")}
    counts = static.groupby("tag_id").size()

    tags = {
        str(t): {"component": geo.TAG_COMPONENT[t], "position": means[t].tolist(), "rotation": rots[t].tolist(), "n_estimates": int(counts[t])}
        for t in sorted(means)
    }

    # Tables: each top through its own tags (their heights and tilts), the
    # rectangle carried from the design by the tags' offset.
    located = {i: geo.pose(rots[i], means[i]) for i in means}
    tops = {k: geo.table_from_tags(k, located) for k, ids in geo.TABLE_TAGS.items() if any(i in located for i in ids)}
    table = {}
    if tops:
        table = {
            "planes": {str(k): {"point": r.centre.tolist(), "normal": r.normal.tolist(), "tilt_deg": float(np.degrees(np.arccos(min(1.0, r.normal[2]))))} for k, r in tops.items()},
            "rectangles": {str(k): _rect_dict(r.centre, r.u, r.v, r.size) for k, r in tops.items()},
        }  # fmt: skip

    # Relay wall: its tags' plane; extent from the design relative to the tags;
    # the NLOS wall's normal forced to exactly -y (as the reference twin does).
    wall = None
    wall_ids = [i for i in geo.WALL_TAG_IDS if i in means]
    if wall_ids:
        Rw, tw = _map_design(list(geo.WALL_TAG_IDS), means)
        centre = Rw @ geo.WALL.centre + tw
        measured_n = Rw @ geo.WALL.normal
        forced = _rect_dict(centre, geo.WALL.u, geo.WALL.v, geo.WALL.size)
        wall = {
            **forced,
            "plane": {"point": centre.tolist(), "normal": geo.WALL.normal.tolist()},
            "measured": _rect_dict(centre, Rw @ geo.WALL.u, Rw @ geo.WALL.v, geo.WALL.size),
            "measured_tilt_deg": float(np.degrees(np.arccos(np.clip(measured_n @ geo.WALL.normal, -1, 1)))),
            "tags": wall_ids,
        }

    # Sensor: tag 0 lies face up on the mount (yaw only), the sensor at the design offset.
    sensor = None
    if geo.SENSOR_TAG_ID in means:
        R0, yaw = _yaw_only(rots[geo.SENSOR_TAG_ID])
        tag0 = geo.pose(R0, means[geo.SENSOR_TAG_ID])
        s = tag0 @ sensor_mount()
        sensor = {"tag_pose": tag0.to_dict(), "tag_yaw_deg": yaw, "pose": s.to_dict(), "position": s.t.tolist(), "forward": s.R[:, 2].tolist()}

    # Tracking camera: mean over every frame's board fit.
    frames = filtered.drop_duplicates(["set", "location"])
    frames = frames[frames["camera_R"].notna()]
    camera = None
    if len(frames):
        C = frames[["cam_x", "cam_y", "cam_z"]].to_numpy(float).mean(axis=0)
        R_cw = mean_rotation(np.stack(frames["camera_R"].map(np.asarray).to_list()))
        intr = frames[["image_width", "image_height", "fx", "fy", "cx", "cy"]].mode().iloc[0]
        camera = {
            "intrinsics": {"width": int(intr["image_width"]), "height": int(intr["image_height"]), **{k: float(intr[k]) for k in ("fx", "fy", "cx", "cy")}},
            "position": C.tolist(), "forward": R_cw[:, 2].tolist(),
            "R_world_to_camera": R_cw.T.tolist(), "t_world_to_camera": (-R_cw.T @ C).tolist(),
            "position_std": frames[["cam_x", "cam_y", "cam_z"]].to_numpy(float).std(axis=0, ddof=1).tolist() if len(frames) > 1 else None,
            "n_frames": int(len(frames)),
        }  # fmt: skip

    # Gantry and objects: the tag's pose per location (its tilt may vary with
    # the carriage's position); the mean rotation over every location beside.
    obj_rows = kept[kept["tag_id"] == geo.OBJECT_TAG_ID]
    gantry, locs = None, {}
    if len(obj_rows):
        gantry = {"tag_rotation": _mean_rotation(obj_rows).tolist()}
        R1 = {int(k): _mean_rotation(g) for k, g in obj_rows.groupby("location")}
        for r in objects.itertuples():
            t1 = geo.pose(R1[int(r.location)], [r.x, r.y, r.z])
            ob = t1 @ geo.OBJECT_MOUNT
            rec = {"tag1": t1.to_dict(), "object": ob.to_dict(), "n_estimates": int(r.n_estimates)}
            if wall is not None:
                rec["wall_distance_m"] = float((np.asarray(wall["centre"]) - ob.t) @ -geo.WALL.normal)
            locs[str(int(r.location))] = rec

    return {
        "version": SCENE_VERSION,
        "frame": {
            "units": "m",
            "origin": f"centre of tag {geo.WORLD_ORIGIN_TAG_ID}",
            "axes": f"tag {geo.WORLD_ORIGIN_TAG_ID}'s: +x along its x axis (toward tags 11/13/15), +y toward the relay wall, +z up (its face)",
        },
        "sets": sorted(set(filtered["set"])),
        "tags": tags,
        "table": table,
        "wall": wall,
        "sensor": sensor,
        "tracking_camera": camera,
        "gantry": gantry,
        "object_mount": geo.OBJECT_MOUNT.to_dict(),
        "locations": locs,
    }


# --- all of it -----------------------------------------------------------------------------


@dataclass
class Calibration:
    estimates: pd.DataFrame  # pooled, every row
    filtered: pd.DataFrame  # ok rows with `kept`
    object_positions: pd.DataFrame
    detection_rates: pd.DataFrame
    scene: dict


def calibrate(
    estimates: pd.DataFrame | Iterable[pd.DataFrame],
    *,
    locations: Iterable[int] | None = None,
    threshold: float = THRESHOLD,
    method: str = DEFAULT_METHOD,
) -> Calibration:
    """Everything the calibration stage derives from the per-set tables of
    light-on sets: |z| > 2 filtering, object positions, detection rates,
    scene. Raises ValueError when a gantry location has no usable object-tag
    estimate (naming it and the sets)."""
    est = pool(estimates)
    filt = filter_estimates(est, threshold=threshold, method=method)
    objs = object_positions(filt, locations, estimates=est)
    return Calibration(est, filt, objs, detection_rates(est), scene_dict(filt, objs))
