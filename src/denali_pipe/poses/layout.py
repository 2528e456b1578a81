"""The static tags' layout and the tracking camera's pose, estimated from one
capture set's frames: nothing of our design drawing is assumed but which
surface each tag lies on; the drawing is the starting point.

Why a structured bundle adjustment. The tracking camera does not move, so
the frames add no parallax: where a tag sits along its line of sight can only
come from its own image (its apparent size and foreshortening), and its
normal likewise. What the frames give precisely is the direction to each tag
(0.05-0.3 mm sideways). The options, measured on the rig's half-scale frames
(scripts/bench_poses.py, both scenes):
- The design's rigid board (the former method) fixes the camera from the
  drawing's inter-tag distances: sub-millimetre when the rig is the drawing;
  where a release's poses.json puts the tags (up to 3 cm from the drawing,
  table 15 1.5 cm higher and tilted 0.6 deg) the static tags came out 15 mm
  off on average (30 at worst), tag 1 31 mm (46).
- Per-tag single-tag poses (IPPE) from the detectors' corners: up to 15 mm
  along the line of sight and 1 deg of normal per tag, biases that averaging
  over frames does not remove.
- This module: the corners of each static tag from a photometric fit of its
  pattern to the set's mean image of it (`template`; 0.002-0.025 px), then one
  least-squares fit of every static tag's corners over the camera pose and
  the layout, with the physical structure as the only constraint: the tags
  of a table lie flat on that table's top, the wall tags on the wall, each
  surface a plane of free height and tilt, each tag free within it (position
  and in-plane rotation); the sensor tag 0 is a free pose. Pooling three tags
  per plane averages their shape errors, and a plane's tilt comes from its
  tags' spread as well as their shapes. Static tags then come out within
  1.2 mm of the truth on either scene (0.3 mm on average) from half-scale
  frames, within 0.3 mm from full-scale ones.

Gauge: the world frame is tag 14's, as in a release's poses.json: origin at
its centre, x along its x axis, z up (its face); table 14's top is z = 0 and
tags 10 and 12 lie on it.

Starting point: the drawing (`geometry.STATIC_TAGS`) and the camera solved
against it (SQPnP). The fit converges from it for layouts well away from
the drawing (on exact corners: tags slid by up to 8 cm, surfaces and tags
turned by up to 10 deg; a release's are within 3.0 cm and 4.2 deg); each
tag's distance from the drawing is reported (`Layout.deviation_m`) and
logged above DEVIATION_WARN_M, where a tag is misidentified or the rig is not
this one. A tag whose corners the fit cannot explain (RMS above
max(OUTLIER_PX, 4 x the median)) is dropped and the fit repeated.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import partial

import cv2
import numpy as np
from scipy.optimize import least_squares

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import Pose
from denali_pipe.poses.detect import quad_centre
from denali_pipe.poses.pnp import Fit, project, solve_board
from denali_pipe.poses.template import fit_template

log = logging.getLogger(__name__)

# Which surface each static tag lies on: tags of a group share a plane (for
# the sensor tag: its own). GAUGE_GROUP's top is the world's z = 0 and tag 14
# its origin.
GROUPS: dict[str, tuple[int, ...]] = {
    **{f"table{t}": ids for t, ids in geo.TABLE_TAGS.items()},
    "wall": geo.WALL_TAG_IDS,
    "sensor": (geo.SENSOR_TAG_ID,),
}
GAUGE_GROUP = f"table{geo.WORLD_ORIGIN_TAG_ID}"
OUTLIER_PX = 0.5
DEFAULT_BLUR_PX = 0.5  # when no tag's blur could be fitted
DEVIATION_WARN_M = 0.05
PATCH_PAD = 0.5  # a static tag's mean patch reaches this many tag edges beyond its corners
OVERLAP_PAD = 0.3  # frames where a moving tag's box (grown by this many edges) meets the static tag's are left out


@dataclass(frozen=True)
class Layout:
    """One set's static layout in the world frame (metres).

    camera: world -> camera fit (X_cam = R X + t) with the RMS (px) over the
    tags it used; tags: tag id -> Pose (tag -> world), each lying on its
    surface's plane; centre_offset: per tag, its template-fitted centre less
    its median detected centre (2,) px, the detector's bias, which per-frame
    centres are corrected by; tag_rms_px: per tag, its corners' RMS against
    the fit; blur_px: the camera's blur sigma; deviation_m: per tag, its
    centre's distance from the drawing."""

    camera: Fit
    tags: dict[int, Pose]
    centre_offset: dict[int, np.ndarray]
    tag_rms_px: dict[int, float]
    blur_px: float
    deviation_m: dict[int, float]

    def to_dict(self) -> dict:
        return {
            "camera": {"R_world_to_camera": self.camera.R.tolist(), "t_world_to_camera": self.camera.t.tolist(), "rms_px": self.camera.rms_px},
            "tags": {str(i): p.to_dict() for i, p in sorted(self.tags.items())},
            "centre_offset_px": {str(i): v.tolist() for i, v in sorted(self.centre_offset.items())},
            "tag_rms_px": {str(i): v for i, v in sorted(self.tag_rms_px.items())},
            "blur_px": self.blur_px,
            "deviation_m": {str(i): v for i, v in sorted(self.deviation_m.items())},
        }


