"""What the tracking camera sees: static tags, table tops, the visual wall and
the object tag at every gantry location, from our design drawing or from a
release's measured poses (config `rig.scene_poses`).

- `design_scene()`: `geometry`'s nominal layout (STATIC_TAGS, TABLES, WALL,
  the regular gantry grid), the default.
- `release_scene(path)`: a release `poses.json` (docs/deviations.md):
  `tracking_avgposes` gives every static tag's averaged centre and rotation
  (tag -> world, world origin tag 14), `tracking_tag1_index_avgposes` tag 1's
  per gantry location. Tables and wall follow their tags: each table top is
  the plane through its tags (10/12/14 and 11/13/15) with their mean normal,
  so its height and tilt are the release's; the visual wall is the wall
  tags' plane 1 mm behind them (as in the reference twin). Their extents are
  the design's, carried by the tags' mean offset from the design.

The tracking frames, rig_truth.json and the histograms' hidden object (mounted
on tag 1 of this scene, `rig.nuisances`) use this scene. The histograms'
relay wall stays `geometry.WALL` (the NLOS wall's normal forced to -y, as the
reference twin does).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.geometry import Pose, Rect

DESIGN = "design"
WALL_GAP_M = 0.001  # the visual wall lies this far behind its tags
ROTATION_TOL = 1e-3  # |R^T R - I| allowed in poses.json before re-orthonormalising


@dataclass(frozen=True)
class TrackedScene:
    """The tracked scene in the world frame (metres; poses map tag -> world).

    source: "design" or the poses.json path; static_tags: tag id -> Pose;
    tables: table id -> Rect (the top, facing up); wall: the visual wall Rect
    behind the wall tags (facing the room); tag1: gantry location -> Pose of
    tag 1 before the gantry's per-set offset."""

    source: str
    static_tags: dict[int, Pose]
    tables: dict[int, Rect]
    wall: Rect
    tag1: dict[int, Pose]

    def tag1_pose(self, location: int) -> Pose:
        if int(location) not in self.tag1:
            raise ValueError(f"scene {self.source}: no tag-1 pose for gantry location {location}")
        return self.tag1[int(location)]

    def surfaces_key(self) -> bytes:
        """Bytes identifying the background surfaces (tables and wall): the frame renderer's cache key."""
        rects = [*self.tables.values(), self.wall]
        return b"".join(np.concatenate([r.centre, r.u, r.v, r.size]).tobytes() for r in rects)

    def to_dict(self) -> dict:
        """JSON-ready record of the scene's source and surfaces (rig_truth.json's
        `scene`; the truth records the tags beside it, tag 1 per location)."""

        def rect(r: Rect) -> dict:
            return {"centre": r.centre.tolist(), "u": r.u.tolist(), "v": r.v.tolist(), "size": list(r.size), "normal": r.normal.tolist()}

        return {
            "source": self.source,
            "tables": {str(i): rect(r) for i, r in sorted(self.tables.items())},
            "wall": rect(self.wall),
        }


@lru_cache(maxsize=1)
def design_scene() -> TrackedScene:
    """Our design drawing (`geometry`)."""
    return TrackedScene(
        DESIGN,
        dict(geo.STATIC_TAGS),
        dict(geo.TABLES),
        geo.WALL,
        {k: geo.tag1_pose(k) for k in range(geo.N_LOCATIONS)},
    )


def _rotation(path: Path, where: str, m) -> np.ndarray:
    R = np.asarray(m, float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"{path}: {where}: rotation_matrix must be a finite 3x3 matrix, got {m!r}")
    if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOL or np.linalg.det(R) <= 0:
        raise ValueError(f"{path}: {where}: rotation_matrix is not a rotation (|R^T R - I| > {ROTATION_TOL} or det <= 0)")
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def _pose(path: Path, where: str, rec) -> Pose:
    if not isinstance(rec, dict) or "center" not in rec or "rotation_matrix" not in rec:
        raise ValueError(f"{path}: {where} needs 'center' and 'rotation_matrix'")
    t = np.asarray(rec["center"], float)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"{path}: {where}: center must be 3 finite numbers, got {rec['center']!r}")
    return Pose(_rotation(path, where, rec["rotation_matrix"]), t)


def _wall(tags: dict[int, Pose]) -> Rect:
    ids = geo.WALL_TAG_IDS
    facing = np.mean([-tags[i].R[:, 2] for i in ids], axis=0)  # tag z points into the wall
    facing /= np.linalg.norm(facing)
    behind = np.mean([tags[i].t for i in ids], axis=0) - WALL_GAP_M * facing
    shift = np.mean([tags[i].t - geo.STATIC_TAGS[i].t for i in ids], axis=0)
    return geo.rect_on_plane(geo.WALL, behind, facing, shift)


def release_scene(path: str | Path) -> TrackedScene:
    """The scene of a release `poses.json` (see the module docstring). Raises
    ValueError naming the file and what is missing or malformed."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: rig.scene_poses names a poses.json that does not exist") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON ({e})") from None
    static, moving = doc.get("tracking_avgposes"), doc.get("tracking_tag1_index_avgposes")
    if not isinstance(static, dict) or not isinstance(moving, dict):
        raise ValueError(f"{path}: a poses.json needs 'tracking_avgposes' and 'tracking_tag1_index_avgposes' objects")
    missing = [i for i in geo.STATIC_TAGS if str(i) not in static]
    if missing:
        raise ValueError(f"{path}: tracking_avgposes lacks static tag(s) {missing}")
    gaps = [k for k in range(geo.N_LOCATIONS) if str(k) not in moving]
    if gaps:
        raise ValueError(f"{path}: tracking_tag1_index_avgposes lacks gantry location(s) {gaps}")
    tags = {i: _pose(path, f"tracking_avgposes[{i}]", static[str(i)]) for i in geo.STATIC_TAGS}
    tag1 = {k: _pose(path, f"tracking_tag1_index_avgposes[{k}]", moving[str(k)]) for k in range(geo.N_LOCATIONS)}
    tables = {t: geo.table_from_tags(t, tags) for t in geo.TABLE_TAGS}
    return TrackedScene(str(path), tags, tables, _wall(tags), tag1)


def tracked_scene(scene_poses: str | Path | None) -> TrackedScene:
    """The scene `rig.scene_poses` selects: None = the design drawing, else a poses.json path."""
    return design_scene() if scene_poses is None else release_scene(str(scene_poses))
