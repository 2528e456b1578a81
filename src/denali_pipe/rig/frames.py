"""Synthetic RGB-D frames from the capture rig's RealSense cameras.

The real capture stores, per gantry location, one aligned colour (bgr8) and
depth (z16, millimetres) frame from the tracking camera (above and behind the
scene, 1280x720) and from the co-located camera next to the LiDAR (848x480,
looking at the relay wall). This module renders frames with the same layout
from a tracked scene (`rig.tracked_scene`: our design drawing in
`denali_pipe.core.geometry`, or a release's measured poses), so that the pose stage
can run the real AprilTag detector on them and recover that geometry.

Rendering model (all cheap enough for a frame in tens of milliseconds):
- Background: per-pixel ray casting against the scene's two table tops, its
  visual wall and a floor, Lambertian shading from two ceiling lights plus
  ambient. It depends only on the camera and those surfaces, so it is
  computed once and cached.
- Tags: each tag (white 8 cm paper square carrying the 6 cm black-bordered
  tag36h11 marker) is warped into its bounding box through the exact plane
  homography, supersampled and box-filtered (anti-aliased), depth-tested
  against the background and composited by its coverage.
- Optics and sensor: Gaussian blur, then shot-like + read noise in DN,
  rounding to uint8. Depth: z-depth with 0.2 % Gaussian noise, uint16 mm.

Conventions: pixel centres at integer coordinates (OpenCV, `Camera.project`);
images are (H, W[, 3]) arrays, row = v, column = u. All randomness comes from
the caller's `rng`, drawn in a fixed order, so equal seeds give equal bytes.
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from denali_pipe.core import geometry as g
from denali_pipe.core.geometry import FLOOR_Z, Camera, Pose
from denali_pipe.core.tags import TAG_BLACK, TAG_WHITE, tag_texture
from denali_pipe.rig.tracked_scene import TrackedScene, design_scene

# --- scene appearance -----------------------------------------------------------

MAX_DEPTH_M = 10.0  # the depth camera reports 0 beyond this (no valid return)

# Albedos, RGB (converted to BGR when writing). The table colour is the
# reference twin's (0.6, 0.5, 0.4); the wall is the near-white relay surface.
TABLE_ALBEDO = {14: np.array([0.60, 0.50, 0.40]), 15: np.array([0.57, 0.48, 0.39])}
WALL_RGB = np.array([0.88, 0.88, 0.86])
FLOOR_RGB = np.array([0.22, 0.23, 0.25])
BACKDROP_RADIANCE = np.array([0.06, 0.06, 0.07])  # dark room beyond 10 m / above the horizon

# Lighting: two ceiling lights above the tables plus ambient fill. Irradiance
# units are arbitrary; exposure normalises them (see _EXPOSURE_TARGET_GREY).
LIGHTS = (np.array([0.35, 0.10, 2.10]), np.array([1.15, 0.10, 2.10]))
LIGHT_POWER = 0.5 * 2.10**2  # each light gives ~0.5 on the table right below it
AMBIENT_ON = 0.35
# With the room lights off only stray light (monitors, the LiDAR's host) is
# left; the real capture validates lights-off frames by mean grey < 30.
AMBIENT_OFF = 0.07

# Sensor. Exposure is fixed per camera (auto-exposure locked at the lit
# level, as in the real capture, so lights-off frames come out dark).
_EXPOSURE_TARGET_GREY = 120.0  # mean DN of a lit frame's background
BLUR_SIGMA_FULL = 0.6  # px at full resolution (lens + demosaicing)
SHOT_NOISE_GAIN = 0.15  # DN^2 per DN: variance of shot-like noise
READ_NOISE_DN = 2.0
DEPTH_NOISE_REL = 0.002  # 1-sigma relative depth noise of active stereo at ~1 m

# Tag rasterisation: supersampling factor of the output (box filter) and the
# minimum marker texture size. Marker textures are 24 * 2^j px so that both
# the 8 marker cells and the 1 cm margins (1/6 of the marker) are whole pixels.
# A box filter over s x s samples puts an edge parallel to the pixel grid (the
# table tags' edges nearly are) on a 1/s px grid, an error no camera has: at
# s = 4 the small table tags' fitted corners (poses.template) came out up to
# 0.05 px off and the pose stage's world frame tilted by 0.05-0.15 deg (1-4 mm
# at table 15, half-scale frames); at 8 the corners are within 0.002-0.025 px.
_SUPERSAMPLE = 8
_MIN_TEXTURE_PX = 64
_NEAR_M = 0.02  # tags closer than this to the camera plane are skipped


# --- tag textures -----------------------------------------------------------------


@lru_cache(maxsize=512)
def _tag_albedo(tag_id: int, marker_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Albedo (N, N) float32 of the printed tag (marker plus white margin,
    geometry.TAG_PRINT_SIZE) and its coverage (N, N) ones, N = marker_px * 8/6."""
    margin = round(marker_px * (g.TAG_PRINT_SIZE - g.TAG_SIZE) / (2 * g.TAG_SIZE))
    marker = tag_texture(tag_id, marker_px).astype(np.float32) / 255.0
    n = marker_px + 2 * margin
    tex = np.ones((n, n), np.float32)
    tex[margin : margin + marker_px, margin : margin + marker_px] = marker
    tex = TAG_BLACK + (TAG_WHITE - TAG_BLACK) * tex
    ones = np.ones_like(tex)
    for a in (tex, ones):
        a.setflags(write=False)  # shared through the cache
    return tex, ones


