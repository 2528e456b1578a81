"""Forward model of TMF8828 histograms looking at a flood-lit relay wall.

Per zone, the sensor counts photons from its own wall patch, binned by
sensor-relative optical path length (OPL):

- the direct wall return (sensor -> wall patch -> sensor);
- the three-bounce return of hidden scatterers (sensor -> wall p -> scatterer
  o -> wall q -> sensor), with a Lambertian part and, for retroreflective
  material, a retroreflective lobe. The lobe sends light back toward where it
  came from, so in the narrow-lobe limit p = q and its path is
  2 |s - q| + 2 |q - o|: an O x Q sum instead of the diffuse part's P x O x Q;
- ambient light (lights on) and dark counts, a flat floor per bin;
- an exGaussian pulse (Gaussian jitter with an exponential SPAD tail), a
  pile-up nonlinearity, Poisson shot noise and Gaussian read noise.

Radiometry is relative: the laser is a point source of unit intensity over the
field of view, so every transport term is in the same (arbitrary) unit, and one
gain, calibrated on the direct-return peak of the centre 3x3 zone, turns it
into counts. Counts scale with the firmware's iterations and, for the flat
floor, with each zone's solid angle, so 8x8 zones carry far fewer photons.
Nothing here knows object labels: signal depends on shape, size, material and
location only through the scatterer points handed in.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from denali_pipe import geometry as geo

# Wall sub-samples per zone side: enough that the OPL spread inside one sample
# cell stays well below the pulse width (~6 bins).
WALL_SAMPLES_PER_ZONE = {3: 4, 8: 2}
# Laser-spot samples over the whole field of view for the diffuse three-bounce
# term (smooth in p, so a coarse grid suffices).
LASER_SAMPLES = 4


@dataclass(frozen=True)
class Photometry:
    """Sensor response, stated for one 3x3 zone at the 3x3 firmware's
    iterations (counts per bin unless noted)."""

    direct_peak_counts: float
    dark_counts: float
    ambient_counts: float
    pulse_sigma_bins: float
    pulse_tail_bins: float
    saturation_counts: float
    read_noise_counts: float

    @classmethod
    def from_config(cls, d: dict) -> "Photometry":
        return cls(**{k: float(d[k]) for k in cls.__dataclass_fields__})


@dataclass(frozen=True)
class Scatterer:
    """Hidden surface samples. points, normals (N, 3) world (normals face the
    wall side); area (N,) m^2; albedos of the Lambertian and retroreflective parts."""

    points: np.ndarray
    normals: np.ndarray
    area: np.ndarray
    rho_diffuse: float
    rho_retro: float


@dataclass(frozen=True)
class WallSamples:
    """Wall points seen through each zone. Arrays (Z, S, ...) with Z = n*n zones."""

    q: np.ndarray  # (Z, S, 3) wall points
    r: np.ndarray  # (Z, S) sensor -> q distance, m
    omega: np.ndarray  # (Z, S) solid angle of the sample's ray cell, sr
    irradiance: np.ndarray  # (Z, S) laser irradiance at q for unit intensity, 1/m^2
    zone_omega: np.ndarray  # (Z,) solid angle of each zone, sr


def _wall_samples(n: int, s: int) -> WallSamples:
    dirs, omega = geo.zone_directions(n, s)
    z = n * n
    dirs, omega = dirs.reshape(z, s * s, 3), omega.reshape(z, s * s)
    q = geo.intersect_plane(geo.SENSOR_POSITION, dirs, geo.WALL)
    r = np.linalg.norm(q - geo.SENSOR_POSITION, axis=-1)
    cos_q = -(dirs @ geo.WALL.normal)
    return WallSamples(q, r, omega, cos_q / r**2, omega.sum(1))


@lru_cache(maxsize=None)
def wall_samples(resolution: str) -> WallSamples:
    n = geo.RESOLUTIONS[resolution]
    return _wall_samples(n, WALL_SAMPLES_PER_ZONE[n])


@lru_cache(maxsize=None)
def laser_samples() -> WallSamples:
    """The flood-lit wall as one coarse grid (a single 'zone')."""
    return _wall_samples(1, LASER_SAMPLES)


def _splat(hist: np.ndarray, zone: np.ndarray, opl: np.ndarray, weight: np.ndarray) -> None:
    """Add `weight` at fractional bins of `opl` (linear interpolation) into hist (Z, B).
    Paths outside the time window land in padding columns that are dropped."""
    nz, nb = hist.shape
    width = nb + 3
    b = geo.opl_to_bin(opl) - 0.5  # bin centres sit at integer + 0.5
    lo = np.floor(b)
    f = b - lo
    idx = zone * width + (np.clip(lo, -1, nb) + 1).astype(np.int64)
    flat = np.bincount(np.concatenate([idx, idx + 1]), np.concatenate([weight * (1 - f), weight * f]), nz * width)
    hist += flat.reshape(nz, width)[:, 1 : nb + 1]


def transport(resolution: str, scatterers: list[Scatterer]) -> np.ndarray:
    """Noise-free, pulse-free light transport (Z, N_BINS) in relative units:
    the direct wall return plus every scatterer's three-bounce return."""
    ws = wall_samples(resolution)
    nz, ns = ws.r.shape
    rho_w = geo.WALL_ALBEDO
    hist = np.zeros((nz, geo.N_BINS))
    zone = np.repeat(np.arange(nz), ns)
    q, r_q = ws.q.reshape(-1, 3), ws.r.reshape(-1)
    # radiance of q toward the sensor per unit irradiance, times the ray cell's solid angle
    seen = (rho_w / np.pi) * ws.omega.reshape(-1)
    _splat(hist, zone, 2 * r_q, seen * ws.irradiance.reshape(-1))

    nw = geo.WALL.normal
    for sc in scatterers:
        d_oq = q[None, :, :] - sc.points[:, None, :]  # (O, Q, 3)
        dist = np.linalg.norm(d_oq, axis=-1)
        cos_o = np.einsum("oqk,ok->oq", d_oq, sc.normals) / dist
        cos_q = -(d_oq @ nw) / dist
        # geometry term o -> q times the area of o; back faces contribute nothing
        g_oq = np.clip(cos_o, 0, None) * np.clip(cos_q, 0, None) / dist**2 * sc.area[:, None]
        if sc.rho_retro > 0:
            radiance_in = (rho_w / np.pi) * ws.irradiance.reshape(-1)  # L(q -> o)
            w = sc.rho_retro * radiance_in[None, :] * g_oq * seen[None, :]
            _splat(hist, np.broadcast_to(zone, w.shape).ravel(), (2 * r_q + 2 * dist).ravel(), w.ravel())
        if sc.rho_diffuse > 0:
            _add_diffuse(hist, zone, r_q, seen, g_oq, dist, sc)
    return hist


def _add_diffuse(hist, zone, r_q, seen, g_oq, d_oq, sc: Scatterer) -> None:
    """Lambertian scatterer lit by the whole flood-lit wall: sum over laser spots p."""
    ls = laser_samples()
    p, r_p = ls.q.reshape(-1, 3), ls.r.reshape(-1)
    d_po = sc.points[None, :, :] - p[:, None, :]  # (P, O, 3)
    dist_po = np.linalg.norm(d_po, axis=-1)
    cos_p = (d_po @ geo.WALL.normal) / dist_po
    cos_o = -np.einsum("pok,ok->po", d_po, sc.normals) / dist_po
    # L(p -> o) cos_p a_p / |p - o|^2 with a_p = omega_p r_p^2 / cos_p, L = rho_w/pi E_L(p)
    e_o = (geo.WALL_ALBEDO / np.pi) * ls.omega.reshape(-1)[:, None] * np.clip(cos_p, 0, None)
    e_o = e_o * np.clip(cos_o, 0, None) / dist_po**2  # (P, O) irradiance at o from each p
    radiance_o = (sc.rho_diffuse / np.pi) * e_o
    w_oq = g_oq * seen[None, :]  # (O, Q)
    zones = np.broadcast_to(zone, w_oq.shape).ravel()
    base_opl = (d_oq + r_q[None, :]).ravel()
    o_index = np.repeat(np.arange(len(sc.points)), len(r_q))
    for ip in range(len(p)):
        opl = base_opl + (r_p[ip] + dist_po[ip])[o_index]
        _splat(hist, zones, opl, (radiance_o[ip][:, None] * w_oq).ravel())


