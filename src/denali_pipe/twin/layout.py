"""The digital twin's scene as plain arrays: what every renderer draws.

The geometry is the calibrated one (`results/calibration/scene.json`, written
by `poses.calibrate.scene_dict`): relay wall, table tops, sensor pose,
tracking camera, object pose per gantry location. On top of it the twin
follows the paper's (supplement section 11.4):

- the illumination (`twin.illumination`): the paper's one laser spot, a
  pulsed point source at the sensor aimed along the sensor's axis (where
  the centre of the TMF8828's flood lands on the wall), or the flood
  itself: the VCSEL lighting the sensor's whole field of view, with an
  elliptical Gaussian emission profile about the axis (`Flood`; its widths
  fitted from the captures by `twin.calibrate`);
- every zone of the sensor's 3x3 or 8x8 grid (`geometry.SENSOR_FOV_DEG`
  tiled as `geometry.zone_edges` tiles it, in the captures' order: row 0 at
  the top, column 0 at the sensor's right) has its own film: the zone's wall
  footprint, a wall-aligned rectangle sampled at `film` x `film` pixel
  centres. The relay surface *is* that patch (the rest of the wall adds no
  three-bounce path between spot, object and footprint, and a whole-wall
  film would spend almost every sample outside the footprints);
- each footprint can be moved on the wall and scaled about its centre
  (`ZoneGeometry`, fitted by `twin.calibrate`), the twin's time axis shifted
  by a path offset, both from the captures, never by hand;
- the object is its wall-facing face only (a plate, Lambertian or with a
  retroreflective lobe: `twin.material`): the rig's model of it, and with it
  both renderers see exactly the same surface;
- table tops optionally (mitransient only).

Units: metres; albedos unitless.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import Camera, Intrinsics, Pose, Rect, TimeAxis
from denali_pipe.core.objects import BOTTOM_Y
from denali_pipe.twin.illumination import check_illumination

MATERIALS = ("lambertian", "retroreflective")


@dataclass(frozen=True)
class Calibration:
    """What the twin reads from scene.json.

    sensor_rotation: (3, 3) sensor -> world, OpenCV axes (x right, y down,
    z forward). tags: {tag id: Pose (tag frame -> world)}.
    object_poses/tag1_poses: {gantry location: Pose (object mesh frame /
    object tag frame -> world)}."""

    path: Path
    wall: Rect
    tables: tuple[Rect, ...]
    sensor_position: np.ndarray
    sensor_rotation: np.ndarray
    tracking_camera: Camera
    tags: dict[int, Pose]
    object_poses: dict[int, Pose]
    tag1_poses: dict[int, Pose]

    @property
    def locations(self) -> list[int]:
        return sorted(self.object_poses)


def _rect(d: dict) -> Rect:
    return Rect(np.asarray(d["centre"], float), np.asarray(d["u"], float), np.asarray(d["v"], float), tuple(map(float, d["size"])))


def load_calibration(path: str | Path) -> Calibration:
    """Read scene.json. Raises ValueError naming the file and the missing or
    empty section (wall, sensor, tracking_camera, locations, table)."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    for key in ("wall", "sensor", "tracking_camera", "locations", "table"):
        if not doc.get(key):
            raise ValueError(f"{path}: the calibrated scene has no {key!r} (the calibration could not estimate it)")
    try:
        cam = doc["tracking_camera"]
        camera = Camera(
            "tracking", Intrinsics.from_dict(cam["intrinsics"]),
            np.asarray(cam["R_world_to_camera"], float), np.asarray(cam["t_world_to_camera"], float),
        )  # fmt: skip
        sensor = doc["sensor"]
        return Calibration(
            path=path,
            wall=_rect(doc["wall"]),
            tables=tuple(_rect(r) for _, r in sorted(doc["table"]["rectangles"].items())),
            sensor_position=np.asarray(sensor["position"], float),
            sensor_rotation=np.asarray(sensor["pose"]["R"], float),
            tracking_camera=camera,
            tags={int(k): geo.pose(t["rotation"], t["position"]) for k, t in doc.get("tags", {}).items()},
            object_poses={int(k): geo.pose(rec["object"]["R"], rec["object"]["t"]) for k, rec in doc["locations"].items()},
            tag1_poses={int(k): geo.pose(rec["tag1"]["R"], rec["tag1"]["t"]) for k, rec in doc["locations"].items()},
        )
    except (KeyError, TypeError) as e:
        raise ValueError(f"{path}: malformed calibrated scene ({type(e).__name__}: {e})") from None


