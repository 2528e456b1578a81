"""Tracking-camera intrinsics, PnP (rigid multi-tag boards and single tags),
the IPPE ambiguity, and ray-plane geometry.

Conventions: OpenCV pinhole camera without distortion (x right, y down, z
forward); a fit (R, t) maps layout/tag coordinates into the camera frame,
X_cam = R X + t. Tag frame as in `geometry`: x right, y down, z into the tag.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import Intrinsics

_NO_DIST = np.zeros(5)


# --- intrinsics ---------------------------------------------------------------------------


# The one fallback for frames whose metadata carries no tracking-camera record
# (the public release): the real tracking RealSense's calibration, 1280x720,
# fx 923.57 fy 923.94 cx 641.69 cy 365.96 (the release's tracking camera), which
# geometry.TRACKING_CAMERA carries; it is scaled to the frame size.
REAL_TRACKING_INTRINSICS = geo.TRACKING_CAMERA.intrinsics
METADATA_KEY = "tracking_camera"


def tracking_intrinsics(metadata: dict | None, frame_shape: tuple[int, ...]) -> tuple[Intrinsics, str]:
    """Intrinsics for tracking frames of `frame_shape` (H, W[, 3]).

    Returns (intrinsics, source): source "metadata" when the capture's metadata
    record has `tracking_camera` {width, height, fx, fy, cx, cy} (the synthetic
    rig writes it), else "fallback" (REAL_TRACKING_INTRINSICS). Either is
    scaled to the frame's size when it differs.
    """
    h, w = int(frame_shape[0]), int(frame_shape[1])
    rec = (metadata or {}).get(METADATA_KEY)
    if isinstance(rec, dict) and all(k in rec for k in ("width", "height", "fx", "fy", "cx", "cy")):
        return Intrinsics.from_dict(rec).scaled_to(w, h), "metadata"
    return REAL_TRACKING_INTRINSICS.scaled_to(w, h), "fallback"


# --- fits -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Fit:
    """A rigid fit X_cam = R @ X + t of layout (or tag) points, with the RMS
    reprojection error in pixels and, for boards, the tags it used and each
    tag's RMS."""

    R: np.ndarray
    t: np.ndarray
    rms_px: float
    tag_ids: tuple[int, ...] = ()
    tag_rms_px: tuple[float, ...] = ()

    @property
    def R_cw(self) -> np.ndarray:
        """Camera -> layout rotation (for a world-layout board: camera axes in world)."""
        return self.R.T

    @property
    def camera_centre(self) -> np.ndarray:
        """Camera centre in layout coordinates."""
        return -self.R.T @ self.t

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points) @ self.R.T + self.t


