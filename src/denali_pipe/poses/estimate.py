"""Per capture set: tag poses in the world frame, one row per (frame, tag).

The tracking camera is fixed, so where a tag sits along its line of sight
can only come from its own image, while the direction to it is good to
~0.1 mm (docs/performance.md). The set is therefore solved in two steps:

1. The static layout (`layout.estimate_layout`): every static tag's mean
   image over the set's frames, its corners from a photometric fit of its
   pattern (`template`), then one least-squares fit of the camera pose and
   every static tag's pose, with the tags of each table, and the wall tags,
   on a common plane of free height and tilt. Nothing of the design drawing
   is assumed but which surface each tag lies on (see `layout` for why and
   what it achieves). World frame: tag 14's (origin at its centre, x along
   its x axis, z up), as in a release's poses.json.
2. Per frame, with that camera (static over a set):
   - static tags (method `plane`): the ray through the frame's detected tag
     centre, corrected by the detector's bias on that tag (the template fit
     of the mean image against the median detection), meets the tag's plane
     from the layout; their orientation is the layout's. A static tag left out of the layout (its corners contradict
     the others) falls back to its single-tag pose (method `single`).
   - the object tag 1 (method `template`): its corners from the template fit
     to the frame (the set's blur fixed), its pose from them by single-tag
     PnP (IPPE) and the camera; every gantry location stands on its own, so
     an uneven gantry is followed. Where the template fit fails the
     detector's refined corners are used (method `single`).
   IPPE's two-fold ambiguity is resolved by the expected surface normal: the
   layout's for static tags, the design's (face up) for tag 1;
   `ippe_solution` says which of the two (0 = the one with the lower
   reprojection error) was taken.

A tag a frame could not place still gets its row, with a `status` saying why:
ok, missing (not detected: dark frame, occluded, out of view), unexpected
(an id the rig does not have), no_camera (the set's layout could not be
solved: tag 14 never seen), pnp_failed, bad_normal (no IPPE solution within
45 deg of the expected normal), no_intersection. Nothing crashes on dark
frames, missing tags or ambiguous poses; `calibrate.detection_rates` counts
them. Per frame, `board_tags` counts the static tags of the layout it shows
and `board_rms_px` is their detected corners' RMS against the layout's
projection (a camera that moved within the set shows there).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import numpy as np
import pandas as pd

from denali_pipe.core import geometry as geo
from denali_pipe.io.store import open_set
from denali_pipe.poses.detect import DEFAULT_DETECTOR, Detection, TagDetector, to_grey
from denali_pipe.poses.layout import Layout, estimate_layout
from denali_pipe.poses.pnp import Fit, Intrinsics, choose_by_normal, intersect_plane, pixel_ray, project, solve_tag, tracking_intrinsics
from denali_pipe.poses.template import fit_template

log = logging.getLogger(__name__)

DARK_GREY = 30.0  # the real capture's lights-off criterion: mean grey below 30
MAX_NORMAL_ERR_DEG = 45.0
MOVING_TAG_IDS = (geo.OBJECT_TAG_ID,)
EXPECTED_TAG_IDS = tuple(sorted([*geo.STATIC_TAGS, *MOVING_TAG_IDS]))
_EXPECTED = frozenset(EXPECTED_TAG_IDS)

STATUSES = ("ok", "missing", "unexpected", "no_camera", "pnp_failed", "bad_normal", "no_intersection")
METHODS = ("plane", "template", "single")
COLUMNS = (
    "set", "light", "location", "tag_id", "component", "detected", "status", "method",
    "x", "y", "z", "R", "corners", "corners_raw", "u", "v", "edge_px", "refined",
    "reproj_err_px", "ippe_solution", "ippe_alt_ratio", "normal_err_deg", "decision_margin", "hamming",
    "single_x", "single_y", "single_z", "ray_x", "ray_y", "ray_z", "cam_x", "cam_y", "cam_z",
    "camera_R", "board_tags", "board_rms_px", "frame_grey", "dark",
    "image_width", "image_height", "fx", "fy", "cx", "cy", "detector",
)  # fmt: skip


def expected_tag_z(tag_id: int, layout: Layout) -> np.ndarray:
    """The z axis (into the tag) a tag is expected to have, world coordinates:
    the layout's for a static tag it holds, else the design's."""
    if tag_id in layout.tags:
        return layout.tags[tag_id].R[:, 2]
    if tag_id == geo.OBJECT_TAG_ID:
        return geo.OBJECT_TAG_ROTATION[:, 2]
    return geo.STATIC_TAGS[tag_id].R[:, 2]


# --- per frame ------------------------------------------------------------------------------


@dataclass
class FrameObservation:
    """What one frame shows: its grey image (H, W) uint8, mean grey level and
    detections (refined corners)."""

    location: int
    grey: np.ndarray
    grey_mean: float
    detections: dict[int, Detection]


def observe_frame(location: int, frame: np.ndarray, detector: TagDetector) -> FrameObservation:
    """Detect and refine the tags of one frame (BGR or grey uint8)."""
    grey = to_grey(frame)
    return FrameObservation(int(location), grey, float(np.asarray(frame).mean()), {d.tag_id: d for d in detector.detect(grey)})


@dataclass
class _Chosen:
    fit: Fit
    index: int
    angle: float
    alt_ratio: float


def _choose(corners: np.ndarray, K: np.ndarray, R_cw: np.ndarray, expected_z: np.ndarray) -> _Chosen | None:
    """The IPPE solution of a tag's corners whose normal is nearest `expected_z`."""
    fits = solve_tag(corners, K)
    if not fits:
        return None
    k, ang = choose_by_normal(fits, R_cw, expected_z)
    other = [f.rms_px for j, f in enumerate(fits) if j != k]
    ratio = (other[0] / max(fits[k].rms_px, 1e-9)) if other else float("nan")
    return _Chosen(fits[k], k, ang, ratio)


def _board_residual(o: FrameObservation, layout: Layout, K: np.ndarray) -> tuple[int, float]:
    """(static tags of the layout in the frame, their refined corners' RMS px against the layout's projection)."""
    ids = [i for i in layout.tags if i in o.detections]
    if not ids:
        return 0, float("nan")
    cam, local = layout.camera, geo.tag_corners_local()
    d = [project(K, cam.R, cam.t, layout.tags[i].apply(local)) - o.detections[i].corners for i in ids]
    return len(ids), float(np.sqrt(np.mean(np.sum(np.concatenate(d) ** 2, axis=1))))


# --- per set ---------------------------------------------------------------------------------


def estimate_frames(
    frames: Iterable[tuple[int, np.ndarray]],
    intrinsics: Intrinsics,
    *,
    set_name: str = "",
    light: str = "",
    detector: str | TagDetector = DEFAULT_DETECTOR,
) -> pd.DataFrame:
    """Tag poses in the world frame from one set's tracking frames.

    frames: (gantry location, BGR uint8 frame) pairs; intrinsics: for the
    frames' size (`tracking_intrinsics`); detector: a name of DETECTORS or a
    TagDetector. Returns one row per (frame, expected tag) plus one per
    unexpected detection, columns COLUMNS (see the module docstring);
    df.attrs holds the layout, the intrinsics and the detector.
    """
    det = detector if isinstance(detector, TagDetector) else TagDetector(detector)
    K = intrinsics.K
    obs = [observe_frame(k, f, det) for k, f in frames]
    layout = estimate_layout([o.grey for o in obs], [{i: d.corners for i, d in o.detections.items()} for o in obs], K)
    rows = []
    for o in obs:
        board = _board_residual(o, layout, K) if layout is not None else (0, float("nan"))
        ids = list(EXPECTED_TAG_IDS) + sorted(set(o.detections) - _EXPECTED)
        for tid in ids:
            row = _base_row(set_name, light, o, tid, intrinsics, det.kind, layout, board)
            d = o.detections.get(tid)
            if d is None:
                row["status"] = "missing"
            else:
                _detection_fields(row, d)
                if tid not in _EXPECTED:
                    row["status"] = "unexpected"
                elif layout is None:
                    row["status"] = "no_camera"
                else:
                    _fill_estimate(row, o, d, layout, K)
            rows.append(row)
    df = _dtypes(pd.DataFrame(rows, columns=list(COLUMNS)))
    df.attrs.update(
        {
            "set": set_name,
            "layout": None if layout is None else layout.to_dict(),
            "intrinsics": intrinsics.to_dict(),
            "detector": det.kind,
        }
    )
    return df


def _base_row(set_name, light, o: FrameObservation, tid, intr: Intrinsics, kind, layout: Layout | None, board: tuple[int, float]) -> dict:
    row = dict.fromkeys(COLUMNS, None)
    row.update(
        set=set_name, light=light, location=o.location, tag_id=int(tid), component=geo.TAG_COMPONENT.get(tid, "unknown"),
        detected=False, status=None, method=None, refined=False, ippe_solution=-1, hamming=-1,
        board_tags=board[0], board_rms_px=board[1], frame_grey=o.grey_mean, dark=o.grey_mean < DARK_GREY,
        image_width=intr.width, image_height=intr.height, fx=intr.fx, fy=intr.fy, cx=intr.cx, cy=intr.cy, detector=kind,
    )  # fmt: skip
    if layout is not None:
        c = layout.camera.camera_centre
        row.update(cam_x=c[0], cam_y=c[1], cam_z=c[2], camera_R=layout.camera.R_cw.ravel().tolist())
    return row


def _detection_fields(row: dict, d: Detection) -> None:
    c = d.centre
    row.update(
        detected=True, corners=d.corners.ravel().tolist(), corners_raw=d.raw_corners.ravel().tolist(),
        u=c[0], v=c[1], edge_px=d.edge_px, refined=d.refined, decision_margin=d.margin, hamming=d.hamming,
    )  # fmt: skip