# --- the static tags' image corners ----------------------------------------------------------


def _box(corners: np.ndarray, pad_edges: float) -> np.ndarray:
    """(x0, y0, x1, y1) of corners (4, 2) grown by `pad_edges` tag edges."""
    c = np.asarray(corners, float)
    pad = pad_edges * float(np.ptp(c[:, 0]) + np.ptp(c[:, 1])) / 2
    return np.r_[c.min(axis=0) - pad, c.max(axis=0) + pad]


def _overlaps(a: np.ndarray, b: np.ndarray) -> bool:
    return not (a[2] < b[0] or b[2] < a[0] or a[3] < b[1] or b[3] < a[1])


@dataclass(frozen=True)
class MeanPatch:
    """A static tag's mean image over frames: patch (h, w) float64 whose
    pixel (0, 0) is image pixel `origin` (x, y); the tag's median detected
    corners (4, 2) in patch coordinates; frames averaged."""

    patch: np.ndarray
    corners: np.ndarray
    origin: np.ndarray
    n_frames: int


def mean_patch(greys: list[np.ndarray], corners: list[np.ndarray], moving: list[list[np.ndarray]]) -> MeanPatch | None:
    """A static tag's mean image over the frames where no moving tag comes near it.

    greys: the frames (H, W) uint8; corners: the tag's detected corners (4, 2)
    in each; moving: per frame the moving tags' corners. None when every
    frame is crowded."""
    med = np.median(np.asarray(corners, float), axis=0)
    box = _box(med, PATCH_PAD)
    clean = [g for g, mv in zip(greys, moving) if not any(_overlaps(box, _box(m, OVERLAP_PAD)) for m in mv)]
    if not clean:
        return None
    h, w = clean[0].shape[:2]
    x0, y0 = max(int(np.floor(box[0])), 0), max(int(np.floor(box[1])), 0)
    x1, y1 = min(int(np.ceil(box[2])) + 1, w), min(int(np.ceil(box[3])) + 1, h)
    acc = np.zeros((y1 - y0, x1 - x0))
    for g in clean:
        acc += g[y0:y1, x0:x1]
    origin = np.array([x0, y0], float)
    return MeanPatch(acc / len(clean), med - origin, origin, len(clean))