# --- where the sensor looks ----------------------------------------------------------------


def _ray(cal: Calibration, tx: float, ty: float) -> np.ndarray:
    """World direction of the sensor ray through tangent-plane point (tx, ty)."""
    d = cal.sensor_rotation @ np.array([tx, ty, 1.0])
    return d / np.linalg.norm(d)


def laser_spot(cal: Calibration) -> np.ndarray:
    """(3,) where the sensor's axis meets the wall plane: the laser spot."""
    return geo.intersect_plane(cal.sensor_position, _ray(cal, 0.0, 0.0), cal.wall)


@dataclass(frozen=True)
class ZoneGeometry:
    """Where each zone of an n x n grid looks, relative to the design FoV:
    offsets (n, n, 2) metres along the wall's (u, v) by which each zone's
    footprint centre moves, scales (n, n) by which its size (the zone's
    iFoV) is multiplied about that centre."""

    offsets: np.ndarray
    scales: np.ndarray

    @classmethod
    def nominal(cls, n: int, scale: float = 1.0) -> ZoneGeometry:
        return cls(np.zeros((n, n, 2)), np.full((n, n), float(scale)))

    @property
    def n(self) -> int:
        return self.scales.shape[0]


def zone_footprints(cal: Calibration, n: int, zones: ZoneGeometry | None = None) -> list[Rect]:
    """The wall footprints of the n x n zones, row-major in the captures'
    order (`geometry.zone_edges`: row 0 at the top, column 0 at the sensor's right).

    A zone's view cone meets the wall in a near-trapezoid; its rectangle
    spans the midpoints of the four edges (so its area matches the
    trapezoid's to first order), then is moved by the zone's offset and
    scaled about its centre (`zones`; the design FoV when None)."""
    zones = zones or ZoneGeometry.nominal(n)
    if zones.n != n:
        raise ValueError(f"zone geometry of a {zones.n}x{zones.n} grid given for a {n}x{n} one")
    edges_h, edges_v = geo.zone_edges(n)
    w = cal.wall
    rects = []
    for r in range(n):
        for c in range(n):
            xm, ym = (edges_h[c] + edges_h[c + 1]) / 2, (edges_v[r] + edges_v[r + 1]) / 2
            mids = [(edges_h[c], ym), (edges_h[c + 1], ym), (xm, edges_v[r]), (xm, edges_v[r + 1])]  # the four edges' midpoints
            p = np.array([geo.intersect_plane(cal.sensor_position, _ray(cal, x, y), w) for x, y in mids])
            rel = p - w.centre
            pu, pv = rel @ w.u, rel @ w.v
            cu, cv = (pu[0] + pu[1]) / 2 + zones.offsets[r, c, 0], (pv[2] + pv[3]) / 2 + zones.offsets[r, c, 1]
            s = zones.scales[r, c]
            rects.append(Rect(w.centre + cu * w.u + cv * w.v, w.u, w.v, (abs(pu[1] - pu[0]) * s, abs(pv[3] - pv[2]) * s)))
    return rects


# Sampling of `three_bounce_lead`: each zone's footprint on a 6 x 6 grid (the
# wall's lit points, every zone's, the same) and the plate's rectangle on a
# 13 x 13 grid (1.7 cm apart at 8 in). Grids 2x and 4x finer moved the demo's
# 3x3 leads by at most 0.4 bins, either way, and one zone's first kept bin
# (`preprocess.crop_window`) by one bin (71 -> 72 at 4x).
LEAD_GRID, PLATE_GRID = 6, 13


