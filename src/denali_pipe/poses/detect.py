"""AprilTag (tag36h11) detection in tracking frames, and corner refinement.

Two detectors sit behind one interface (`TagDetector`):
- ``apriltag``: the AprilTag C library through `pyapriltags` (what the real
  capture used). Its corners use a +0.5 px pixel-centre convention and its own
  corner order; both are converted here, so every corner leaving this module
  is in OpenCV pixel coordinates (pixel centres at integers) and in the order
  TL, TR, BR, BL of the tag frame (`geometry.tag_corners_local`).
- ``aruco``: OpenCV's `cv2.aruco.ArucoDetector` with DICT_APRILTAG_36h11
  (OpenCV convention already).
`apriltag` is the default, chosen by measurement on the rig's frames
(scripts/bench_poses.py, 20 frames per scale): it finds every tag a frame
shows at scales 1.0, 0.5 and 0.35 (ArUco: 94, 85 and 69 %), even in
lights-off frames (ArUco: under 10 %), with centre errors of 0.03-0.13 px
against 0.12-0.23 px, and ArUco's squares come out 0.4-0.45 px too small.
ArUco is 5-10x faster (10 against 118 ms per 1280x720 frame on one core).

Corner refinement (`refine_corners`). Both detectors place a tag's outer edge
where the intensity crosses a level between the observed black and white, so
anything that makes the two sides of an edge asymmetric moves every edge the
same way: when the white paper saturates (the rig's raised tags 0 and 1 reach
about 350 DN before clipping at 255), the black square shrinks by 0.1-0.4 px
and single-tag PnP puts the tag 7-14 mm too far along the line of sight. The
refinement measures the centre line of the tag's black border band, between
its outer edge (against the white margin) and its inner edge (against white
data cells, known from the tag's code): both edges shift toward black by the
same amount, so the band's midline is unbiased under any symmetric blur and
any monotone intensity response, clipping included. Each side's outer edge is
then put half a cell outside its band's midline.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from denali_pipe.core import geometry as geo

DETECTORS = ("apriltag", "aruco")
DEFAULT_DETECTOR = "apriltag"
MAX_HAMMING = 1  # bit errors accepted in a decoded tag (more invites false positives)

# AprilTag -> OpenCV corner order (the AprilTag library's convention; checked against the rig's renders)
_APRILTAG_TO_OPENCV = [1, 0, 3, 2]
_APRILTAG_PIXEL_OFFSET = 0.5  # the library puts pixel centres at +0.5

_DICT = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)


@dataclass(frozen=True)
class Detection:
    """One detected tag. corners (4, 2) float64, OpenCV pixel coordinates, order
    TL, TR, BR, BL of the tag frame; `raw_corners` the detector's own corners in
    the same convention (before refinement); `refined` whether refinement was
    applied; margin: the detector's decision margin (NaN for ArUco)."""

    tag_id: int
    corners: np.ndarray
    raw_corners: np.ndarray
    margin: float
    hamming: int
    refined: bool = False

    @property
    def centre(self) -> np.ndarray:
        return quad_centre(self.corners)

    @property
    def edge_px(self) -> float:
        """Mean side length of the black square in pixels."""
        return float(np.mean(np.linalg.norm(self.corners - np.roll(self.corners, 1, axis=0), axis=1)))


def quad_centre(corners: np.ndarray) -> np.ndarray:
    """Projective centre of a quadrilateral (4, 2): the intersection of its diagonals
    (the image of the square's centre under any perspective)."""
    c = np.asarray(corners, float)
    h = np.cross(np.cross([*c[0], 1.0], [*c[2], 1.0]), np.cross([*c[1], 1.0], [*c[3], 1.0]))
    if abs(h[2]) < 1e-12:
        return c.mean(axis=0)
    return h[:2] / h[2]


def to_grey(frame: np.ndarray) -> np.ndarray:
    """BGR (H, W, 3) or grey (H, W) uint8 -> contiguous grey uint8."""
    frame = np.asarray(frame)
    if frame.ndim == 3:
        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(frame)