def _marker_px_for(edge_px: float) -> int:
    """Texture size (px) of the marker for a projected marker edge `edge_px`:
    at least the supersampled size, so one texel <= one supersample."""
    need = max(_MIN_TEXTURE_PX, _SUPERSAMPLE * edge_px)
    px = 24
    while px < need:
        px *= 2
    return px


# --- lighting ------------------------------------------------------------------------


def _irradiance(points: np.ndarray, normal: np.ndarray, light_on: bool) -> np.ndarray:
    """Irradiance (...,) at world points (..., 3) on a surface with unit `normal` (3,)."""
    if not light_on:
        return np.full(points.shape[:-1], AMBIENT_OFF)
    e = np.full(points.shape[:-1], AMBIENT_ON)
    for light in LIGHTS:
        d = light - points
        r2 = np.einsum("...i,...i->...", d, d)
        cos = np.clip(d @ normal, 0.0, None) / np.sqrt(r2)
        e = e + LIGHT_POWER * cos / r2
    return e


# --- background (cached per camera) ------------------------------------------------


def _camera_key(camera: Camera) -> tuple:
    # Camera holds arrays, so it is not hashable: key on its defining numbers.
    return (
        camera.name,
        camera.intrinsics,
        np.asarray(camera.R_wc, float).tobytes(),
        np.asarray(camera.t_wc, float).tobytes(),
    )