def project(K: np.ndarray, R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N, 2) of points (N, 3) under X_cam = R X + t."""
    pc = np.asarray(points, float) @ np.asarray(R).T + np.asarray(t).ravel()
    uv = pc @ np.asarray(K).T
    return uv[:, :2] / uv[:, 2:3]


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=-1))))


def solve_board(
    corners: dict[int, np.ndarray],
    layout: dict[int, geo.Pose],
    K: np.ndarray,
    *,
    min_tags: int = 2,
    size: float = geo.TAG_SIZE,
    outlier_px: float = 1.5,
) -> Fit | None:
    """Camera pose from every detected tag of a rigid board at once.

    corners: tag id -> (4, 2) pixel corners (TL, TR, BR, BL); layout: tag id ->
    tag pose in the board's coordinates (the design drawing); only ids in
    both are used. Needs `min_tags` tags (8 corners for 2). SQPnP (global)
    then Levenberg-Marquardt refinement; a tag whose RMS exceeds
    max(outlier_px, 4 x the median tag RMS) is dropped (a misdetected or
    partly occluded tag) and the board refitted while enough tags remain.
    Returns None when too few tags remain or the fit puts the board behind
    the camera.
    """
    ids = sorted(i for i in corners if i in layout)
    local = geo.tag_corners_local(size)
    while len(ids) >= min_tags:
        obj = np.concatenate([layout[i].apply(local) for i in ids])
        img = np.concatenate([np.asarray(corners[i], float) for i in ids])
        try:
            ok, rvec, tvec = cv2.solvePnP(obj, img, K, _NO_DIST, flags=cv2.SOLVEPNP_SQPNP)
            if not ok:
                return None
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, _NO_DIST, rvec, tvec)
        except cv2.error:
            return None
        R, _ = cv2.Rodrigues(rvec)
        t = tvec.ravel()
        if np.any(obj @ R.T @ [0, 0, 1] + t[2] <= 0):
            return None
        proj = project(K, R, t, obj).reshape(len(ids), 4, 2)
        per_tag = [_rms(proj[k], img.reshape(len(ids), 4, 2)[k]) for k in range(len(ids))]
        worst = int(np.argmax(per_tag))
        limit = max(outlier_px, 4 * float(np.median(per_tag)))
        if per_tag[worst] > limit and len(ids) > min_tags:
            ids.pop(worst)
            continue
        if per_tag[worst] > limit:
            return None
        return Fit(R, t, _rms(proj.reshape(-1, 2), img), tuple(ids), tuple(per_tag))
    return None


# IPPE_SQUARE wants the square's corners as (-s/2, s/2), (s/2, s/2), (s/2, -s/2),
# (-s/2, -s/2): in our tag frame (y down) those are BL, BR, TR, TL.
_IPPE_ORDER = [3, 2, 1, 0]


def solve_tag(corners: np.ndarray, K: np.ndarray, size: float = geo.TAG_SIZE) -> list[Fit]:
    """Both IPPE solutions of one square tag, X_cam = R X_tag + t, ordered by
    reprojection error (index 0 the lower), as `solvePnPGeneric` returns them.
    Empty when the solver fails."""
    c = np.asarray(corners, float)
    obj = geo.tag_corners_local(size)
    try:
        n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj[_IPPE_ORDER], c[_IPPE_ORDER], K, _NO_DIST, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    except cv2.error:
        return []
    fits = []
    for rv, tv in zip(rvecs[:n], tvecs[:n]):
        R, _ = cv2.Rodrigues(rv)
        t = tv.ravel()
        if t[2] <= 0:
            continue
        fits.append(Fit(R, t, _rms(project(K, R, t, obj), c)))
    return fits


def choose_by_normal(fits: list[Fit], R_cw: np.ndarray, expected_z: np.ndarray) -> tuple[int, float]:
    """Resolve the IPPE ambiguity with a known surface orientation.

    fits: `solve_tag`'s solutions; R_cw: camera -> world rotation;
    expected_z: the tag's z axis (into the tag) in world coordinates, e.g.
    (0, 0, -1) for a tag facing up. Returns (index of the solution whose z
    axis is closest to expected_z, angle between them in degrees).
    """
    e = np.asarray(expected_z, float)
    e = e / np.linalg.norm(e)
    cos = [float(np.clip((R_cw @ f.R[:, 2]) @ e, -1.0, 1.0)) for f in fits]
    k = int(np.argmax(cos))
    return k, float(np.degrees(np.arccos(cos[k])))


# --- rays and planes ------------------------------------------------------------------------


def pixel_ray(uv: np.ndarray, K: np.ndarray, R_cw: np.ndarray) -> np.ndarray:
    """Unit direction (3,) in world/layout coordinates of the ray through pixel uv."""
    d = np.linalg.solve(np.asarray(K, float), [uv[0], uv[1], 1.0])
    d = np.asarray(R_cw) @ d
    return d / np.linalg.norm(d)


def intersect_plane(origin: np.ndarray, direction: np.ndarray, point: np.ndarray, normal: np.ndarray, min_cos: float = 1e-3) -> np.ndarray | None:
    """Where the ray origin + s direction (s > 0) meets the plane through `point`
    with `normal`; None when the ray is (near) parallel or the plane behind."""
    n = np.asarray(normal, float)
    denom = float(np.asarray(direction) @ n)
    if abs(denom) < min_cos * np.linalg.norm(n):
        return None
    s = float((np.asarray(point) - origin) @ n) / denom
    if s <= 0:
        return None
    return np.asarray(origin) + s * np.asarray(direction)


def mean_rotation(Rs: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of rotations (N, 3, 3): the rotation nearest their average."""
    M = np.mean(np.asarray(Rs, float).reshape(-1, 3, 3), axis=0)
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def rigid_fit(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation R and translation t with dst ~ R src + t (Kabsch),
    for N >= 3 non-collinear points (N, 3)."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs
