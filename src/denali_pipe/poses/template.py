"""Tag corners from a photometric fit of the tag's known printed pattern.

The detectors' corners (`detect`) come from edges; on the 15-25 px tags of a
half-scale tracking frame their worst corner is off by 0.04-0.2 px even as a
median over frames, which a single tag's pose turns into up to 15 mm along
the line of sight and up to 1 deg of normal. Every pixel of a tag's image is
a function of its corners, though: the pattern (tag36h11 code, black border,
white margin) is known. Fitting that model to the image uses the whole tag,
not its outer edge: on the mean image of 25 half-scale rig frames the worst
corner of each static tag is 0.002-0.025 px off.

Model of the patch around a tag, pixel centres at integers (OpenCV):

    I(x) = a + b * G_sigma * A[P(H^-1 x)]

P: the printed pattern in cell units (the 8 x 8 cells of the black square,
white margin around it); H: the homography of the black square's corners
(TL, TR, BR, BL of `geometry.tag_corners_local`); A: the pixel's area
(SUPERSAMPLE x SUPERSAMPLE samples of P, bilinear); G_sigma: a Gaussian
optical blur of sigma px. Fitted: the 8 corner coordinates and, unless it is
fixed, sigma (Gauss-Newton); a and b (linear least squares at every step).

Pixels used: those whose blur footprint stays on the printed square (at
least 2 sigma + 0.7 px inside its outer edge, so the background beyond the
white margin never enters), and whose *predicted* value lies within
(DARK_DN, SATURATED_DN). Selecting by the prediction rather than by the
observation keeps clipped whites (the rig's raised tags 0 and 1 reach ~350 DN
before clipping at 255) out without biasing the edges. A mean patch over
frames (static tags) or a single frame (the moving tag) fit the same way.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.poses.detect import tag_bits

_CELLS = 8
_SQUARE = np.array([[0, 0], [_CELLS, 0], [_CELLS, _CELLS], [0, _CELLS]], np.float64)
MARGIN_CELLS = (geo.TAG_PRINT_SIZE - geo.TAG_SIZE) / 2 / (geo.TAG_SIZE / _CELLS)  # the white margin, 1.33 cells
SUPERSAMPLE = 16  # area samples per pixel and axis: edges sit on a 1/16 px grid
DARK_DN = 3.0  # predicted values below this may clip at 0
SATURATED_DN = 235.0  # 255 less three sd of a white pixel's noise: above it a pixel may clip
MAX_MOVE_PX = 1.0  # a corner moving further than this from its start is a failed fit (small tags' detections are off by up to ~0.4 px)
MIN_PIXELS = 30
MAX_ITERATIONS = 10
CONVERGED_PX = 2e-4
_STEP_PX = 0.01  # finite-difference step of the corners' displacement fields
_STEP_SIGMA = 0.02
SIGMA_RANGE = (0.1, 3.0)


@dataclass(frozen=True)
class TemplateFit:
    """corners (4, 2) in the image's pixel coordinates (TL, TR, BR, BL);
    sigma_px the blur; rms_dn the residual RMS (grey levels); n_pixels used."""

    corners: np.ndarray
    sigma_px: float
    rms_dn: float
    n_pixels: int


def _homography(corners: np.ndarray) -> np.ndarray:
    return cv2.getPerspectiveTransform(_SQUARE.astype(np.float32), np.asarray(corners, np.float32)).astype(np.float64)


@lru_cache(maxsize=256)
def _pattern(tag_id: int, texels_per_cell: int, pad: int) -> np.ndarray:
    """The printed pattern, 1 white 0 black, `texels_per_cell` texels per cell,
    white-padded by `pad` texels (the margin and beyond). Cached, read-only."""
    cells = tag_bits(int(tag_id)).astype(np.float32)
    tex = np.pad(np.kron(cells, np.ones((texels_per_cell, texels_per_cell), np.float32)), pad, constant_values=1.0)
    tex.setflags(write=False)
    return tex


def render_model(corners: np.ndarray, tag_id: int, box: tuple[int, int, int, int], sigma: float) -> np.ndarray:
    """The model G_sigma * A[P(H^-1 x)] (h, w) float64 in [0, 1] on the image
    box (x0, y0, w, h) for black-square corners (4, 2) in image pixels."""
    x0, y0, w, h = box
    s = SUPERSAMPLE
    edge = float(np.mean(np.linalg.norm(corners - np.roll(corners, 1, axis=0), axis=1)))
    tpc = max(2, int(np.ceil(s * edge / _CELLS)))  # about one texel per sample
    pad = int(np.ceil(MARGIN_CELLS * tpc)) + 2
    tex = _pattern(tag_id, tpc, pad)
    # texel centres at integers; sample centres of pixel x at x - 1/2 + (j + 1/2)/s
    src = (_SQUARE * tpc + pad - 0.5).astype(np.float32)
    dst = (s * (np.asarray(corners) - [x0, y0] + 0.5) - 0.5).astype(np.float32)
    H = cv2.getPerspectiveTransform(src, dst)
    fine = cv2.warpPerspective(tex, H, (w * s, h * s), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=1.0)
    m = cv2.resize(fine, (w, h), interpolation=cv2.INTER_AREA).astype(np.float64)
    return cv2.GaussianBlur(m, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)


def _inside_distance(quad: np.ndarray, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Signed distance (px) of points (X, Y) inside the convex quad (4, 2): > 0 inside."""
    q = np.asarray(quad, float)
    orient = np.sign(np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1]))
    d = np.full(X.shape, np.inf)
    for a, b in zip(q, np.roll(q, -1, axis=0)):
        e = b - a
        n = orient * np.array([-e[1], e[0]]) / np.linalg.norm(e)
        d = np.minimum(d, (X - a[0]) * n[0] + (Y - a[1]) * n[1])
    return d