class _Background:
    """Everything about a camera's view of the scene's surfaces (tables, wall,
    floor) that does not change between frames.

    rays (H, W, 3) float32 unit world directions; ray_z (H, W) float32 their
    camera-axis component (z-depth per unit ray length); depth (H, W) float32
    z-depth in m (0 = no surface within MAX_DEPTH_M); radiance_on / _off
    (H, W, 3) float32 BGR linear radiance; exposure: DN per radiance unit.
    """

    def __init__(self, camera: Camera, scene: TrackedScene):
        self.origin = camera.position
        rays = camera.rays()  # (H, W, 3) float64
        # Contiguous components: dot products with fixed 3-vectors as three
        # multiply-adds are several times faster than (H, W, 3) @ (3,).
        self._comp = tuple(np.ascontiguousarray(rays[..., i]) for i in range(3))
        fwd = np.asarray(camera.R_wc, float)[2]  # camera z axis in world
        ray_z = self._dot(fwd)
        hw = rays.shape[:2]

        # Nearest hit over the bounded planar surfaces (tables, wall).
        surfaces = [("table", tid, rect) for tid, rect in scene.tables.items()] + [("wall", None, scene.wall)]
        t_best = np.full(hw, np.inf)
        which = np.full(hw, -1, np.int8)
        for k, (_, _, rect) in enumerate(surfaces):
            t = self._hit_rect(rect)
            closer = t < t_best
            t_best = np.where(closer, t, t_best)
            which[closer] = k
        # The floor: an unbounded plane below the tables.
        with np.errstate(divide="ignore", invalid="ignore"):
            t_floor = (FLOOR_Z - self.origin[2]) / self._comp[2]
        t_floor = np.where(t_floor > 0, t_floor, np.inf)
        floor = t_floor < t_best
        t_best = np.where(floor, t_floor, t_best)
        which[floor] = len(surfaces)
        none = t_best > MAX_DEPTH_M
        which[none] = -1

        points = self.origin + np.where(none, 0.0, t_best)[..., None] * rays
        rad_on = np.empty(hw + (3,))
        rad_off = np.empty(hw + (3,))
        rad_on[:] = BACKDROP_RADIANCE
        rad_off[:] = BACKDROP_RADIANCE * (AMBIENT_OFF / AMBIENT_ON)
        for k, (kind, tid, rect) in enumerate(surfaces + [("floor", None, None)]):
            m = which == k
            if not m.any():
                continue
            p = points[m]
            normal = np.array([0.0, 0.0, 1.0]) if rect is None else rect.normal
            if kind == "wall":
                normal = -normal if (self.origin - rect.centre) @ normal < 0 else normal
            albedo = self._albedo(kind, tid, p)
            rad_on[m] = albedo * _irradiance(p, normal, True)[:, None]
            rad_off[m] = albedo * _irradiance(p, normal, False)[:, None]

        self.rays = rays.astype(np.float32)
        del self._comp
        self.ray_z = ray_z.astype(np.float32)
        self.depth = np.where(none, 0.0, t_best * ray_z).astype(np.float32)
        # RGB -> BGR once here, so per-frame work is in the output layout.
        self.radiance_on = np.ascontiguousarray(rad_on[..., ::-1], dtype=np.float32)
        self.radiance_off = np.ascontiguousarray(rad_off[..., ::-1], dtype=np.float32)
        self.exposure = _EXPOSURE_TARGET_GREY / float(self.radiance_on.mean())

    def _hit_rect(self, rect: g.Rect) -> np.ndarray:
        """Ray parameter t (H, W) of hits inside `rect`, inf elsewhere."""
        n = rect.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((rect.centre - self.origin) @ n) / self._dot(n)
        t = np.where(np.isfinite(t) & (t > 0), t, np.inf)
        tf = np.where(np.isfinite(t), t, 0.0)
        # In-plane coordinates of the hit: (origin - centre) . a + t (ray . a).
        oc = self.origin - rect.centre
        a_u = oc @ rect.u + tf * self._dot(rect.u)
        a_v = oc @ rect.v + tf * self._dot(rect.v)
        inside = (np.abs(a_u) <= rect.size[0] / 2) & (np.abs(a_v) <= rect.size[1] / 2)
        return np.where(inside, t, np.inf)

    def _dot(self, a: np.ndarray) -> np.ndarray:
        """Per-pixel ray . a (H, W) for a world 3-vector a."""
        x, y, z = self._comp
        return x * a[0] + y * a[1] + z * a[2]

    @staticmethod
    def _albedo(kind: str, tid: int | None, p: np.ndarray) -> np.ndarray:
        """RGB albedo (N, 3) at world points p (N, 3), with mild deterministic
        texture (wood grain, paint, carpet) so surfaces are not perfectly flat
        in the image, kept low-contrast so it never resembles a tag edge."""
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        if kind == "table":
            grain = 1.0 + 0.03 * np.sin(2 * np.pi * (23.0 * y + 0.4 * np.sin(2 * np.pi * 2.3 * x)))
            return TABLE_ALBEDO[tid] * grain[:, None]
        if kind == "wall":
            paint = 1.0 + 0.015 * np.sin(2 * np.pi * 3.1 * x) * np.sin(2 * np.pi * 4.3 * z)
            return WALL_RGB * paint[:, None]
        carpet = 1.0 + 0.08 * np.sin(2 * np.pi * 1.7 * x) * np.cos(2 * np.pi * 1.1 * y)
        return FLOOR_RGB * carpet[:, None]


_BG_CACHE: dict[tuple, _Background] = {}
_BG_CACHE_MAX = 8


