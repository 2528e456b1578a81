"""What each of the TMF8820's 3x3 zones sees: its field of view, as rays.

The sensor looks along +z of its own frame. A direction is two angles
(radians), x_rot about the frame's y axis and then y_rot about its x axis:
d = (sin x, cos x sin y, cos x cos y). Each zone is a rectangle of these
angles, three columns (x_rot) by three rows (y_rot), zone 0 at +x +y and
zone z in column z // 3 and row z % 3, as the ProximityPlanarRecovery
code (uwgraphics, MIT; its zone_spec.json) defines them for the same
firmware that took the real captures (docs/sensor.md): the outer columns
12.0 deg wide, the centre 9.6 deg, every row 11.1 deg, 33.6 x 33.2 deg in all.
"""

from __future__ import annotations

import numpy as np

from denali_pipe.sensor.captures import ZONES

# Radians: the columns' centres and widths (zone z in column z // 3), the rows' (row z % 3).
COLUMN_CENTRES = np.array([0.18844, 0.0, -0.18844])
COLUMN_WIDTHS = np.array([0.20923, 0.16761, 0.20923])
ROW_CENTRES = np.array([0.19339, 0.0, -0.19339])
ROW_HEIGHT = 0.19339


def direction(x_rot: np.ndarray, y_rot: np.ndarray) -> np.ndarray:
    """(..., 3) unit directions in the sensor's frame of angles x_rot, y_rot (radians, the module's convention)."""
    x, y = np.asarray(x_rot, float), np.asarray(y_rot, float)
    return np.stack([np.sin(x), np.cos(x) * np.sin(y), np.cos(x) * np.cos(y)], axis=-1)


def zone_rays(per_side: int) -> tuple[np.ndarray, np.ndarray]:
    """(directions (ZONES, per_side^2, 3) in the sensor's frame, solid angles
    (ZONES, per_side^2) sr): each zone's field sampled on a per_side x
    per_side grid of angle cells, each ray at its cell's centre with the
    cell's solid angle (cos x_rot dx dy: the angles' Jacobian)."""
    cell = (np.arange(per_side) + 0.5) / per_side - 0.5
    dirs, omega = [], []
    for z in range(ZONES):
        col, row = divmod(z, 3)
        x = COLUMN_CENTRES[col] + COLUMN_WIDTHS[col] * cell
        y = ROW_CENTRES[row] + ROW_HEIGHT * cell
        gx, gy = np.meshgrid(x, y, indexing="ij")
        dirs.append(direction(gx, gy).reshape(-1, 3))
        omega.append((np.cos(gx) * COLUMN_WIDTHS[col] * ROW_HEIGHT / per_side**2).ravel())
    return np.stack(dirs), np.stack(omega)


def plane_view(per_side: int) -> tuple[np.ndarray, np.ndarray]:
    """How each zone sees a Lambertian plane square to the sensor's axis at
    unit distance: (geometric return (ZONES,), sum of cos^3 d_omega: a
    ray's cos/r^2 irradiance times its cos incidence, r = 1/cos; mean
    range (ZONES,), return-weighted, in units of the plane's distance)."""
    dirs, omega = zone_rays(per_side)
    c = dirs[..., 2]
    w = c**3 * omega
    return w.sum(-1), (w / c).sum(-1) / w.sum(-1)