def template_corners(patches: dict[int, MeanPatch]) -> tuple[dict[int, np.ndarray], float]:
    """Template-fitted corners per static tag (image coordinates) and the
    camera's blur sigma (px): the median of free-sigma fits, then every tag
    refitted with it fixed (a tag whose white clips cannot tell blur from
    contrast). A tag whose fit fails keeps its median detected corners."""
    free = {t: fit_template(m.patch, m.corners, t) for t, m in patches.items()}
    sigmas = [f.sigma_px for f in free.values() if f is not None]
    blur = float(np.median(sigmas)) if sigmas else DEFAULT_BLUR_PX
    out = {}
    for t, m in patches.items():
        start = m.corners if free[t] is None else free[t].corners
        fit = fit_template(m.patch, start, t, sigma=blur, fit_sigma=False)
        out[t] = (m.corners if fit is None else fit.corners) + m.origin
    return out, blur


# --- the layout model ---------------------------------------------------------------------------


def _base(group: str) -> Pose:
    """A group's plane frame in the drawing: the first tag's orientation at the
    tags' mean centre; for the gauge group, tag 14's frame (the world's)."""
    if group == GAUGE_GROUP:
        return geo.STATIC_TAGS[geo.WORLD_ORIGIN_TAG_ID]
    ids = GROUPS[group]
    return Pose(geo.STATIC_TAGS[ids[0]].R, np.mean([geo.STATIC_TAGS[i].t for i in ids], axis=0))


def _in_plane(base: Pose, tag: Pose) -> np.ndarray:
    """(x, y, yaw rad) of a tag in a plane frame (the drawing's, as a start)."""
    p = base.R.T @ (tag.t - base.t)
    R = base.R.T @ tag.R
    return np.array([p[0], p[1], np.arctan2(R[1, 0], R[0, 0])])


def _rotvec(v: np.ndarray) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(v, float).reshape(3, 1))[0]