def _background(camera: Camera, scene: TrackedScene) -> _Background:
    key = (*_camera_key(camera), scene.surfaces_key())
    bg = _BG_CACHE.get(key)
    if bg is None:
        if len(_BG_CACHE) >= _BG_CACHE_MAX:
            _BG_CACHE.pop(next(iter(_BG_CACHE)))  # oldest first (dicts keep order)
        bg = _BG_CACHE[key] = _Background(camera, scene)
    return bg


# --- tags ------------------------------------------------------------------------------


def frame_tags(
    location: int, camera_name: str, gantry_offset: tuple[float, float, float] = (0.0, 0.0, 0.0), scene: TrackedScene | None = None
) -> dict[int, Pose]:
    """Tags present in a frame at gantry `location` (0..99): every static tag
    of `scene` (default: the design drawing) plus the object tag 1 at the
    scene's pose for `location` moved by the carriage's `gantry_offset` (m,
    world). The same set serves both cameras; the renderer skips whatever a
    camera cannot see."""
    if camera_name not in (g.TRACKING_CAMERA.name, g.COLOCATED_CAMERA.name):
        raise ValueError(f"unknown camera {camera_name!r}")
    if not 0 <= int(location) < g.N_LOCATIONS:
        raise ValueError(f"gantry location must be 0..{g.N_LOCATIONS - 1}, got {location}")
    scene = scene or design_scene()
    tag1 = scene.tag1_pose(int(location))
    return {**scene.static_tags, g.OBJECT_TAG_ID: Pose(tag1.R, tag1.t + np.asarray(gantry_offset, float))}