def three_bounce_lead(cal: Calibration, n: int, plate_size: float) -> np.ndarray:
    """(n, n) per zone, the least optical path (m) by which a hidden object's
    three-bounce return can arrive after the zone's earliest direct return.

    Paths: sensor -> lit wall point p -> object point o -> the zone's wall
    point q -> sensor, against 2 |sensor - q'| for the zone's nearest q'. The
    sensor floods its whole field, so p ranges over every zone's footprint;
    o over the rectangle any plate of largest dimension `plate_size` (m)
    lies in, in its frame (`objects`: centred in x, bottom edge at
    BOTTOM_Y), at each gantry location's object pose of the scene. Used to
    keep a zone's bins from the time its object signal can begin
    (`preprocess.crop_window`)."""
    s = cal.sensor_position
    feet = zone_footprints(cal, n)
    walls = np.concatenate([pixel_centres(r, LEAD_GRID).reshape(-1, 3) for r in feet])
    outline = Rect(np.array([0.0, BOTTOM_Y + plate_size / 2, 0.0]), np.array([1.0, 0, 0]), np.array([0.0, 1, 0]), (plate_size, plate_size))
    plate = pixel_centres(outline, PLATE_GRID).reshape(-1, 3)
    objects = np.concatenate([cal.object_poses[k].apply(plate) for k in cal.locations])
    first = (np.linalg.norm(walls - s, axis=1)[None, :] + np.linalg.norm(objects[:, None] - walls[None], axis=2)).min(axis=1)  # (O,)
    out = []
    for rect in feet:
        q = pixel_centres(rect, LEAD_GRID).reshape(-1, 3)
        back = np.linalg.norm(q - s, axis=1)
        last = (np.linalg.norm(objects[:, None] - q[None], axis=2) + back[None]).min(axis=1)  # (O,)
        out.append((first + last).min() - 2 * back.min())
    return np.array(out).reshape(n, n)


@dataclass(frozen=True)
class Emission:
    """The sensor's emission over its field, two lobes on its axis: relative
    radiant intensity toward angles a_h, a_v (deg) from the axis across and
    along the field,

        E = (1 - c) G(a_h / w_h, a_v / w_v) + c G(a_h / w_c, a_v / w_c),
        G(x, y) = exp(-ln 2 (x^2 + y^2)),

    1 on the axis. The flood (half widths at half maximum `hwhm_deg` (w_h,
    w_v)) is the light the VCSEL package's microlens array spreads over the
    field; the core (round, `core_hwhm_deg` w_c) the light that leaves it
    unspread, with the VCSEL's own divergence; `core_share` c its part of
    the on-axis intensity (the default, 0: the flood alone). A single elliptical Gaussian, or any product of a
    horizontal and a vertical profile, makes the centre zone's light over an
    edge zone's equal an edge zone's over a corner's; the real sensor's zone
    means have 2.46 against 1.38 (docs/twin.md)."""

    hwhm_deg: tuple[float, float]
    core_share: float = 0.0
    core_hwhm_deg: float = 1.0

    def flood(self, a_h: np.ndarray, a_v: np.ndarray) -> np.ndarray:
        """The flood lobe's part of the intensity toward (a_h, a_v) deg."""
        return (1 - self.core_share) * np.exp(-np.log(2) * ((a_h / self.hwhm_deg[0]) ** 2 + (a_v / self.hwhm_deg[1]) ** 2))

    def core(self, a_h: np.ndarray, a_v: np.ndarray) -> np.ndarray:
        """The core lobe's part of the intensity toward (a_h, a_v) deg."""
        return self.core_share * np.exp(-np.log(2) * (a_h**2 + a_v**2) / self.core_hwhm_deg**2)

    def core_solid_angle(self) -> float:
        """The core's intensity integrated over directions (sr, per unit of
        on-axis intensity): c pi w_c^2 / ln 2, w_c in radians (a few degrees:
        the small-angle integral is exact to well under 1 %)."""
        return self.core_share * np.pi * np.deg2rad(self.core_hwhm_deg) ** 2 / np.log(2)


# The spacing, in core half widths, of the sub-samples over which a film
# pixel's mean emission is taken (`Flood.pixel_intensity`): at 0.5 the mean
# of a Gaussian over a pixel is within 1 % (tests/test_twin_layout.py).
SUBSAMPLE_SPACING = 0.5


