"""The fitted sensor on scenes it was not fitted to: real captures of a mesh
on a table, rendered from their poses and compared zone by zone.

The render is direct view, one bounce: each zone's field (sensor.zones) is
cast as rays from the capture's pose into the scene's mesh (Mitsuba's ray
tracer). A ray that meets a Lambertian surface at range r, at incidence
cos i, within solid angle w, returns rho k_z(r) cos i / r^2 w detections per
cycle at the position zero_bin + offset_z + s_z r (bins), spread by the
fitted pulse. Interreflections are left out: the scenes' concave corners
(object on table) hold a few per cent of their light at most.

Everything about the sensor comes from its fit to the distance sweep
(sensor.fit) and nothing is refitted here:

- k_z(d), each zone's gain at distance d: the sweep's returns A_z(d) over
  what the same rays give for the plane (sensor.zones.plane_view), smoothed
  as a quadratic in d of its log and held at its ends beyond the sweep. It
  carries the beam, the receiver's vignetting and the emitter-receiver
  overlap, whatever their shares.
- s_z, bins per metre of range: the zone's bins per metre of plane
  distance over its mean range per unit distance (plane_view).
- the pulse, the pile-up's cycles and each zone's crosstalk.

What the scene leaves free is the scene's: the object's and the table's
albedos (relative to the sweep's plane; one each per scene, shared by
every capture and zone) and each capture's and zone's floor (the room's
light). The comparison is in counts, net of each capture's shot noise
(sensor.fit.scores), and says where the residual lies.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import nnls

from denali_pipe.sensor.captures import BINS, ZONES, Captures
from denali_pipe.sensor.fit import TAIL, SensorFit, grid_minimum, scores
from denali_pipe.sensor.response import counts_from_rates, pulse_at, rates_from_counts
from denali_pipe.sensor.zones import plane_view, zone_rays

BIN = np.arange(BINS)
# The window about each zone's measured peak (bins) that the residual is split into, beside the fit's TAIL; the floor is the rest.
PEAK = (-3, 4)
# Rays per side of each zone's field: 24^2 = 576 a zone puts a 5 cm object's edge within a ray of 0.4 deg.
RAYS_PER_SIDE = 24
# Each ray's return is placed on a grid of 1/FINE bin before the pulse spreads it.
FINE = 8
# How the scene is fitted: `render`, the rendered returns scaled by the object's and the table's
# albedos (the render's test); `free`, each capture's and zone's object and table returns free in
# size (the sensor's pulse, timing and pile-up alone, as the sweep's held-out captures are scored).
MODES = ("render", "free")
SHIFT_GRID = np.linspace(-1.5, 1.5, 31)  # bins: each capture's time shift searched
ROUNDS = 2  # alternations of the albedos (or amplitudes) and the shifts


@dataclass(frozen=True)
class Mesh:
    """vertices (V, 3) m, faces (F, 3), table (F,) bool: the face is the table's."""

    vertices: np.ndarray
    faces: np.ndarray
    table: np.ndarray


def read_mesh(path: Path) -> Mesh:
    """A scene's mesh (STL, z up): the table is every face that rises no
    higher than the mesh's largest upward face (the table's top, which may
    be cut around the object's footprint), the object the rest. ValueError
    naming the file when it is not a readable mesh with faces above its table."""
    import trimesh

    try:
        mesh = trimesh.load_mesh(Path(path))
    except Exception as e:  # noqa: BLE001 -- trimesh raises many kinds for a bad file
        raise ValueError(f"{path}: not a readable mesh ({e})") from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
    if len(faces) == 0:
        raise ValueError(f"{path}: no triangle faces")
    up = np.flatnonzero(mesh.face_normals[:, 2] > 0.99)
    if len(up) == 0:
        raise ValueError(f"{path}: no upward face for a table top")
    top = mesh.vertices[faces[up[np.argmax(mesh.area_faces[up])]], 2].max()
    table = mesh.vertices[faces, 2].max(axis=1) <= top + 1e-4
    if table.all():
        raise ValueError(f"{path}: every face is at or below the table's top (z = {top:.4f} m): no object")
    return Mesh(np.asarray(mesh.vertices, float), faces, table)