def fit_template(image: np.ndarray, corners: np.ndarray, tag_id: int, *, sigma: float = 0.5, fit_sigma: bool = True) -> TemplateFit | None:
    """Fit the tag's pattern to `image` (H, W) grey, uint8 or float (e.g. a
    mean over frames), starting from the detector's `corners` (4, 2).

    sigma: the blur (px), the starting value or, with fit_sigma=False, fixed.
    Returns None, and the caller keeps the detector's corners, when the
    printed square runs off the image, fewer than MIN_PIXELS pixels are
    usable, or a corner moves more than MAX_MOVE_PX.
    """
    img = np.asarray(image, np.float64)
    c0 = np.asarray(corners, np.float64)
    c = c0.copy()
    cell_px = float(np.mean(np.linalg.norm(c - np.roll(c, 1, axis=0), axis=1))) / _CELLS
    pad = int(np.ceil(MARGIN_CELLS * cell_px)) + 3
    x0, y0 = max(int(np.floor(c[:, 0].min())) - pad, 0), max(int(np.floor(c[:, 1].min())) - pad, 0)
    x1 = min(int(np.ceil(c[:, 0].max())) + pad + 1, img.shape[1])
    y1 = min(int(np.ceil(c[:, 1].max())) + pad + 1, img.shape[0])
    box = (x0, y0, x1 - x0, y1 - y0)
    patch = img[y0:y1, x0:x1]
    X, Y = np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float))
    XY = np.stack([X, Y], -1)
    printed = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * MARGIN_CELLS + _SQUARE
    predicted = None
    for it in range(MAX_ITERATIONS):
        H = _homography(c)
        reach = 2 * sigma + 0.7
        dist = _inside_distance(cv2.perspectiveTransform(printed.reshape(-1, 1, 2), H).reshape(4, 2), X, Y)
        if (dist[[0, -1], :] > reach).any() or (dist[:, [0, -1]] > reach).any():
            return None  # the printed square reaches the patch border: cut by the image edge
        mask = dist > reach
        mask &= (predicted > DARK_DN) & (predicted < SATURATED_DN) if predicted is not None else (patch > DARK_DN) & (patch < SATURATED_DN)
        if mask.sum() < MIN_PIXELS:
            return None
        M = render_model(c, tag_id, box, sigma)
        A = np.stack([np.ones(mask.sum()), M[mask]], 1)
        (a, b), *_ = np.linalg.lstsq(A, patch[mask], rcond=None)
        predicted = a + b * M
        r = patch[mask] - predicted[mask]
        # d model / d corner: the image gradient against each corner's displacement field
        gy, gx = np.gradient(M)
        cells = cv2.perspectiveTransform(XY.reshape(-1, 1, 2), np.linalg.inv(H))
        cols = []
        for k in range(4):
            for axis in range(2):
                moved = c.copy()
                moved[k, axis] += _STEP_PX
                dx = (cv2.perspectiveTransform(cells, _homography(moved)).reshape(XY.shape) - XY) / _STEP_PX
                cols.append(-b * (gx * dx[..., 0] + gy * dx[..., 1])[mask])
        if fit_sigma:
            cols.append(b * ((render_model(c, tag_id, box, sigma + _STEP_SIGMA) - M) / _STEP_SIGMA)[mask])
        J = np.stack([*cols, np.ones(mask.sum()), M[mask]], 1)
        step, *_ = np.linalg.lstsq(J, r, rcond=None)
        c = c + step[:8].reshape(4, 2)
        if fit_sigma:
            sigma = float(np.clip(sigma + step[8], *SIGMA_RANGE))
        if np.abs(c - c0).max() > MAX_MOVE_PX:
            return None
        if np.abs(step[:8]).max() < CONVERGED_PX and it >= 1:
            break
    return TemplateFit(c, float(sigma), float(np.sqrt(np.mean(r**2))), int(mask.sum()))
