"""Mitsuba 3 scenes of the twin: the transient NLOS scene and the tracking
camera's RGB view (Fig 18).

Functions take the `mitsuba` module returned by `variant.load_mitsuba`, so
nothing here imports drjit at module import time.

Transient scene (`transient_scene`), per mitransient's NLOS set-up, one
per relay patch (a zone's footprint, or the whole wall):
- `relay`: a rectangle over the patch, a Lambertian BSDF and the
  `nlos_capture_meter` sensor with a `transient_hdr_film` of film x film
  pixels, 128 bins of the twin's time axis, starting at its start less the
  twin's time offset (the real data's time axis);
- `spot`: a SPOT_PATCH_M square of wall around the laser spot, SPOT_BEHIND_M
  behind the wall plane, for the laser to land on where the patch does not
  hold the spot (an off-centre zone): mitransient needs the laser to hit
  the scene, and a path through it to the object needs only its spot;
- `object`: the wall-facing face as a triangle mesh, `diffuse` or the
  `retroreflective_bsdf` plugin (`twin.bsdf`). Its vertex buffer is
  moved between locations through `mi.traverse` (a mesh keeps the compiled
  kernel; rectangles would recompile per pose);
- `table0`, `table1`: the table tops, when the twin has them;
- `laser`: a `projector` at the sensor with a 0.2 deg cone aimed at the spot,
  of unit radiant intensity (Mitsuba's projector emits pi x `irradiance` on
  its axis, measured), so renders are in the analytic renderer's units.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import FLOOR_Z, Camera, Pose, Rect
from denali_pipe.core.tags import TAG_BLACK, TAG_WHITE, tag_texture
from denali_pipe.twin.layout import Calibration, TwinScene

LASER_FOV_DEG = 0.2  # the reference twin's laser cone
SPOT_PATCH_M = 0.02  # side of the wall square the laser lands on (its 0.2 deg cone is ~2 mm across there)
SPOT_BEHIND_M = 1e-4  # behind the wall plane, so that a relay patch holding the spot takes the laser itself
PROJECTOR_INTENSITY_PER_IRRADIANCE = np.pi  # Mitsuba projector: on-axis W/sr per unit `irradiance`
# Integrator settings shared by every transient render: laser and hidden-geometry
# sampling (the NLOS estimators), box time filter, sensor-relative path lengths.
NLOS_INTEGRATOR = {
    "nlos_laser_sampling": True,
    "nlos_hidden_geometry_sampling": True,
    "nlos_hidden_geometry_sampling_do_rroulette": False,
    "temporal_filter": "box",
    "account_first_and_last_bounces": True,
    "capture_type": 1,  # one laser spot
}

# RGB view: albedos of what only the camera sees (the reference twin's).
VISUAL_ALBEDO = 0.8  # the visible wall
TABLE_RGB = (0.6, 0.5, 0.4)
FLOOR_ALBEDO = 0.02  # a dark floor below the tables: the reference's black backdrop
TAG_EDGE = 0.08  # printed tag including its white margin, m
TAG_TEXTURE_PX = 96  # marker pixels: 8 cells x 12


def rect_transform(mi: ModuleType, rect: Rect) -> object:
    """to_world of Mitsuba's [-1, 1]^2 `rectangle` (normal +z) onto `rect`:
    local x -> u, y -> v, z -> the rect's normal (u x v), so the lit side
    faces where `rect.normal` points and uv runs along (u, v)."""
    m = np.eye(4)
    m[:3, 0] = rect.u * rect.size[0] / 2
    m[:3, 1] = rect.v * rect.size[1] / 2
    m[:3, 2] = rect.normal
    m[:3, 3] = rect.centre
    return mi.ScalarTransform4f(m.tolist())


def diffuse(albedo) -> dict:
    """A Lambertian BSDF of a grey (scalar) or RGB albedo."""
    rgb = [float(albedo)] * 3 if np.ndim(albedo) == 0 else [float(a) for a in albedo]
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": rgb}}


def triangle_mesh(mi: ModuleType, name: str, vertices: np.ndarray, faces: np.ndarray, bsdf: dict) -> object:
    """A Mitsuba mesh from world vertices (V, 3) and faces (F, 3)."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf)
    mesh = mi.Mesh(name, len(vertices), len(faces), props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.asarray(vertices, np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, np.uint32).ravel())
    params.update()
    return mesh