def cast(mesh: Mesh, origins: np.ndarray, dirs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(range (M,) m, cos incidence (M,), face (M,), -1 where the ray meets
    nothing) of rays from origins (M, 3) along unit dirs (M, 3)."""
    from denali_pipe.twin.scene import diffuse, triangle_mesh
    from denali_pipe.twin.variant import load_mitsuba

    mi = load_mitsuba()
    scene = mi.load_dict({"type": "scene", "mesh": triangle_mesh(mi, "mesh", mesh.vertices, mesh.faces, diffuse(0.5))})
    o, d = np.asarray(origins, np.float32), np.asarray(dirs, np.float32)
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o.T), mi.Vector3f(*d.T)))
    hit = np.array(si.is_valid(), bool)
    n = np.stack([np.array(c) for c in (si.n.x, si.n.y, si.n.z)], axis=-1)
    cos = np.abs((n * d).sum(-1))
    return np.where(hit, np.array(si.t), np.inf), np.where(hit, cos, 0.0), np.where(hit, np.array(si.prim_index, np.int64), -1)


def zone_gain(fit: SensorFit, geometric: np.ndarray) -> np.ndarray:
    """(3, ZONES) the coefficients of log k_z(d) as a quadratic in d (highest
    first): the sweep's returns A_z(d) d^2 over the plane's geometric return
    (ZONES,) at unit distance (module docstring)."""
    d = fit.train_distances
    log_k = np.log(fit.amplitude * d[:, None] ** 2 / geometric[None, :])
    return np.polyfit(d, log_k, 2)


def ray_returns(fit: SensorFit, mesh: Mesh, captures: Captures, per_side: int = RAYS_PER_SIDE) -> np.ndarray:
    """(N, ZONES, 2, BINS * FINE) detections per cycle of each capture's
    zones from the object (index 0) and the table (1) at unit albedo, before
    the pulse: each ray's return deposited at its position (module
    docstring) on a grid of 1/FINE bin, shared linearly between the two
    nearest grid points."""
    dirs, omega = zone_rays(per_side)
    geometric, mean_range = plane_view(per_side)
    gain = zone_gain(fit, geometric)
    slope = fit.timing.bins_per_metre / mean_range
    lo, hi = fit.train_distances.min(), fit.train_distances.max()
    n, rays = len(captures.pose), dirs.shape[1]
    origins = np.repeat(captures.pose[:, :3, 3], ZONES * rays, axis=0)
    world = np.einsum("nij,zrj->nzri", captures.pose[:, :3, :3], dirs).reshape(-1, 3)
    r, cos, face = (a.reshape(n, ZONES, rays) for a in cast(mesh, origins, world))
    hit = face >= 0
    zone = np.arange(ZONES)[None, :, None]
    k = np.exp(sum(c[zone] * np.clip(r, lo, hi) ** (2 - i) for i, c in enumerate(gain)))
    weight = np.where(hit, k * cos / np.where(hit, r, 1.0) ** 2 * omega[None], 0.0)
    x = (fit.timing.zero_bin + fit.timing.offsets[zone] + slope[zone] * np.where(hit, r, 0.0)) * FINE
    i = np.clip(np.floor(x).astype(int), 0, BINS * FINE - 2)
    f = np.clip(x - i, 0.0, 1.0)
    part = np.where(hit, mesh.table[np.maximum(face, 0)].astype(int), 0)
    out = np.zeros((n, ZONES, 2, BINS * FINE))
    cell = (np.arange(n)[:, None, None] * ZONES + zone) * 2 + part
    flat = out.reshape(-1, BINS * FINE)
    np.add.at(flat, (cell, i), weight * (1 - f))
    np.add.at(flat, (cell, i + 1), weight * f)
    return out


def through_pulse(fit: SensorFit, fine: np.ndarray, shift: float) -> np.ndarray:
    """(..., BINS) the deposited returns fine (..., BINS * FINE) spread by the
    pulse, every position moved by `shift` bins."""
    x = np.arange(BINS * FINE) / FINE + shift
    return fine @ pulse_at(fit.pulse, BIN[None, :] - x[:, None])


def crosstalk_rates(fit: SensorFit) -> np.ndarray:
    """(ZONES, BINS) each zone's cover-glass return, detections per cycle."""
    zero = fit.timing.zero_bin + fit.timing.offsets
    return fit.crosstalk[:, None] * pulse_at(fit.pulse, BIN[None, :] - zero[:, None])