@dataclass(frozen=True)
class Flood:
    """The sensor's flood illumination of the wall, `emission` (`Emission`)
    about the sensor's axis.

    points (M, 3) and areas (M,) m^2: the lit wall the flood lobe lights,
    sampled as a `grid` x `grid` film over each design 3x3 zone footprint
    (the field the VCSEL lights is the field the zones see). The core, a few
    degrees wide (a few cm on the wall, seen from an object tens of cm away),
    lights the wall as one spot: `axis_point` (3,), where the sensor's axis
    meets the wall. sensor_rotation (3, 3): sensor -> world, OpenCV axes;
    wall_normal (3,): the wall's unit normal."""

    emission: Emission
    points: np.ndarray
    areas: np.ndarray
    sensor: np.ndarray
    sensor_rotation: np.ndarray
    axis_point: np.ndarray
    wall_normal: np.ndarray

    def angles(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(a_h, a_v) deg of world points (..., 3) from the sensor's axis."""
        d = (points - self.sensor) @ self.sensor_rotation  # into the sensor's frame: x right, y down, z forward
        return np.rad2deg(np.arctan2(d[..., 0], d[..., 2])), np.rad2deg(np.arctan2(d[..., 1], d[..., 2]))

    def intensity(self, points: np.ndarray) -> np.ndarray:
        """(...,) relative intensity, both lobes, toward world points (..., 3)."""
        a = self.angles(points)
        return self.emission.flood(*a) + self.emission.core(*a)

    def lit(self) -> tuple[np.ndarray, np.ndarray]:
        """The lit wall as spots: points (M + 1, 3) and the light each gets,
        intensity x solid angle (M + 1,) sr per unit on-axis intensity: the
        flood lobe at its grid points (intensity x area x cos / r^2), then
        the core's whole light at the axis point."""
        rel = self.points - self.sensor
        r = np.linalg.norm(rel, axis=1)
        solid = self.areas * np.abs(rel @ self.wall_normal) / r**3
        flood = self.emission.flood(*self.angles(self.points)) * solid
        return np.vstack([self.points, self.axis_point]), np.append(flood, self.emission.core_solid_angle())

    def pixel_intensity(self, relay: Rect, film: int) -> np.ndarray:
        """(film, film) the emission's mean over each film pixel of `relay`
        (`pixel_centres`' order): the core is narrower than a calibration
        pixel, and its value at the centre would swing with a pixel's place."""
        pixel_deg = np.rad2deg(max(relay.size) / film / np.linalg.norm(relay.centre - self.sensor))
        k = max(1, int(np.ceil(pixel_deg / (SUBSAMPLE_SPACING * self.emission.core_hwhm_deg)))) if self.emission.core_share > 0 else 1
        sub = pixel_centres(relay, film * k)
        return self.intensity(sub).reshape(film, k, film, k).mean(axis=(1, 3))


def flood(cal: Calibration, emission: Emission, grid: int) -> Flood:
    """The flood of `emission` over the design 3x3 footprints, each sampled
    at `grid` x `grid` points."""
    feet = zone_footprints(cal, 3)
    points = np.concatenate([pixel_centres(r, grid).reshape(-1, 3) for r in feet])
    areas = np.concatenate([np.full(grid * grid, r.size[0] * r.size[1] / grid**2) for r in feet])
    return Flood(emission, points, areas, cal.sensor_position, cal.sensor_rotation, laser_spot(cal), cal.wall.normal)


def emission_of(twin: dict) -> Emission:
    """The design emission of the config's `twin.flood`."""
    f = twin["flood"]
    return Emission(tuple(float(v) for v in f["beam_hwhm_deg"]), float(f["core_share"]), float(f["core_hwhm_deg"]))


def zone_footprint(cal: Calibration, scale: float = 1.0) -> Rect:
    """The centre zone's footprint of the 3x3 grid (the paper's film), scaled by `scale`."""
    return zone_footprints(cal, 3, ZoneGeometry.nominal(3, scale))[4]


def pixel_centres(relay: Rect, film: int) -> np.ndarray:
    """(film, film, 3) film pixel centres on `relay`: row i runs along +v
    (row 0 at the bottom edge), column j along +u, as mitransient's
    `nlos_capture_meter` samples them (one point per pixel, at its centre)."""
    t = (np.arange(film) + 0.5) / film - 0.5
    return relay.centre + t[None, :, None] * relay.size[0] * relay.u + t[:, None, None] * relay.size[1] * relay.v


def pixels_inside(relay: Rect, film: int, patch: Rect) -> np.ndarray:
    """(film, film) bool: the pixels of a film over `relay` whose centres lie in `patch`."""
    rel = pixel_centres(relay, film) - patch.centre
    return (np.abs(rel @ patch.u) <= patch.size[0] / 2) & (np.abs(rel @ patch.v) <= patch.size[1] / 2)


# --- the object --------------------------------------------------------------------------


def front_face(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """The wall-facing (-z, local) faces of an object mesh as a compact
    triangle mesh: vertices (V, 3) local metres, faces (F, 3) int. Face
    winding is kept, so the geometric normals face the wall."""
    front = mesh.faces[mesh.face_normals[:, 2] < -0.5]
    if not len(front):
        raise ValueError("the object mesh has no wall-facing (-z) faces")
    used, faces = np.unique(front, return_inverse=True)
    return np.asarray(mesh.vertices[used], float), faces.reshape(-1, 3)


@dataclass(frozen=True)
class Material:
    """The object's reflectance: albedo (the share of light reflected at
    normal incidence); kind `lambertian` or `retroreflective`: then a share
    `diffuse_share` of it Lambertian and the rest in a Gaussian lobe of
    width `lobe_width_deg` (standard deviation of the angle between the
    incident and outgoing directions) about the incident direction
    (`twin.material` documents the BRDF)."""

    kind: str
    albedo: float
    lobe_width_deg: float = 0.0
    diffuse_share: float = 1.0

    def __post_init__(self):
        if self.kind not in MATERIALS:
            raise ValueError(f"unknown twin material {self.kind!r}; expected one of {list(MATERIALS)}")
        if self.kind == "retroreflective" and not (self.lobe_width_deg > 0 and 0 <= self.diffuse_share <= 1):
            raise ValueError(f"retroreflective lobe needs a width > 0 and a diffuse share in [0, 1], got {self.lobe_width_deg}, {self.diffuse_share}")

    def to_dict(self) -> dict:
        return {"kind": self.kind, "albedo": self.albedo, "lobe_width_deg": self.lobe_width_deg, "diffuse_share": self.diffuse_share}


def material_of(settings: dict, retroreflective: bool = True, calibrated: dict | None = None) -> Material:
    """The object's material from the `twin` config section: the configured
    kind for a retroreflective object, Lambertian for the others (the non-RR
    variants are paper and card). `calibrated` (twin_calibration.json's
    "material") overrides the lobe's width and diffuse share."""
    kind = settings.get("material", "lambertian") if retroreflective else "lambertian"
    if kind == "lambertian":
        return Material("lambertian", float(settings["object_albedo"]))
    lobe = {**settings["retroreflective"], **(calibrated or {})}
    return Material(kind, float(settings["object_albedo"]), float(lobe["lobe_width_deg"]), float(lobe["diffuse_share"]))


@dataclass(frozen=True)
class TwinScene:
    """One object at one size in the calibrated scene; everything a renderer needs.

    relays: the films' wall patches (one per zone, row-major, or the whole
    wall); film: pixels per side of each; sensor: (3,) the sensor and laser
    origin; spot: (3,) where the sensor's axis meets the wall (the laser
    spot); flood: the flood illumination, None for the spot alone; mesh: the object's full
    mesh (local); vertices/faces: its wall-facing face (local); poses:
    {location: object pose}; material: the object's; time_axis: the bins
    the renderers draw into (config `sensor.time_axis`); time_offset_opl: m
    of optical path added to every path (the captures' time zero against
    the design's); tables: table tops (empty without table)."""

    relays: tuple[Rect, ...]
    film: int
    sensor: np.ndarray
    spot: np.ndarray
    mesh: trimesh.Trimesh
    vertices: np.ndarray
    faces: np.ndarray
    poses: dict[int, Pose]
    wall_albedo: float
    material: Material
    time_axis: TimeAxis
    time_offset_opl: float = 0.0
    tables: tuple[Rect, ...] = ()
    table_albedo: float = 0.0
    flood: Flood | None = None

    @property
    def object_albedo(self) -> float:
        return self.material.albedo


def film_of(twin: dict, n: int) -> int:
    """Pixels per side of each zone's film for an n x n grid: `twin.footprint.film`
    for a 3x3 zone, the same pixel pitch for others (a zone's side scales as 1/n)."""
    return max(1, int(round(twin["footprint"]["film"] * 3 / n)))


def twin_scene(
    cal: Calibration,
    mesh: trimesh.Trimesh,
    twin: dict,
    axis: TimeAxis,
    n: int = 3,
    zones: ZoneGeometry | None = None,
    relays: tuple[Rect, ...] | None = None,
    film: int | None = None,
    material: Material | None = None,
    time_offset_opl: float = 0.0,
    emission: Emission | None = None,
) -> TwinScene:
    """The twin of one object mesh from the calibration and the config's
    `twin` section (footprint, albedos, material, table, illumination),
    rendered on `axis`, with one film per zone of the n x n grid
    (`zone_footprints` of `zones`, the design FoV scaled by
    `footprint.scale` when None). `relays`/`film` override the
    patches and their film (the benchmark's whole-wall film); `material`
    the configured one (`material_of`); `emission` the flood's configured
    one (`emission_of`). No illumination set: the paper's spot."""
    illumination = twin.get("illumination", "spot")
    check_illumination(illumination)
    lit = None
    if illumination == "flood":
        lit = flood(cal, emission or emission_of(twin), twin["flood"]["grid"])
    vertices, faces = front_face(mesh)
    if relays is None:
        relays = tuple(zone_footprints(cal, n, zones or ZoneGeometry.nominal(n, twin["footprint"]["scale"])))
    return TwinScene(
        relays=tuple(relays),
        film=int(film if film is not None else film_of(twin, n)),
        sensor=cal.sensor_position,
        spot=laser_spot(cal),
        mesh=mesh,
        vertices=vertices,
        faces=faces,
        poses=cal.object_poses,
        wall_albedo=float(twin["wall_albedo"]),
        material=material or material_of(twin),
        time_axis=axis,
        time_offset_opl=float(time_offset_opl),
        tables=cal.tables if twin["table"] else (),
        table_albedo=float(twin["table_albedo"]),
        flood=lit,
    )


def nominal_scene(locations) -> dict:
    """A scene.json document (the parts `load_calibration` reads) from the
    rig's design geometry in `denali_pipe.core.geometry`, for gantry `locations`:
    what a perfect calibration would give. For tests and benchmarks that run
    without the pose stage."""
    from denali_pipe.poses.calibrate import sensor_mount

    def rect(r: Rect) -> dict:
        return {"centre": r.centre.tolist(), "u": r.u.tolist(), "v": r.v.tolist(), "size": list(r.size)}

    cam = geo.TRACKING_CAMERA
    sensor = geo.STATIC_TAGS[geo.SENSOR_TAG_ID] @ sensor_mount()
    return {
        "wall": rect(geo.WALL),
        "table": {"rectangles": {str(k): rect(r) for k, r in geo.TABLES.items()}},
        "sensor": {"pose": sensor.to_dict(), "position": sensor.t.tolist()},
        "tracking_camera": {"intrinsics": cam.intrinsics.to_dict(), "R_world_to_camera": cam.R_wc.tolist(), "t_world_to_camera": cam.t_wc.tolist()},
        "tags": {str(k): {"position": p.t.tolist(), "rotation": p.R.tolist()} for k, p in geo.STATIC_TAGS.items()},
        "locations": {str(int(k)): {"object": geo.object_pose(int(k)).to_dict(), "tag1": geo.tag1_pose(int(k)).to_dict()} for k in locations},
    }


def perturbed_scene(locations, seed: int, shift_m: float = 0.02, turn_deg: float = 3.0) -> dict:
    """`nominal_scene` moved off the design drawing, as a measured scene is:
    the sensor, and each location's object, shifted by up to `shift_m` along
    each axis and turned by up to `turn_deg` about a random axis through
    its origin, drawn from `seed`. For the calibration's recovery tests and
    its coverage script: a scene the twin was not designed on."""
    from scipy.spatial.transform import Rotation

    doc = nominal_scene(locations)
    rng = np.random.default_rng(seed)

    def move(p: dict) -> dict:
        axis = rng.normal(size=3)
        turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.deg2rad(rng.uniform(-turn_deg, turn_deg))).as_matrix()
        return {"R": (turn @ np.asarray(p["R"])).tolist(), "t": (np.asarray(p["t"]) + rng.uniform(-shift_m, shift_m, 3)).tolist()}

    doc["sensor"]["pose"] = move(doc["sensor"]["pose"])
    doc["sensor"]["position"] = doc["sensor"]["pose"]["t"]
    for rec in doc["locations"].values():
        rec["object"] = move(rec["object"])
    return doc