def _draw_tag(img: np.ndarray, depth: np.ndarray, bg: _Background, camera: Camera, tag_id: int, tag_pose: Pose, light_on: bool) -> None:
    """Composite one tag into `img` (H, W, 3) radiance and `depth` (H, W) m in place."""
    normal_out = -tag_pose.R[:, 2]  # tag z points into the tag
    if (bg.origin - tag_pose.t) @ normal_out <= 0:
        return  # seen from behind (or edge-on): the back of the plate
    corners = tag_pose.apply(g.tag_corners_local(g.TAG_PRINT_SIZE))
    uv, z = camera.project(corners)
    if np.any(z < _NEAR_M):
        return  # behind (or straddling) the camera
    x0 = max(int(np.floor(uv[:, 0].min())) - 1, 0)
    y0 = max(int(np.floor(uv[:, 1].min())) - 1, 0)
    x1 = min(int(np.ceil(uv[:, 0].max())) + 2, camera.width)
    y1 = min(int(np.ceil(uv[:, 1].max())) + 2, camera.height)
    if x1 <= x0 or y1 <= y0:
        return  # entirely outside the image
    w, h = x1 - x0, y1 - y0

    # Texture resolution from the projected size of the 6 cm marker.
    marker_uv, _ = camera.project(tag_pose.apply(g.tag_corners_local(g.TAG_SIZE)))
    edge = float(np.max(np.linalg.norm(marker_uv - np.roll(marker_uv, 1, axis=0), axis=1)))
    tex, ones = _tag_albedo(int(tag_id), _marker_px_for(edge))
    n = tex.shape[0]

    # Texture texel centres sit at integers, so the tag's outer edges are at
    # -0.5 and n - 0.5; same for the supersampled box grid, whose sample s
    # covers image u in [x0 - 0.5 + s/ss, x0 - 0.5 + (s+1)/ss].
    ss = _SUPERSAMPLE
    src = np.array([[-0.5, -0.5], [n - 0.5, -0.5], [n - 0.5, n - 0.5], [-0.5, n - 0.5]], np.float32)
    dst = (ss * (uv - [x0, y0] + 0.5) - 0.5).astype(np.float32)
    H = cv2.getPerspectiveTransform(src, dst)
    size = (w * ss, h * ss)
    warp = dict(flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    alb = cv2.warpPerspective(tex, H, size, **warp)
    cov = cv2.warpPerspective(ones, H, size, **warp)
    # Box filter the supersamples: exact area average for an integer factor.
    alb = cv2.resize(alb, (w, h), interpolation=cv2.INTER_AREA)
    cov = cv2.resize(cov, (w, h), interpolation=cv2.INTER_AREA)

    # z-depth of the tag plane through each pixel of the box, for the depth
    # test against what is already drawn and for the depth image itself.
    rays = bg.rays[y0:y1, x0:x1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((tag_pose.t - bg.origin) @ normal_out) / (rays @ normal_out)
    tag_depth = (t * bg.ray_z[y0:y1, x0:x1]).astype(np.float32)
    behind = depth[y0:y1, x0:x1]
    visible = (tag_depth > 0) & ((behind <= 0) | (tag_depth < behind + 0.002))
    a = np.where(visible, cov, 0.0).astype(np.float32)

    # One irradiance for the whole 8 cm square: lighting varies little over it.
    e = float(_irradiance(tag_pose.t, normal_out, light_on))
    patch = img[y0:y1, x0:x1]
    # alb is premultiplied by coverage (warped with a black border), so
    # composite as patch * (1 - a) + alb * e, restricted to visible pixels.
    patch *= (1.0 - a)[..., None]
    patch += (np.where(visible, alb, 0.0) * e)[..., None]
    d = depth[y0:y1, x0:x1]
    solid = visible & (cov > 0.5)
    d[solid] = tag_depth[solid]


# --- the frame ---------------------------------------------------------------------


def render_frame(
    camera: Camera,
    tags: dict[int, Pose],
    light_on: bool,
    rng: np.random.Generator,
    *,
    scene: TrackedScene | None = None,
    blur_sigma_px: float = BLUR_SIGMA_FULL,
    read_noise_dn: float = READ_NOISE_DN,
) -> tuple[np.ndarray, np.ndarray]:
    """Render one aligned RGB-D frame of `camera` (any `Camera.scaled` copy).

    tags: tag id -> Pose (tag frame -> world, m), e.g. from `frame_tags`.
    light_on: room lights on (normal exposure) or off (dark frame, mean grey
    well below 30). rng: the only source of randomness (sensor noise).
    scene: whose tables and wall form the background (default: the design
    drawing; the tags come from `tags`). blur_sigma_px: optical blur sigma in full-resolution pixels (scaled with
    the image). read_noise_dn: Gaussian read noise, DN (8-bit levels).

    Returns (bgr, depth): bgr (H, W, 3) uint8; depth (H, W) uint16 z-depth
    along the camera axis in millimetres, 0 where there is no surface within
    10 m. Depth comes from an active stereo sensor, so it ignores `light_on`.
    """
    bg = _background(camera, scene or design_scene())
    img = (bg.radiance_on if light_on else bg.radiance_off).copy()
    depth = bg.depth.copy()

    # Painter's order, far to near, plus a per-pixel depth test inside _draw_tag.
    order = sorted(tags.items(), key=lambda kv: -float(camera.project(kv[1].t)[1]))
    for tag_id, tag_pose in order:
        _draw_tag(img, depth, bg, camera, tag_id, tag_pose, light_on)

    # Optics: blur in radiance (before the sensor), sigma scaled with the image.
    img *= np.float32(bg.exposure)
    sigma = blur_sigma_px * camera.width / _full_width(camera)
    if sigma > 0:
        cv2.GaussianBlur(img, (0, 0), sigma, dst=img, borderType=cv2.BORDER_REFLECT)

    # Sensor: Gaussian approximation of shot (variance ~ signal) + read noise.
    noise = rng.standard_normal(img.shape, dtype=np.float32)
    std = np.sqrt(np.clip(img, 0.0, None) * np.float32(SHOT_NOISE_GAIN) + np.float32(read_noise_dn**2))
    img += std * noise
    np.clip(img, 0.0, 255.0, out=img)
    bgr = np.rint(img).astype(np.uint8)

    # Depth: relative Gaussian noise, then round to whole millimetres.
    dn = rng.standard_normal(depth.shape, dtype=np.float32)
    mm = depth * np.float32(1000.0) * (np.float32(1.0) + np.float32(DEPTH_NOISE_REL) * dn)
    mm[depth <= 0] = 0.0
    depth_mm = np.rint(np.clip(mm, 0.0, 65535.0)).astype(np.uint16)
    return bgr, depth_mm


def _full_width(camera: Camera) -> int:
    """Full-resolution width of the rig camera `camera` was scaled from (px)."""
    for full in (g.TRACKING_CAMERA, g.COLOCATED_CAMERA):
        if camera.name == full.name:
            return full.width
    return camera.width  # an unknown camera: treat as full scale