class TagDetector:
    """tag36h11 detector: `TagDetector("apriltag" | "aruco").detect(frame)` ->
    [Detection], at most one per tag id (the most confident), sorted by id.

    refine: apply `refine_corners` to every detection (default). nthreads:
    threads of the AprilTag library (ArUco follows cv2.setNumThreads).
    """

    def __init__(self, kind: str = DEFAULT_DETECTOR, *, refine: bool = True, nthreads: int = 1, max_hamming: int = MAX_HAMMING):
        if kind not in DETECTORS:
            raise ValueError(f"unknown tag detector {kind!r}: expected one of {list(DETECTORS)}")
        self.kind, self.refine, self.max_hamming = kind, refine, max_hamming
        if kind == "apriltag":
            import pyapriltags

            # quad_decimate 1: decimation 2 loses small tags (docs/performance.md)
            self._det = pyapriltags.Detector(families=geo.TAG_FAMILY, nthreads=int(nthreads), quad_decimate=1.0)
        else:
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
            self._det = cv2.aruco.ArucoDetector(_DICT, params)

    def detect_raw(self, grey: np.ndarray) -> list[tuple[int, np.ndarray, float, int]]:
        """(tag id, corners (4, 2) OpenCV convention, margin, hamming) per detection, unfiltered."""
        out = []
        if self.kind == "apriltag":
            for d in self._det.detect(grey):
                c = np.asarray(d.corners, float)[_APRILTAG_TO_OPENCV] - _APRILTAG_PIXEL_OFFSET
                out.append((int(d.tag_id), c, float(d.decision_margin), int(d.hamming)))
        else:
            corners, ids, _ = self._det.detectMarkers(grey)
            if ids is not None:
                for c, i in zip(corners, np.asarray(ids).ravel()):
                    out.append((int(i), np.asarray(c, float).reshape(4, 2), float("nan"), 0))
        return out

    def detect(self, frame: np.ndarray) -> list[Detection]:
        grey = to_grey(frame)
        best: dict[int, tuple] = {}
        for tid, c, margin, ham in self.detect_raw(grey):
            if ham > self.max_hamming or not np.all(np.isfinite(c)):
                continue
            key = (-ham, np.nan_to_num(margin, nan=0.0))
            if tid not in best or key > best[tid][0]:
                best[tid] = (key, c, margin, ham)
        dets = []
        for tid in sorted(best):
            _, c, margin, ham = best[tid]
            corners, ok = refine_corners(grey, c, tid) if self.refine else (c, False)
            dets.append(Detection(tid, corners, c, margin, ham, ok))
        return dets


# --- corner refinement ------------------------------------------------------------------

# The black square in cell units: 8 x 8 cells (1 border cell, 6 x 6 data cells,
# 1 border cell); (u, v) = (0, 0) is the TL corner, u right, v down.
_CELLS = 8
_SQUARE = np.array([[0, 0], [_CELLS, 0], [_CELLS, _CELLS], [0, _CELLS]], np.float32)
_S = np.arange(-0.6, 1.6001, 0.05)  # normal coordinate across a border band (cells): 0 outer edge, 1 inner edge
_T_IN_CELL = np.arange(0.3, 0.7001, 0.1)  # along-edge samples inside a data cell, clear of its neighbours
_MIN_EDGE_PX = 8.0  # below one pixel per cell the band cannot be resolved
_MIN_CONTRAST_DN = 10.0
_MAX_SHIFT_CELLS = 0.35  # a refinement moving an edge further than this is rejected
_MAX_BAD_BITS = 2


@lru_cache(maxsize=1024)
def tag_bits(tag_id: int) -> np.ndarray:
    """(8, 8) bool cells of tag36h11 `tag_id`, True = white, [row v, col u],
    in the orientation whose TL is the detectors' first corner."""
    img = cv2.aruco.generateImageMarker(_DICT, int(tag_id), _CELLS, borderBits=1)
    bits = img > 127
    bits.setflags(write=False)
    return bits


def _homography(corners: np.ndarray) -> np.ndarray:
    return cv2.getPerspectiveTransform(_SQUARE, np.asarray(corners, np.float32)).astype(np.float64)