def _albedos(y: np.ndarray, w: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """(2,) the object's and the table's albedos: non-negative weighted least
    squares over every capture and zone, each one's floor profiled out."""

    def centred(a):  # less its weighted mean over the bins: the floor's share
        return a - (w * a).sum(-1, keepdims=True) / w.sum(-1, keepdims=True)

    X = np.stack([centred(unit[:, :, p]) for p in (0, 1)], axis=-1) * np.sqrt(w)[..., None]
    return nnls(X.reshape(-1, 2), (centred(y) * np.sqrt(w)).ravel())[0]


def _scene_rates(y: np.ndarray, w: np.ndarray, unit: np.ndarray, albedo: np.ndarray | None) -> np.ndarray:
    """(N, ZONES, BINS) the rates that best fit y given the unit returns
    (N, ZONES, 2, BINS): with `albedo`, its returns and each capture's and
    zone's floor (weighted mean, non-negative); without, each capture's and
    zone's own object, table and floor amplitudes (`_nonnegative`)."""
    if albedo is not None:
        scene = np.einsum("nzpb,p->nzb", unit, albedo)
        return scene + np.clip((w * (y - scene)).sum(-1, keepdims=True) / w.sum(-1, keepdims=True), 0.0, None)
    X = np.concatenate([np.moveaxis(unit, 2, -1), np.ones(y.shape + (1,))], axis=-1)
    return np.einsum("nzbi,nzi->nzb", X, _nonnegative(X, w, y))


def _nonnegative(X: np.ndarray, w: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., K) non-negative weighted least squares of y (..., B) on the
    columns X (..., B, K), K small: every subset of the columns solved at
    once, the best feasible one kept (exact, as an active-set method is)."""
    k = X.shape[-1]
    normal = np.einsum("...bi,...b,...bj->...ij", X, w, X)
    rhs = np.einsum("...bi,...b,...b->...i", X, w, y)
    best, best_cost = np.zeros(rhs.shape), np.full(rhs.shape[:-1], np.inf)
    for subset in range(1, 2**k):
        keep = np.array([(subset >> i) & 1 for i in range(k)], bool)
        sub = normal[..., keep][..., keep, :] + 1e-12 * np.eye(keep.sum())
        coef = np.zeros(rhs.shape)
        coef[..., keep] = np.linalg.solve(sub, rhs[..., keep][..., None])[..., 0]
        # the weighted cost less its constant: c' N c - 2 c' r
        cost = np.einsum("...i,...ij,...j->...", coef, normal, coef) - 2 * (coef * rhs).sum(-1)
        better = (coef >= 0).all(-1) & (cost < best_cost)
        best, best_cost = np.where(better[..., None], coef, best), np.where(better, cost, best_cost)
    return best


def fit_scene(fit: SensorFit, captures: Captures, fine: np.ndarray, mode: str) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(expected counts (N, ZONES, BINS), each capture's time shift (N,)
    bins, the albedos (2,) or None): the captures' rates fitted by the
    rendered returns `fine` (ray_returns) in one of MODES, each capture's
    shift searched as the sweep's held-out captures' are (sensor.fit)."""
    if mode not in MODES:
        raise ValueError(f"unknown mode {mode!r}; expected one of {MODES}")
    rates, sd = rates_from_counts(captures.hists, fit.cycles)
    y, w = rates - crosstalk_rates(fit)[None], 1 / sd**2
    shift, albedo = np.zeros(len(y)), None
    for _ in range(ROUNDS):
        unit = np.stack([through_pulse(fit, f, s) for f, s in zip(fine, shift)])
        albedo = _albedos(y, w, unit) if mode == "render" else None
        costs = np.stack([(w * (y - _scene_rates(y, w, u, albedo)) ** 2).sum(axis=(1, 2)) for u in (through_pulse(fit, fine, s) for s in SHIFT_GRID)], axis=1)
        shift = grid_minimum(SHIFT_GRID, costs)
    unit = np.stack([through_pulse(fit, f, s) for f, s in zip(fine, shift)])
    albedo = _albedos(y, w, unit) if mode == "render" else None
    return counts_from_rates(_scene_rates(y, w, unit, albedo) + crosstalk_rates(fit)[None], fit.cycles), shift, albedo


def residual_shares(measured: np.ndarray, expected: np.ndarray) -> dict:
    """Per zone (ZONES,), the share of the residual net of shot noise,
    sum (h - e)^2 - e, in the PEAK and TAIL windows about each capture's
    measured peak and in the rest (the floor); shares of the total, which
    may be negative where a window is within its noise."""
    peak = measured.argmax(-1)[..., None]
    offset = BIN[None, None, :] - peak
    excess = (measured - expected) ** 2 - expected
    masks = {"peak": (offset >= PEAK[0]) & (offset <= PEAK[1]), "tail": (offset >= TAIL[0]) & (offset <= TAIL[1])}
    masks["floor"] = ~(masks["peak"] | masks["tail"])
    total = excess.sum(axis=(0, 2))
    return {f"share_{name}": (excess * m).sum(axis=(0, 2)) / total for name, m in masks.items()}


def compare_scene(fit: SensorFit, captures: Captures, mesh: Mesh) -> tuple[pd.DataFrame, dict]:
    """(one row per mode and zone: the scores (sensor.fit.scores), where the
    residual lies, the captures' shifts, the albedos where fitted; each
    mode's expected counts (N, ZONES, BINS))."""
    fine = ray_returns(fit, mesh, captures)
    rows, expected = [], {}
    for mode in MODES:
        e, shift, albedo = fit_scene(fit, captures, fine, mode)
        expected[mode] = e
        a = np.full(2, np.nan) if albedo is None else albedo
        rows.append(
            pd.DataFrame({"scene": captures.name, "mode": mode, "zone": np.arange(ZONES), **scores(captures.hists, e), **residual_shares(captures.hists, e)})
            .assign(shift_mean_bins=shift.mean(), shift_sd_bins=shift.std(), albedo_object=a[0], albedo_table=a[1], n_captures=len(e))
        )  # fmt: skip
    return pd.concat(rows, ignore_index=True), expected