def _fill_estimate(row: dict, o: FrameObservation, d: Detection, layout: Layout, K: np.ndarray) -> None:
    """Locate one detected expected tag (see the module docstring)."""
    tid, cam = d.tag_id, layout.camera
    moving = tid not in geo.STATIC_TAGS
    corners, method = d.corners, "single"
    if moving and (tf := fit_template(o.grey, d.corners, tid, sigma=layout.blur_px, fit_sigma=False)) is not None:
        corners, method = tf.corners, "template"
    ch = _choose(corners, K, cam.R_cw, expected_tag_z(tid, layout))
    if ch is None:
        row["status"] = "pnp_failed"
        return
    ray = pixel_ray(d.centre + layout.centre_offset.get(tid, 0.0), K, cam.R_cw)
    single = cam.R_cw @ ch.fit.t + cam.camera_centre
    R_world = layout.tags[tid].R if tid in layout.tags else cam.R_cw @ ch.fit.R
    row.update(
        ray_x=ray[0], ray_y=ray[1], ray_z=ray[2], single_x=single[0], single_y=single[1], single_z=single[2],
        reproj_err_px=ch.fit.rms_px, ippe_solution=ch.index, ippe_alt_ratio=ch.alt_ratio, normal_err_deg=ch.angle,
        R=R_world.ravel().tolist(),
    )  # fmt: skip
    if ch.angle > MAX_NORMAL_ERR_DEG:
        row["status"] = "bad_normal"
        return
    p = single
    if tid in layout.tags:
        tag = layout.tags[tid]
        method, p = "plane", intersect_plane(cam.camera_centre, ray, tag.t, tag.R[:, 2])
    if p is None:
        row["status"] = "no_intersection"
        return
    row.update(status="ok", method=method, x=p[0], y=p[1], z=p[2])


_FLOAT_COLS = (
    "x", "y", "z", "u", "v", "edge_px", "reproj_err_px", "ippe_alt_ratio", "normal_err_deg", "decision_margin",
    "single_x", "single_y", "single_z", "ray_x", "ray_y", "ray_z", "cam_x", "cam_y", "cam_z",
    "board_rms_px", "frame_grey", "fx", "fy", "cx", "cy",
)  # fmt: skip
_INT_COLS = ("location", "tag_id", "ippe_solution", "hamming", "board_tags", "image_width", "image_height")
_BOOL_COLS = ("detected", "refined", "dark")
_STR_COLS = ("set", "light", "component", "status", "method", "detector")


def _dtypes(df: pd.DataFrame) -> pd.DataFrame:
    return df.astype(
        {**dict.fromkeys(_FLOAT_COLS, "float64"), **dict.fromkeys(_INT_COLS, "int64"), **dict.fromkeys(_BOOL_COLS, "bool"),
         **dict.fromkeys(_STR_COLS, "object")}
    )  # fmt: skip


def detect_set(
    store: Path,
    *,
    detector: str = DEFAULT_DETECTOR,
    refine: bool = True,
    threads: int = 1,
    require_object: bool = False,
) -> pd.DataFrame:
    """Tag poses of one capture set from its Zarr store's tracking RGB frames
    (see `estimate_frames`). Intrinsics from the store's metadata record
    (`tracking_camera`), else the real camera's scaled to the frame size.

    detector, refine, threads: the TagDetector's kind, corner refinement and
    AprilTag threads. require_object: raise ValueError naming the store, the
    set and the gantry locations where the object tag has no usable estimate
    (otherwise those rows keep their status and `calibrate` decides).
    """
    cs = open_set(store)
    if "tracking_rgb" not in cs.modalities:
        raise ValueError(f"{cs.path}: capture set {cs.name} has no tracking_rgb frames (store has {list(cs.modalities)})")
    shape = cs.frames("tracking_rgb").shape[1:]
    intr, source = tracking_intrinsics(cs.metadata, shape)
    det = TagDetector(detector, refine=refine, nthreads=threads)
    df = estimate_frames(
        cs.iter_frames("tracking_rgb"), intr, set_name=cs.name, light=cs.capture_set.light,
        detector=det,
    )  # fmt: skip
    df.attrs["intrinsics_source"] = source
    n_ok = int((df["status"] == "ok").sum())
    log.info("%s: %d frames, %d tag estimates (intrinsics from %s)", cs.name, len(cs), n_ok, source)
    if require_object:
        check_object_coverage(df, cs.locations, f"{cs.path}: capture set {cs.name}")
    return df


def check_object_coverage(df: pd.DataFrame, locations: Iterable[int], where: str) -> None:
    """ValueError naming `where` (a set or sets) and every gantry location
    without an `ok` object-tag estimate."""
    ok = set(df.loc[(df["tag_id"] == geo.OBJECT_TAG_ID) & (df["status"] == "ok"), "location"].astype(int))
    missing = [int(k) for k in locations if int(k) not in ok]
    if missing:
        why = df[(df["tag_id"] == geo.OBJECT_TAG_ID) & df["location"].isin(missing)].groupby("location")["status"].agg(lambda s: ",".join(sorted(set(s))))
        detail = "; ".join(f"location {k}: {why.get(k, 'no frame')}" for k in missing)
        raise ValueError(f"{where}: no usable object-tag (tag {geo.OBJECT_TAG_ID}) estimate at gantry location(s) {missing} ({detail})")