def _sample(grey32: np.ndarray, H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear samples of the image at tag-cell coordinates uv (..., 2)."""
    p = cv2.perspectiveTransform(uv.reshape(-1, 1, 2).astype(np.float64), H).reshape(1, -1, 2).astype(np.float32)
    out = cv2.remap(grey32, p[..., 0], p[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(uv.shape[:-1])


def _side_coords(side: str, t: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Cell coordinates of (along-edge t, inward normal s) on one side of the square."""
    n = _CELLS
    return {
        "top": lambda: np.stack([t, s], -1),
        "bottom": lambda: np.stack([t, n - s], -1),
        "left": lambda: np.stack([s, t], -1),
        "right": lambda: np.stack([n - s, t], -1),
    }[side]()


def _inner_white(bits: np.ndarray, side: str) -> np.ndarray:
    """Which of the 6 data cells adjacent to a side's border band are white."""
    return {"top": bits[1, 1:7], "bottom": bits[6, 1:7], "left": bits[1:7, 1], "right": bits[1:7, 6]}[side]


def _band_centre(profile: np.ndarray) -> float | None:
    """Centre (cells) of the dark band in a white-black-white profile sampled at
    _S: the midpoint of its two half-level crossings, or None."""
    core = (_S > 0.2) & (_S < 0.8)
    i0 = int(np.argmin(np.where(core, profile, np.inf)))
    black = profile[i0]
    w_out, w_in = profile[_S < -0.35].mean(), profile[_S > 1.35].mean()
    if min(w_out, w_in) - black < _MIN_CONTRAST_DN:
        return None
    lo, hi = (black + w_out) / 2, (black + w_in) / 2
    i = i0
    while i > 0 and profile[i] < lo:
        i -= 1
    j = i0
    while j < len(_S) - 1 and profile[j] < hi:
        j += 1
    if profile[i] < lo or profile[j] < hi:
        return None
    s_out = _S[i] + (lo - profile[i]) / (profile[i + 1] - profile[i]) * (_S[i + 1] - _S[i])
    s_in = _S[j - 1] + (hi - profile[j - 1]) / (profile[j] - profile[j - 1]) * (_S[j] - _S[j - 1])
    return 0.5 * (s_out + s_in)


def _code_matches(grey32: np.ndarray, H: np.ndarray, bits: np.ndarray) -> bool:
    """Whether the cells sampled at their centres show the expected code (so the
    corner order and the code table agree)."""
    uv = np.stack(np.meshgrid(np.arange(_CELLS) + 0.5, np.arange(_CELLS) + 0.5), -1)  # [v, u] -> (u, v)
    vals = _sample(grey32, H, uv)
    white, dark = vals[bits], vals[~bits]
    if white.size == 0 or white.mean() - dark.mean() < _MIN_CONTRAST_DN:
        return False
    level = 0.5 * (white.mean() + dark.mean())
    return int(np.sum(white < level) + np.sum(dark >= level)) <= _MAX_BAD_BITS


def refine_corners(grey: np.ndarray, corners: np.ndarray, tag_id: int, iterations: int = 2) -> tuple[np.ndarray, bool]:
    """Move each side of a detected tag so that its black border band's midline
    sits half a cell inside it (see the module docstring).

    grey (H, W) uint8; corners (4, 2) OpenCV convention, TL, TR, BR, BL.
    Returns (corners, True) or, where the tag is too small (< 8 px), its code
    does not match the expected pattern, the bands have too little contrast or
    a side would move implausibly far, the input corners and False. A side
    whose adjacent data cells are all black takes the mean shift of the others.
    """
    c = np.asarray(corners, np.float64)
    edge = np.mean(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1))
    if not np.isfinite(edge) or edge < _MIN_EDGE_PX:
        return c, False
    bits = tag_bits(int(tag_id))
    grey32 = np.asarray(grey, np.float32)
    if not _code_matches(grey32, _homography(c), bits):
        return c, False
    # the sample grid of every side whose band borders white data cells, built once
    grids = []
    for side in ("top", "bottom", "left", "right"):
        white = _inner_white(bits, side)
        if white.any():
            t = np.concatenate([j + 1 + _T_IN_CELL for j in range(6) if white[j]])
            T, S = np.meshgrid(t, _S, indexing="ij")
            grids.append((side, len(t), _side_coords(side, T, S).reshape(-1, 2)))
    if not grids:
        return c, False
    uv = np.concatenate([g[2] for g in grids])
    for _ in range(iterations):
        H = _homography(c)
        vals = _sample(grey32, H, uv)  # one remap for all sides
        shift, at = {}, 0
        for side, n_t, pts in grids:
            profile = vals[at : at + len(pts)].reshape(n_t, len(_S)).mean(axis=0)
            at += len(pts)
            centre = _band_centre(profile)
            if centre is not None:
                shift[side] = centre - 0.5  # > 0: the true outer edge lies inside the detected one
        if not shift or max(abs(v) for v in shift.values()) > _MAX_SHIFT_CELLS:
            return np.asarray(corners, np.float64), False
        mean = float(np.mean(list(shift.values())))
        top, bottom, left, right = (shift.get(k, mean) for k in ("top", "bottom", "left", "right"))
        new = np.array([[left, top], [_CELLS - right, top], [_CELLS - right, _CELLS - bottom], [left, _CELLS - bottom]])
        c = cv2.perspectiveTransform(new.reshape(-1, 1, 2), H).reshape(4, 2)
    return c, True