class _Model:
    """Parameter vector <-> camera and tag poses. Parameters: camera rotation
    vector and translation (6); per free group its plane's tilt about the
    plane frame's x and y (rad) and offset along its z (m) (3); per tag, bar
    the gauge tag 14, its (x, y, yaw) in its plane (3)."""

    def __init__(self, tags: list[int], cam0: Fit):
        self.cam0 = cam0
        self.groups = {g: [i for i in ids if i in tags] for g, ids in GROUPS.items()}
        self.groups = {g: ids for g, ids in self.groups.items() if ids}
        self.slots: dict[object, slice] = {}
        x0 = [cv2.Rodrigues(cam0.R)[0].ravel(), cam0.t]
        self._slot("camera", 6)
        for g, ids in self.groups.items():
            if g != GAUGE_GROUP:
                self._slot(("plane", g), 3)
                x0.append(np.zeros(3))
            for i in ids:
                if i != geo.WORLD_ORIGIN_TAG_ID:
                    self._slot(("tag", i), 3)
                    x0.append(_in_plane(_base(g), geo.STATIC_TAGS[i]))
        self.x0 = np.concatenate(x0)

    def _slot(self, key, n: int) -> None:
        start = max((s.stop for s in self.slots.values()), default=0)
        self.slots[key] = slice(start, start + n)

    def camera(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = x[self.slots["camera"]]
        return _rotvec(c[:3]), c[3:]

    def plane(self, x: np.ndarray, group: str) -> Pose:
        base = _base(group)
        if group == GAUGE_GROUP:
            return base
        a, b, d = x[self.slots["plane", group]]
        return base @ Pose(_rotvec([a, b, 0.0]), np.array([0.0, 0.0, d]))

    def tags(self, x: np.ndarray) -> dict[int, Pose]:
        out = {}
        for g, ids in self.groups.items():
            P = self.plane(x, g)
            for i in ids:
                u, v, yaw = (0.0, 0.0, 0.0) if i == geo.WORLD_ORIGIN_TAG_ID else x[self.slots["tag", i]]
                out[i] = P @ Pose(geo.rot_z(np.degrees(yaw)), np.array([u, v, 0.0]))
        return out


def _residuals(model: _Model, x: np.ndarray, corners: dict[int, np.ndarray], K: np.ndarray) -> np.ndarray:
    R, t = model.camera(x)
    local = geo.tag_corners_local()
    tags = model.tags(x)
    return np.concatenate([(project(K, R, t, tags[i].apply(local)) - corners[i]).ravel() for i in sorted(tags)])


def _initial_camera(corners: dict[int, np.ndarray], K: np.ndarray) -> Fit | None:
    return solve_board(corners, geo.STATIC_TAGS, K, outlier_px=np.inf)


def solve_layout(corners: dict[int, np.ndarray], K: np.ndarray) -> tuple[Fit, dict[int, Pose], dict[int, float]] | None:
    """Camera and static tag poses from each static tag's image corners
    (tag id -> (4, 2)). Needs the gauge tag 14; drops tags the fit cannot
    explain (see the module docstring). Returns (camera fit, tag poses,
    per-tag RMS px) or None."""
    ids = sorted(i for i in corners if i in geo.STATIC_TAGS)
    while geo.WORLD_ORIGIN_TAG_ID in ids:
        cam0 = _initial_camera({i: corners[i] for i in ids}, K)
        if cam0 is None:
            return None
        model = _Model(ids, cam0)
        obs = {i: corners[i] for i in ids}
        sol = least_squares(partial(_residuals, model), model.x0, args=(obs, K), method="lm", x_scale="jac")
        per_tag = {i: float(np.sqrt(np.mean(r**2))) for i, r in zip(ids, sol.fun.reshape(len(ids), 8))}
        worst = max((i for i in ids if i != geo.WORLD_ORIGIN_TAG_ID), key=per_tag.get, default=None)
        limit = max(OUTLIER_PX, 4 * float(np.median(list(per_tag.values()))))
        if worst is not None and per_tag[worst] > limit:
            log.warning("static tag %d dropped from the layout: corner RMS %.2f px > %.2f px", worst, per_tag[worst], limit)
            ids.remove(worst)
            continue
        R, t = model.camera(sol.x)
        return Fit(R, t, float(np.sqrt(np.mean(sol.fun**2))), tuple(ids), tuple(per_tag[i] for i in ids)), model.tags(sol.x), per_tag
    return None


def estimate_layout(greys: list[np.ndarray], detections: list[dict[int, np.ndarray]], K: np.ndarray) -> Layout | None:
    """The set's layout from its frames.

    greys: the frames (H, W) uint8; detections: per frame, tag id -> detected
    corners (4, 2) (refined); K: intrinsics (3, 3). Static tags are averaged
    over the frames that show them clear of the moving tag, template-fitted,
    and solved together (`solve_layout`). None when tag 14 is never seen or
    the fit fails (the set's rows then say `no_camera`)."""
    patches = {}
    for t in geo.STATIC_TAGS:
        seen = [k for k, d in enumerate(detections) if t in d]
        moving = [[c for i, c in detections[k].items() if i not in geo.STATIC_TAGS] for k in seen]
        if seen and (m := mean_patch([greys[k] for k in seen], [detections[k][t] for k in seen], moving)) is not None:
            patches[t] = m
    if geo.WORLD_ORIGIN_TAG_ID not in patches:
        return None
    corners, blur = template_corners(patches)
    solved = solve_layout(corners, K)
    if solved is None:
        return None
    camera, tags, per_tag = solved
    deviation = {i: float(np.linalg.norm(p.t - geo.STATIC_TAGS[i].t)) for i, p in tags.items()}
    far = {i: round(d, 3) for i, d in deviation.items() if d > DEVIATION_WARN_M}
    if far:
        log.warning("static tags more than %.2f m from the drawing (m): %s", DEVIATION_WARN_M, far)
    offset = {i: quad_centre(corners[i]) - np.median([quad_centre(d[i]) for d in detections if i in d], axis=0) for i in tags}
    return Layout(camera, tags, offset, per_tag, blur, deviation)