def transient_scene(mi: ModuleType, twin: TwinScene, relay: Rect, max_depth: int, integrator: str, location: int) -> dict:
    """The transient scene dict with the object at `location`.

    integrator: the registered integrator type (`transient_nlos_path`, or the
    table-safe subclass of `twin.mitransient`); relay: the patch of the
    film (one of `twin.relays`)."""
    from denali_pipe.twin.bsdf import object_bsdf

    film = {
        "type": "transient_hdr_film",
        "width": twin.film,
        "height": twin.film,
        "temporal_bins": geo.N_BINS,
        "bin_width_opl": twin.time_axis.bin_width_opl,
        "start_opl": twin.time_axis.start_opl - twin.time_offset_opl,
        "rfilter": {"type": "box"},
    }
    spot = Rect(twin.spot - SPOT_BEHIND_M * relay.normal, relay.u, relay.v, (SPOT_PATCH_M, SPOT_PATCH_M))
    scene = {
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": int(max_depth), **NLOS_INTEGRATOR},
        "relay": {
            "type": "rectangle",
            "to_world": rect_transform(mi, relay),
            "bsdf": diffuse(twin.wall_albedo),
            "sensor": {
                "type": "nlos_capture_meter",
                "sensor_origin": mi.ScalarPoint3f(*map(float, twin.sensor)),
                "sampler": {"type": "independent"},
                "film": film,
            },
        },
        "spot": {"type": "rectangle", "to_world": rect_transform(mi, spot), "bsdf": diffuse(twin.wall_albedo)},
        "object": triangle_mesh(mi, "object", twin.poses[location].apply(twin.vertices), twin.faces, object_bsdf(mi, twin.material)),
        "laser": {
            "type": "projector",
            "irradiance": 1.0 / PROJECTOR_INTENSITY_PER_IRRADIANCE,
            "fov": LASER_FOV_DEG,
            "to_world": mi.ScalarTransform4f().look_at(origin=twin.sensor.tolist(), target=twin.spot.tolist(), up=[0.0, 0.0, 1.0]),
        },
    }
    for i, table in enumerate(twin.tables):
        scene[f"table{i}"] = {"type": "rectangle", "to_world": rect_transform(mi, table), "bsdf": diffuse(twin.table_albedo)}
    return scene


# --- the tracking camera's view --------------------------------------------------------


def camera_sensor(mi: ModuleType, camera: Camera, spp: int) -> dict:
    """A Mitsuba `perspective` sensor reproducing an OpenCV pinhole camera
    (horizontal FoV from fx, principal point as a film offset)."""
    R_cw = camera.R_wc.T  # columns: OpenCV camera axes in world
    m = np.eye(4)
    # Mitsuba's camera looks along +z with +x to the left and +y up: flip OpenCV's x and y
    m[:3, 0], m[:3, 1], m[:3, 2] = -R_cw[:, 0], -R_cw[:, 1], R_cw[:, 2]
    m[:3, 3] = camera.position
    w, h = camera.width, camera.height
    return {
        "type": "perspective",
        "fov_axis": "x",
        "fov": float(np.degrees(2 * np.arctan(w / (2 * camera.fx)))),
        # in film fractions, positive toward the image's left and top (measured
        # by projecting points); OpenCV's pixel centres sit at integers
        "principal_point_offset_x": float((w / 2 - camera.cx - 0.5) / w),
        "principal_point_offset_y": float((h / 2 - camera.cy - 0.5) / h),
        "to_world": mi.ScalarTransform4f(m.tolist()),
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgb", "rfilter": {"type": "box"}},
    }


