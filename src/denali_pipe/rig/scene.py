"""The hidden scene of one capture set as scatterer samples for the histogram model."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.meshes import front_samples, object_mesh, sample_spacing
from denali_pipe.core.objects import ObjectSpec
from denali_pipe.rig.histograms import Scatterer

MOUNT_SPACING = 0.02  # m; the post is diffuse and dim, so a coarse grid suffices


@lru_cache(maxsize=8)
def _object_samples(spec: ObjectSpec, size: str) -> tuple[np.ndarray, np.ndarray]:
    return front_samples(object_mesh(spec, size), sample_spacing(size))


def object_scatterer(spec: ObjectSpec, size: str, pose: geo.Pose) -> Scatterer:
    """The object's wall-facing face at `pose` (object frame -> world, e.g.
    `geometry.object_pose(location)`)."""
    points, area = _object_samples(spec, size)
    material = spec.material_params
    normal = pose.R @ np.array([0.0, 0.0, -1.0])  # local -z faces the wall
    return Scatterer(pose.apply(points), np.tile(normal, (len(points), 1)), area, material.rho_diffuse, material.rho_retro)


def mount_scatterer(mount_point: np.ndarray) -> Scatterer:
    """The front face of the mount post, from `mount_point` (3,) world (the
    object frame's origin) down to the table.
    Occlusion of the post by the object is not modelled: it is static per
    location and removed by background subtraction."""
    w, h, _ = geo.MOUNT_POST_SIZE
    xs = np.arange(-w / 2 + MOUNT_SPACING / 2, w / 2, MOUNT_SPACING)
    zs = -np.arange(MOUNT_SPACING / 2, h, MOUNT_SPACING)
    X, Z = np.meshgrid(xs, zs)
    top = np.asarray(mount_point, float)
    points = top + np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], 1)
    normals = np.tile(-geo.WALL.normal, (len(points), 1))
    area = np.full(len(points), (w / len(xs)) * MOUNT_SPACING)
    return Scatterer(points, normals, area, geo.MOUNT_POST_ALBEDO, 0.0)


def design_scene(spec: ObjectSpec, size: str, location: int) -> list[Scatterer]:
    """The mount and the object at gantry `location`'s design pose, no
    nuisances (benchmarks and physics tests); the mount alone, element 0,
    is that location's background."""
    pose = geo.object_pose(location)
    return [mount_scatterer(pose.t), object_scatterer(spec, size, pose)]