@lru_cache(maxsize=None)
def pulse_matrix(sigma_bins: float, tail_bins: float) -> np.ndarray:
    """(N_BINS, N_BINS) matrix M with hist @ M = hist convolved with the
    unit-area exGaussian pulse (delay 0 at the Gaussian's centre)."""
    t = np.arange(-geo.N_BINS + 1, geo.N_BINS, dtype=float)
    x = t[:, None] + np.linspace(-0.5, 0.5, 11)[None, :]  # integrate over each bin
    delay = np.arange(0, 12 * tail_bins, 0.1)  # exponential tail, numerically convolved
    shape = np.exp(-0.5 * ((x[..., None] - delay) / sigma_bins) ** 2) @ np.exp(-delay / tail_bins)
    shape = shape.mean(-1)
    shape = shape / shape.sum()
    i = np.arange(geo.N_BINS)
    return shape[(i[None, :] - i[:, None]) + geo.N_BINS - 1]


def _gain(phot: Photometry) -> float:
    """Counts per unit transport so that the centre 3x3 zone's direct peak is
    `direct_peak_counts` above the floor."""
    return phot.direct_peak_counts / _direct_peak(phot.pulse_sigma_bins, phot.pulse_tail_bins)


@lru_cache(maxsize=None)
def _direct_peak(sigma: float, tail: float) -> float:
    h = transport(geo.REFERENCE_RESOLUTION, []) @ pulse_matrix(sigma, tail)
    return float(h[len(h) // 2].max())


def expected_counts(resolution: str, light_on: bool, scatterers: list[Scatterer], phot: Photometry) -> np.ndarray:
    """Expected counts (n, n, N_BINS) float64, before noise."""
    return counts_from_transport(resolution, light_on, transport(resolution, scatterers), phot)


def counts_from_transport(resolution: str, light_on: bool, light: np.ndarray, phot: Photometry) -> np.ndarray:
    """Expected counts (n, n, N_BINS) from a `transport` result (Z, N_BINS):
    pulse, gain, floor and pile-up. Lightings share one transport."""
    n = geo.RESOLUTIONS[resolution]
    fw, ref = geo.FIRMWARE[resolution], geo.FIRMWARE[geo.REFERENCE_RESOLUTION]
    iters = fw.kilo_iterations / ref.kilo_iterations
    ref_zone = wall_samples(geo.REFERENCE_RESOLUTION).zone_omega.mean()
    floor_per_zone = wall_samples(resolution).zone_omega / ref_zone
    signal = light @ pulse_matrix(phot.pulse_sigma_bins, phot.pulse_tail_bins)
    floor = phot.dark_counts + (phot.ambient_counts if light_on else 0.0)
    x = iters * (_gain(phot) * signal + floor * floor_per_zone[:, None])
    # pile-up: a SPAD registers at most one photon per pulse, so the counts saturate
    sat = iters * phot.saturation_counts
    return (sat * -np.expm1(-x / sat)).reshape(n, n, geo.N_BINS)


def sample_counts(expected: np.ndarray, phot: Photometry, rng: np.random.Generator) -> np.ndarray:
    """One noisy histogram like `expected`: Poisson shot noise plus Gaussian read noise, int32 >= 0."""
    noisy = rng.poisson(expected) + rng.normal(0.0, phot.read_noise_counts, expected.shape)
    return np.clip(np.rint(noisy), 0, None).astype(np.int32)