def _tag_bitmap(mi: ModuleType, tag_id: int) -> object:
    """The printed tag (marker plus white margin) as an RGB bitmap, TL corner first."""
    margin = TAG_TEXTURE_PX // 6  # 1 cm of the 6 cm marker
    n = TAG_TEXTURE_PX + 2 * margin
    tex = np.ones((n, n), np.float32)
    tex[margin:-margin, margin:-margin] = tag_texture(tag_id, TAG_TEXTURE_PX) / 255.0
    tex = TAG_BLACK + (TAG_WHITE - TAG_BLACK) * tex
    return mi.Bitmap(np.repeat(tex[..., None], 3, axis=2))


def _tag_shape(mi: ModuleType, tag_id: int, pose: Pose) -> dict:
    """A printed tag: local x, y of the rectangle run along the tag's x
    (right) and y (down), so uv (0, 0) is its top-left corner, bitmap row 0;
    two-sided, so the sign of the normal does not matter."""
    m = np.eye(4)
    m[:3, 0] = pose.R[:, 0] * TAG_EDGE / 2
    m[:3, 1] = pose.R[:, 1] * TAG_EDGE / 2
    m[:3, 2] = pose.R[:, 2]
    m[:3, 3] = pose.t - 0.0005 * pose.R[:, 2]  # tag z points into its surface: stand just proud of it
    texture = {"type": "bitmap", "bitmap": _tag_bitmap(mi, tag_id), "filter_type": "nearest", "raw": True}
    return {
        "type": "rectangle",
        "to_world": mi.ScalarTransform4f(m.tolist()),
        "bsdf": {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": texture}},
    }


def rgb_scene(mi: ModuleType, cal: Calibration, twin: TwinScene, location: int, camera: Camera, spp: int) -> dict:
    """The tracking camera's view of the calibrated scene with the object at
    `location`: `path` integrator under a uniform sky (the reference twin's
    lighting), black floor, relay wall, tables, tags, mount post, object."""
    pose = twin.poses[location]
    post_w, post_h, post_d = geo.MOUNT_POST_SIZE
    post = np.diag([post_w / 2, post_d / 2, post_h / 2, 1.0])
    post[:3, 3] = pose.t - [0.0, 0.0, post_h / 2]
    floor = Rect(np.array([cal.wall.centre[0], 0.0, FLOOR_Z]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), (10.0, 10.0))
    scene = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 4},
        "sensor": camera_sensor(mi, camera, spp),
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
        "floor": {"type": "rectangle", "to_world": rect_transform(mi, floor), "bsdf": diffuse(FLOOR_ALBEDO)},
        "wall": {"type": "rectangle", "to_world": rect_transform(mi, cal.wall), "bsdf": {"type": "twosided", "bsdf": diffuse(VISUAL_ALBEDO)}},
        "post": {"type": "cube", "to_world": mi.ScalarTransform4f(post.tolist()), "bsdf": diffuse(geo.MOUNT_POST_ALBEDO)},
        "object": triangle_mesh(mi, "object", pose.apply(twin.mesh.vertices), twin.mesh.faces, {"type": "twosided", "bsdf": diffuse(twin.object_albedo)}),
    }
    for i, table in enumerate(cal.tables):
        scene[f"table{i}"] = {"type": "rectangle", "to_world": rect_transform(mi, table), "bsdf": diffuse(TABLE_RGB)}
    tags = {**cal.tags, geo.OBJECT_TAG_ID: cal.tag1_poses[location]}
    for tag_id, tag_pose in sorted(tags.items()):
        scene[f"tag{tag_id}"] = _tag_shape(mi, tag_id, tag_pose)
    return scene


def render_rgb(mi: ModuleType, scene: dict, seed: int) -> np.ndarray:
    """Render an `rgb_scene`: (H, W, 3) uint8 RGB, linear radiance clipped to
    [0, 1] then sRGB-encoded (as a camera's JPEG/PNG would be)."""
    image = mi.render(mi.load_dict(scene), seed=seed)
    srgb = np.asarray(mi.Bitmap(image).convert(srgb_gamma=True, component_format=mi.Struct.Type.Float32))
    return (np.clip(srgb, 0, 1) * 255 + 0.5).astype(np.uint8)
