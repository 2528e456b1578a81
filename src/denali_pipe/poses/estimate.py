"""Per capture set: tag poses in the estimated world frame, one row per
(frame, tag).

How each position is measured (single-tag distance along the line of sight is
biased by several mm to several cm for tags spanning 10-50 px, whatever the
averaging, while the direction to a tag's centre is good to ~0.1 mm):

1. Camera pose per frame from every detected table tag (10-15) at once, as
   one rigid board whose layout is the rig's design drawing
   (`geometry.STATIC_TAGS`); this fixes a provisional "board" frame.
2. Table tags (method `board`): the ray through the tag's centre meets the
   board's plane (the table top).
3. The world frame is then estimated, not copied: origin at the median
   located tag 14, +x along the table rows toward 11/13/15, +y along the
   columns toward the wall (10/12), +z up. On the rig it lies within a
   fraction of a millimetre of the board frame; on a real rig it absorbs
   where the tags actually are.
4. Wall tags (method `plane`): per frame, the wall tags 5-7 form a second
   rigid board (their layout on the wall from the design); composed with the
   camera pose it gives the wall's plane, and each wall tag's centre ray meets
   it. A frame with fewer than two wall tags uses the set's median wall plane.
5. Sensor tag 0 and object tag 1 (method `plane`): horizontal planes
   z = h. h is the median over the set's frames of the tag's single-tag PnP
   height (IPPE, corners refined by `detect.refine_corners`, which removes the
   saturation bias; what remains averages out over frames), and each frame's
   centre ray meets the plane. `calibrate.replane` re-estimates h from every
   set pooled. `gantry_plane="fit"` fits a tilted plane z = a + b x + c y to
   the object tag instead (a gantry that is not level).
6. Orientation of every tag from its IPPE solution, the two-fold ambiguity
   resolved by the design's surface normal (table, sensor and object tags face
   up, wall tags face -y); `ippe_solution` says which of the two (0 = the one
   with the lower reprojection error) was taken.

A tag a frame could not place still gets its row, with a `status` saying why:
ok, missing (not detected: dark frame, occluded, out of view), unexpected
(an id the rig does not have), no_camera (too few table tags for the board),
pnp_failed, bad_normal (no IPPE solution within 45 deg of the known normal),
no_intersection. Nothing crashes on dark frames, missing tags or ambiguous
poses; `calibrate.detection_rates` counts them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np
import pandas as pd

from denali_pipe import geometry as geo
from denali_pipe.io.store import open_set
from denali_pipe.poses.detect import DEFAULT_DETECTOR, Detection, TagDetector
from denali_pipe.poses.pnp import (
    Fit,
    Intrinsics,
    choose_by_normal,
    intersect_plane,
    pixel_ray,
    solve_board,
    solve_tag,
    tracking_intrinsics,
)

log = logging.getLogger(__name__)

DARK_GREY = 30.0  # the real capture's lights-off criterion: mean grey below 30
MAX_NORMAL_ERR_DEG = 45.0
GANTRY_PLANES = ("horizontal", "fit")
MOVING_TAG_IDS = (geo.OBJECT_TAG_ID,)
EXPECTED_TAG_IDS = tuple(sorted([*geo.STATIC_TAGS, *MOVING_TAG_IDS]))
TABLE_LAYOUT = {i: geo.STATIC_TAGS[i] for i in geo.TABLE_TAG_IDS}
WALL_LAYOUT = {i: geo.STATIC_TAGS[i] for i in geo.WALL_TAG_IDS}
HEIGHT_TAG_IDS = (geo.SENSOR_TAG_ID, geo.OBJECT_TAG_ID)  # located on horizontal planes of estimated height
_EXPECTED = frozenset(EXPECTED_TAG_IDS)


def expected_tag_z(tag_id: int) -> np.ndarray:
    """The design's z axis (into the tag) of a tag in world coordinates: the
    known surface normal that resolves the IPPE ambiguity."""
    if tag_id == geo.OBJECT_TAG_ID:
        return geo.OBJECT_TAG_ROTATION[:, 2]
    return geo.STATIC_TAGS[tag_id].R[:, 2]


STATUSES = ("ok", "missing", "unexpected", "no_camera", "pnp_failed", "bad_normal", "no_intersection")
METHODS = ("board", "plane", "single")
COLUMNS = (
    "set", "light", "location", "tag_id", "component", "detected", "status", "method",
    "x", "y", "z", "R", "corners", "corners_raw", "u", "v", "edge_px", "refined",
    "reproj_err_px", "ippe_solution", "ippe_alt_ratio", "normal_err_deg", "decision_margin", "hamming",
    "single_x", "single_y", "single_z", "plane_z", "ray_x", "ray_y", "ray_z", "cam_x", "cam_y", "cam_z",
    "camera_R", "board_tags", "board_rms_px", "wall_tags", "frame_grey", "dark",
    "image_width", "image_height", "fx", "fy", "cx", "cy", "detector",
)  # fmt: skip


# --- the world frame ----------------------------------------------------------------------


@dataclass(frozen=True)
class WorldFrame:
    """World frame estimated in board coordinates: A's rows are the world x, y, z
    axes, `origin` the world origin; p_world = A (p_board - origin)."""

    A: np.ndarray
    origin: np.ndarray
    tags: tuple[int, ...] = ()

    def point(self, p: np.ndarray) -> np.ndarray:
        return self.A @ (np.asarray(p, float) - self.origin)

    def vector(self, v: np.ndarray) -> np.ndarray:
        return self.A @ np.asarray(v, float)

    def to_dict(self) -> dict:
        return {"axes_in_board": self.A.tolist(), "origin_in_board": self.origin.tolist(), "tags": list(self.tags)}


def _table_pairs() -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Design pairs of table tags: along rows (same y, toward +x) and along
    columns (same x, toward +y, the wall)."""
    ids = sorted(geo.TABLE_TAG_IDS)
    p = {i: geo.STATIC_TAGS[i].t for i in ids}
    rows = [(a, b) for a in ids for b in ids if abs(p[a][1] - p[b][1]) < 0.01 and p[b][0] - p[a][0] > 0.1]
    cols = [(a, b) for a in ids for b in ids if abs(p[a][0] - p[b][0]) < 0.01 and p[b][1] - p[a][1] > 0.1]
    return rows, cols


def estimate_world_frame(table_positions: dict[int, np.ndarray]) -> WorldFrame:
    """World frame from located table-tag centres (board coordinates): origin
    at tag 14, x the mean unit direction along the rows (10->11, 12->13,
    14->15), y along the columns toward the wall, orthonormalised with z = x
    cross y (up). Missing tags fall back to the board's axes or origin."""
    pos = {int(k): np.asarray(v, float) for k, v in table_positions.items() if np.all(np.isfinite(v))}
    rows, cols = _table_pairs()

    def mean_dir(pairs, default):
        d = [pos[b] - pos[a] for a, b in pairs if a in pos and b in pos]
        if not d:
            return np.asarray(default, float)
        v = np.mean([x / np.linalg.norm(x) for x in d], axis=0)
        return v / np.linalg.norm(v)

    x = mean_dir(rows, (1.0, 0, 0))
    y = mean_dir(cols, (0, 1.0, 0))
    z = np.cross(x, y)
    z /= np.linalg.norm(z)
    x = x - (x @ z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    origin = pos.get(geo.WORLD_ORIGIN_TAG_ID, geo.STATIC_TAGS[geo.WORLD_ORIGIN_TAG_ID].t)
    return WorldFrame(np.stack([x, y, z]), np.asarray(origin, float), tuple(sorted(pos)))


# --- per frame ------------------------------------------------------------------------------


@dataclass
class FrameObservation:
    """What one frame shows, in board coordinates: detections, the camera's board
    fit (None: fewer than two table tags), the wall board's fit in the camera
    frame, and each detected tag's IPPE solutions."""

    location: int
    grey_mean: float
    detections: dict[int, Detection]
    camera: Fit | None
    wall: Fit | None
    singles: dict[int, list[Fit]] = field(default_factory=dict)

    def ray(self, tag_id: int, K: np.ndarray) -> np.ndarray:
        return pixel_ray(self.detections[tag_id].centre, K, self.camera.R_cw)

    def wall_plane(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The wall tags' plane (point, unit normal facing the room) in board coordinates."""
        if self.camera is None or self.wall is None:
            return None
        M = self.camera.R.T @ self.wall.R
        m = self.camera.R.T @ (self.wall.t - self.camera.t)
        centre = np.mean([WALL_LAYOUT[i].t for i in WALL_LAYOUT], axis=0)
        return M @ centre + m, M @ -WALL_LAYOUT[min(WALL_LAYOUT)].R[:, 2]


def observe_frame(location: int, frame: np.ndarray, detector: TagDetector, intr: Intrinsics) -> FrameObservation:
    """Detect, refine and solve everything one frame allows (no set-level input)."""
    frame = np.asarray(frame)
    grey_mean = float(frame.mean())
    dets = {d.tag_id: d for d in detector.detect(frame)}
    K = intr.K
    corners = {i: d.corners for i, d in dets.items()}
    camera = solve_board(corners, TABLE_LAYOUT, K)
    wall = solve_board(corners, WALL_LAYOUT, K) if camera is not None else None
    singles = {i: solve_tag(d.corners, K) for i, d in dets.items()}
    return FrameObservation(int(location), grey_mean, dets, camera, wall, singles)


# --- per set ---------------------------------------------------------------------------------


def _median_point(points: list[np.ndarray]) -> np.ndarray | None:
    return np.median(np.asarray(points), axis=0) if points else None


@dataclass
class _Chosen:
    fit: Fit
    index: int
    angle: float
    alt_ratio: float


def _choose(obs: FrameObservation, tid: int) -> _Chosen | None:
    fits = obs.singles.get(tid) or []
    if not fits or obs.camera is None:
        return None
    k, ang = choose_by_normal(fits, obs.camera.R_cw, expected_tag_z(tid))
    other = [f.rms_px for j, f in enumerate(fits) if j != k]
    ratio = (other[0] / max(fits[k].rms_px, 1e-9)) if other else float("nan")
    return _Chosen(fits[k], k, ang, ratio)


def _single_point(obs: FrameObservation, ch: _Chosen) -> np.ndarray:
    """The tag centre by single-tag PnP, board coordinates."""
    return obs.camera.R_cw @ ch.fit.t + obs.camera.camera_centre


def estimate_frames(
    frames: Iterable[tuple[int, np.ndarray]],
    intrinsics: Intrinsics,
    *,
    set_name: str = "",
    light: str = "",
    detector: str | TagDetector = DEFAULT_DETECTOR,
    gantry_plane: str = "horizontal",
    heights: dict[int, float] | None = None,
) -> pd.DataFrame:
    """Tag poses in the estimated world frame from one set's tracking frames.

    frames: (gantry location, BGR uint8 frame) pairs; intrinsics: for the
    frames' size (`tracking_intrinsics`); detector: a name of DETECTORS or a
    TagDetector; heights: known plane heights (m, world z) of tag 0 and/or
    tag 1 (e.g. measured on the rig), used instead of estimating them.
    Returns one row per (frame, expected tag) plus one per unexpected
    detection, columns COLUMNS (see the module docstring); df.attrs holds the
    world frame, the planes, the intrinsics and the detector.
    """
    if gantry_plane not in GANTRY_PLANES:
        raise ValueError(f"gantry_plane must be one of {list(GANTRY_PLANES)}, got {gantry_plane!r}")
    known = {int(t): float(h) for t, h in (heights or {}).items()}
    if set(known) - set(HEIGHT_TAG_IDS):
        raise ValueError(f"heights: tags {sorted(set(known) - set(HEIGHT_TAG_IDS))} are not located on a horizontal plane (tags {list(HEIGHT_TAG_IDS)} are)")
    det = detector if isinstance(detector, TagDetector) else TagDetector(detector)
    K = intrinsics.K
    obs = [observe_frame(k, f, det, intrinsics) for k, f in frames]

    # Table tags on the board's plane (z = 0 of the design) -> the world frame.
    table_pts: dict[int, list[np.ndarray]] = {}
    for o in obs:
        if o.camera is None:
            continue
        for tid in TABLE_LAYOUT:
            if tid in o.detections:
                p = intersect_plane(o.camera.camera_centre, o.ray(tid, K), np.zeros(3), np.array([0, 0, 1.0]))
                if p is not None:
                    table_pts.setdefault(tid, []).append(p)
    wf = estimate_world_frame({t: _median_point(v) for t, v in table_pts.items()})

    # Set-level planes in world coordinates: median wall plane, heights of tags 0 and 1.
    walls = [w for w in (o.wall_plane() for o in obs) if w is not None]
    set_wall = None
    if walls:
        n = np.median([w[1] for w in walls], axis=0)
        set_wall = (wf.point(np.median([w[0] for w in walls], axis=0)), wf.vector(n / np.linalg.norm(n)))
    singles_w: dict[int, list[tuple[int, np.ndarray]]] = {t: [] for t in HEIGHT_TAG_IDS}
    chosen: dict[tuple[int, int], _Chosen | None] = {}
    for i, o in enumerate(obs):
        for tid in o.detections:
            if tid not in _EXPECTED:
                continue
            ch = chosen[i, tid] = _choose(o, tid)
            if tid in singles_w and ch is not None and ch.angle <= MAX_NORMAL_ERR_DEG:
                singles_w[tid].append((o.location, wf.point(_single_point(o, ch))))
    planes = {tid: _height_plane(tid, pts, gantry_plane) for tid, pts in singles_w.items()}
    for tid, h in known.items():
        planes[tid] = (np.array([0.0, 0.0, h]), np.array([0.0, 0.0, 1.0]))

    rows = []
    for i, o in enumerate(obs):
        cam_c = wf.point(o.camera.camera_centre) if o.camera is not None else None
        cam_R = wf.A @ o.camera.R_cw if o.camera is not None else None
        frame_wall = None
        if (wp := o.wall_plane()) is not None:
            frame_wall = (wf.point(wp[0]), wf.vector(wp[1]))
        ids = list(EXPECTED_TAG_IDS) + sorted(set(o.detections) - set(EXPECTED_TAG_IDS))
        for tid in ids:
            row = _base_row(set_name, light, o, tid, intrinsics, det.kind, cam_c, cam_R)
            d = o.detections.get(tid)
            if d is None:
                row["status"] = "missing"
                rows.append(row)
                continue
            _detection_fields(row, d)
            if tid not in EXPECTED_TAG_IDS:
                row["status"] = "unexpected"
            elif o.camera is None:
                row["status"] = "no_camera"
            elif (ch := chosen.get((i, tid))) is None:
                row["status"] = "pnp_failed"
            else:
                _fill_estimate(row, o, tid, ch, wf, cam_c, cam_R, K, frame_wall, set_wall, planes)
            rows.append(row)
    df = pd.DataFrame(rows, columns=list(COLUMNS))
    df = _dtypes(df)
    df.attrs.update(
        {
            "set": set_name,
            "world_frame": wf.to_dict(),
            "planes": {str(t): (None if p is None else {"point": p[0].tolist(), "normal": p[1].tolist()}) for t, p in planes.items()},
            "intrinsics": intrinsics.to_dict(),
            "detector": det.kind,
            "gantry_plane": gantry_plane,
        }
    )
    return df


def _height_plane(tid: int, pts: list[tuple[int, np.ndarray]], mode: str) -> tuple[np.ndarray, np.ndarray] | None:
    """(point, normal) in world coordinates of the plane a height-located tag
    moves in: horizontal at the median single-tag height or, for the gantry
    with mode "fit", a least-squares plane z = a + b x + c y (needs three
    non-collinear locations, else horizontal)."""
    if not pts:
        return None
    p = np.asarray([q for _, q in pts])
    h = float(np.median(p[:, 2]))
    if tid == geo.OBJECT_TAG_ID and mode == "fit":
        A = np.c_[np.ones(len(p)), p[:, 0], p[:, 1]]
        if np.linalg.matrix_rank(A - A.mean(axis=0) * [0, 1, 1]) == 3:
            coef, *_ = np.linalg.lstsq(A, p[:, 2], rcond=None)
            c = np.median(p[:, :2], axis=0)
            point = np.array([c[0], c[1], coef[0] + coef[1] * c[0] + coef[2] * c[1]])
            n = np.array([-coef[1], -coef[2], 1.0])
            return point, n / np.linalg.norm(n)
    return np.array([0.0, 0.0, h]), np.array([0.0, 0.0, 1.0])


def _base_row(set_name, light, o: FrameObservation, tid, intr: Intrinsics, kind, cam_c, cam_R) -> dict:
    nan = float("nan")
    row = dict.fromkeys(COLUMNS, None)
    row.update(
        set=set_name, light=light, location=o.location, tag_id=int(tid), component=geo.TAG_COMPONENT.get(tid, "unknown"),
        detected=False, status=None, method=None, refined=False, ippe_solution=-1, hamming=-1,
        board_tags=0 if o.camera is None else len(o.camera.tag_ids),
        board_rms_px=nan if o.camera is None else o.camera.rms_px,
        wall_tags=0 if o.wall is None else len(o.wall.tag_ids),
        frame_grey=o.grey_mean, dark=o.grey_mean < DARK_GREY,
        image_width=intr.width, image_height=intr.height, fx=intr.fx, fy=intr.fy, cx=intr.cx, cy=intr.cy, detector=kind,
    )  # fmt: skip
    if cam_c is not None:
        row.update(cam_x=cam_c[0], cam_y=cam_c[1], cam_z=cam_c[2], camera_R=cam_R.ravel().tolist())
    return row


def _detection_fields(row: dict, d: Detection) -> None:
    c = d.centre
    row.update(
        detected=True, corners=d.corners.ravel().tolist(), corners_raw=d.raw_corners.ravel().tolist(),
        u=c[0], v=c[1], edge_px=d.edge_px, refined=d.refined, decision_margin=d.margin, hamming=d.hamming,
    )  # fmt: skip


def _fill_estimate(row, o: FrameObservation, tid, ch: _Chosen, wf: WorldFrame, cam_c, cam_R, K, frame_wall, set_wall, planes) -> None:
    ray = wf.vector(o.ray(tid, K))
    single = wf.point(_single_point(o, ch))
    R_world = cam_R @ ch.fit.R
    row.update(
        ray_x=ray[0], ray_y=ray[1], ray_z=ray[2], single_x=single[0], single_y=single[1], single_z=single[2],
        reproj_err_px=ch.fit.rms_px, ippe_solution=ch.index, ippe_alt_ratio=ch.alt_ratio, normal_err_deg=ch.angle,
        R=R_world.ravel().tolist(),
    )  # fmt: skip
    if ch.angle > MAX_NORMAL_ERR_DEG:
        row["status"] = "bad_normal"
        return
    if tid in TABLE_LAYOUT:
        # the board's plane (z = 0 in board coordinates) in world coordinates
        method, plane = "board", (wf.point(np.zeros(3)), wf.vector([0, 0, 1.0]))
    elif tid in WALL_LAYOUT:
        method, plane = ("plane", frame_wall or set_wall) if (frame_wall or set_wall) else ("single", None)
    elif tid in HEIGHT_TAG_IDS and planes.get(tid) is not None:
        method, plane = "plane", planes[tid]
    else:
        method, plane = "single", None
    p = single if plane is None else intersect_plane(cam_c, ray, plane[0], plane[1])
    if p is None:
        row["status"] = "no_intersection"
        return
    if method == "plane" and tid in HEIGHT_TAG_IDS and abs(plane[1][2]) == 1.0:
        row["plane_z"] = float(plane[0][2])
    row.update(status="ok", method=method, x=p[0], y=p[1], z=p[2])


_FLOAT_COLS = (
    "x", "y", "z", "u", "v", "edge_px", "reproj_err_px", "ippe_alt_ratio", "normal_err_deg", "decision_margin",
    "single_x", "single_y", "single_z", "plane_z", "ray_x", "ray_y", "ray_z", "cam_x", "cam_y", "cam_z",
    "board_rms_px", "frame_grey", "fx", "fy", "cx", "cy",
)  # fmt: skip
_INT_COLS = ("location", "tag_id", "ippe_solution", "hamming", "board_tags", "wall_tags", "image_width", "image_height")
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
    gantry_plane: str = "horizontal",
    heights: dict[int, float] | None = None,
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
        detector=det, gantry_plane=gantry_plane, heights=heights,
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
