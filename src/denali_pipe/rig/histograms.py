"""Forward model of TMF8828 histograms looking at a flood-lit relay wall.

Per zone, the sensor counts photons from its own wall patch, binned by
sensor-relative optical path length (OPL):

- the direct wall return (sensor -> wall patch -> sensor);
- the three-bounce return of hidden scatterers (sensor -> wall p -> scatterer
  o -> wall q -> sensor), with a Lambertian part and, for retroreflective
  material, a retroreflective lobe. The lobe sends light back toward where it
  came from, so in the narrow-lobe limit p = q and its path is
  2 |s - q| + 2 |q - o|: an O x Q sum instead of the diffuse part's P x O x Q;
- ambient light (lights on) and dark counts, a floor per bin. Room light
  reaches each wall patch from the whole room; hidden scatterers block the
  share of it they subtend (`Transport.ambient`), so with lights on the
  floor of the zones near the object carries its silhouette;
- the instrument response: a pulse (Gaussian jitter, a fast exponential SPAD
  tail and a slow tail of carrier diffusion and laser afterglow), then the
  response nonlinearity of a zone (`respond`): SPAD dead time, which lowers
  every bin after a strong return, and the saturation of the zone's pulse
  combiner, which flattens the direct peak; Poisson shot noise and Gaussian
  read noise.

Radiometry is relative: the laser is a point source whose intensity is 1 on
its beam axis and falls off over the field as the VCSEL's emission profile
(`Photometry.emission`); each ray a zone collects is weighted by the
receiver's response (`Photometry.response`: the lens's relative
illumination, the same for every zone's SPAD group). Every transport
term is in the same (arbitrary) unit, and one gain, calibrated on the
direct-return peak of the centre 3x3 zone, turns it into counts. Counts scale
with the firmware's iterations and, for the floor, with each zone's SPADs
(dark counts) or its response-weighted solid angle (room light), so 8x8
zones carry far fewer photons.
Nothing here knows object labels: signal depends on shape, size, material and
location only through the scatterer points handed in.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core import pulse
from denali_pipe.core.glare import glare

# Wall sub-samples per zone side: enough that the OPL spread inside one sample
# cell (largest in the zones that see the wall obliquely, ~3 bins) stays near
# the pulse width (~2 bins FWHM), so their direct returns show no steps.
WALL_SAMPLES_PER_ZONE = {3: 6, 8: 2}
# Laser-spot samples over the whole field of view for the diffuse three-bounce
# term (smooth in p, so a coarse grid suffices).
LASER_SAMPLES = 4
# The flood's power over the field is integrated on a finer grid: a flood
# with near-rectangular contours (beam_contour >> 2) has edges that the
# spots' midpoint grid over-integrates (by 10 % at 12.7; 16 per side is
# within 0.1 % of 128 at exponents 2-15).
FLOOD_POWER_SAMPLES = 16


@dataclass(frozen=True)
class Photometry:
    """Sensor response, counts stated for the centre 3x3 zone at the 3x3
    firmware's iterations (counts per bin unless noted; `config/config.yaml`
    gives the basis of each value).

    direct_peak_counts: the centre zone's direct-return peak above the floor
        before the response nonlinearity (the photon flux; sets the gain).
    dark_counts, ambient_counts: the centre zone's floor per bin, lights off
        and the extra with lights on, before the nonlinearity.
    pulse_sigma_bins, pulse_tail_bins: Gaussian jitter and fast SPAD tail.
    slow_tail_bins, slow_tail_fraction: time constant and energy share of the
        slow tail (carrier diffusion, laser afterglow).
    saturation_counts: counts per bin at which the zone's pulse combiner
        saturates (s in s (1 - exp(-x / s))).
    dead_time_counts: counts after which a zone's later bins keep 1/e of
        their photons (its SPADs fire once per laser cycle: SPADs per zone
        x cycles, in the firmware's count units).
    read_noise_counts: Gaussian read noise on top of Poisson shot noise.
    beam_hwhm_deg, beam_order, beam_contour: the flood the VCSEL's microlens
        array spreads, a super-Gaussian 2^-(r^(2 order)) of the superelliptic
        radius r = (|ax / hx|^q + |ay / hy|^q)^(1 / q) of the angles ax
        (horizontal) and ay (vertical) from the beam axis: half widths at half
        maximum (hx, hy) in degrees, order (1 = Gaussian) and the contours'
        exponent q (2 = ellipses; larger = closer to the rectangle a
        diffuser shapes to the receiver's field).
    core_share, core_hwhm_deg: the light that leaves the microlens array
        unspread and keeps the VCSEL's own divergence, a round Gaussian on the
        same axis (half width at half maximum, degrees): its share of the
        on-axis intensity (the flood has the rest).
    beam_yaw_deg, beam_pitch_deg: the beam axis's pointing offset from the
        receiver's optical axis, degrees toward the sensor's right and up.
    vignetting_power: the receive lens's relative illumination cos^n of the
        field angle (n = 4: natural vignetting of a thin lens).
    glare_share: the share of the light reaching the receiver that its optics
        scatter evenly over the SPAD array (veiling glare: stray light of the
        lens and the cover glass), which every zone then collects in
        proportion to its SPADs (`glare`).
    time_axis: the histograms' bins in time and optical path (config
        `sensor.time_axis`).
    """

    direct_peak_counts: float
    dark_counts: float
    ambient_counts: float
    pulse_sigma_bins: float
    pulse_tail_bins: float
    slow_tail_bins: float
    slow_tail_fraction: float
    saturation_counts: float
    dead_time_counts: float
    read_noise_counts: float
    beam_hwhm_deg: tuple[float, float]
    beam_order: float
    beam_contour: float
    core_share: float
    core_hwhm_deg: float
    beam_yaw_deg: float
    beam_pitch_deg: float
    vignetting_power: float
    glare_share: float
    time_axis: geo.TimeAxis

    @classmethod
    def from_config(cls, d: dict, time_axis: geo.TimeAxis) -> "Photometry":
        """The photometry of config `rig.photometry` (`d`) on `time_axis`."""
        values = {k: tuple(map(float, d[k])) if isinstance(d[k], list) else float(d[k]) for k in cls.__dataclass_fields__ if k != "time_axis"}
        return cls(**values, time_axis=time_axis)

    @property
    def pulse(self) -> pulse.Pulse:
        """The instrument response these parameters set (`denali_pipe.core.pulse`)."""
        return pulse.Pulse(self.pulse_sigma_bins, self.pulse_tail_bins, self.slow_tail_bins, self.slow_tail_fraction)

    def emission(self, d_cam: np.ndarray) -> np.ndarray:
        """Relative VCSEL intensity (...,) toward unit directions d_cam
        (..., 3) in the sensor's camera frame (x right, y down, z forward);
        1 on the beam axis: the flood plus the core."""
        return self.flood(d_cam) + self.core(d_cam)

    def flood(self, d_cam: np.ndarray) -> np.ndarray:
        """The flood's share of `emission` (...,). Its angles from the axis
        across (horizontal) and along (vertical) are scaled by their own half
        widths, and its contours are superellipses of `beam_contour`."""
        ax, ay = self._beam_angles(d_cam)
        q = self.beam_contour
        u, v = np.abs(ax / np.deg2rad(self.beam_hwhm_deg[0])), np.abs(ay / np.deg2rad(self.beam_hwhm_deg[1]))
        # scaled by the larger of the two so that a near-rectangular
        # contour (large q) does not overflow far off the axis
        m = np.maximum(np.maximum(u, v), np.finfo(float).tiny)
        r = m * ((u / m) ** q + (v / m) ** q) ** (1.0 / q)
        return (1.0 - self.core_share) * np.exp2(-(r ** (2.0 * self.beam_order)))

    def core(self, d_cam: np.ndarray) -> np.ndarray:
        """The core's share of `emission` (...,)."""
        ax, ay = self._beam_angles(d_cam)
        return self.core_share * np.exp2(-(ax**2 + ay**2) / np.deg2rad(self.core_hwhm_deg) ** 2)

    def core_spot(self) -> tuple[np.ndarray, float]:
        """The core as one spot, for terms smooth over the lit wall: its
        direction (3,) in the camera frame (the beam axis) and its power,
        the core's intensity integrated over solid angle (sr)."""
        axis = self._to_beam()[:, 2]
        return axis, self.core_share * np.pi * np.deg2rad(self.core_hwhm_deg) ** 2 / np.log(2)

    def _to_beam(self) -> np.ndarray:
        """(3, 3): camera-frame row vectors times this are in the beam's frame."""
        return geo.rot_y(self.beam_yaw_deg) @ geo.rot_x(self.beam_pitch_deg)

    def _beam_angles(self, d_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal and vertical angles (rad) of d_cam from the beam axis."""
        d = d_cam @ self._to_beam()
        return np.arctan2(d[..., 0], d[..., 2]), np.arctan2(d[..., 1], d[..., 2])

    def response(self, d_cam: np.ndarray) -> np.ndarray:
        """Relative receive response (...,) to rays along d_cam (..., 3,
        camera frame): the lens's relative illumination, 1 on its axis.
        Every zone of a SPAD map has the same SPAD group behind the lens, so
        this is each zone's angular response across its footprint too."""
        return d_cam[..., 2] ** self.vignetting_power


@dataclass(frozen=True)
class Conditions:
    """Operating conditions of one capture (the campaign's nuisances,
    `rig.nuisances`): laser power and room light relative to nominal, and the
    clock offset in bins (positive = later). Power and clock offset are per
    subcapture of the firmware (a tuple of one value each, `Firmware.subcaptures`),
    or one value for all."""

    power_gain: tuple[float, ...] | float = 1.0
    ambient_gain: float = 1.0
    time_shift_bins: tuple[float, ...] | float = 0.0


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
    spread: np.ndarray  # (Z, S) cos(incidence at q) / r^2: irradiance at q per unit laser intensity, 1/m^2
    d_cam: np.ndarray  # (Z, S, 3) unit ray directions in the sensor's camera frame
    zone_omega: np.ndarray  # (Z,) solid angle of each zone, sr


def _wall_samples(n: int, s: int) -> WallSamples:
    dirs, omega = geo.zone_directions(n, s)
    z = n * n
    dirs, omega = dirs.reshape(z, s * s, 3), omega.reshape(z, s * s)
    q = geo.intersect_plane(geo.SENSOR_POSITION, dirs, geo.WALL)
    r = np.linalg.norm(q - geo.SENSOR_POSITION, axis=-1)
    cos_q = -(dirs @ geo.WALL.normal)
    R, _ = geo.look_at(geo.SENSOR_POSITION, geo.SENSOR_FORWARD)
    return WallSamples(q, r, omega, cos_q / r**2, dirs @ R.T, omega.sum(1))


@lru_cache(maxsize=None)
def wall_samples(resolution: str) -> WallSamples:
    n = geo.RESOLUTIONS[resolution]
    return _wall_samples(n, WALL_SAMPLES_PER_ZONE[n])


@lru_cache(maxsize=None)
def laser_samples(per_side: int) -> WallSamples:
    """The flood-lit wall as one grid (a single 'zone') of per_side^2 samples."""
    return _wall_samples(1, per_side)


def irradiance(ws: WallSamples, phot: Photometry) -> np.ndarray:
    """(Z, S) laser irradiance at each wall sample, relative (1/m^2 at unit on-axis intensity)."""
    return phot.emission(ws.d_cam) * ws.spread


def collected(ws: WallSamples, phot: Photometry) -> np.ndarray:
    """(Z, S) each sample's solid angle weighted by the zone's receive response, sr."""
    return ws.omega * phot.response(ws.d_cam)


def _splat(hist: np.ndarray, zone: np.ndarray, opl: np.ndarray, weight: np.ndarray, axis: geo.TimeAxis) -> None:
    """Add `weight` at fractional bins of `opl` (m, on `axis`; linear
    interpolation) into hist (Z, B). Paths outside the time window land in
    padding columns that are dropped."""
    nz, nb = hist.shape
    width = nb + 3
    b = axis.opl_to_bin(opl) - 0.5  # bin centres sit at integer + 0.5
    lo = np.floor(b)
    f = b - lo
    idx = zone * width + (np.clip(lo, -1, nb) + 1).astype(np.int64)
    flat = np.bincount(np.concatenate([idx, idx + 1]), np.concatenate([weight * (1 - f), weight * f]), nz * width)
    hist += flat.reshape(nz, width)[:, 1 : nb + 1]


@dataclass(frozen=True)
class Transport:
    """Noise-free, pulse-free light transport of one scene at one resolution.

    hist: (Z, N_BINS) the direct wall return plus every scatterer's
        three-bounce return, relative units;
    ambient: (Z,) share of the room light that still reaches each zone's
        wall patch (1 without scatterers)."""

    hist: np.ndarray
    ambient: np.ndarray


def transport(resolution: str, scatterers: list[Scatterer], phot: Photometry) -> Transport:
    """The scene's light transport: laser returns and room-light occlusion,
    under `phot`'s emission profile and receive response."""
    ws = wall_samples(resolution)
    nz, ns = ws.r.shape
    rho_w = geo.WALL_ALBEDO
    hist = np.zeros((nz, geo.N_BINS))
    blocked = np.zeros(nz * ns)
    zone = np.repeat(np.arange(nz), ns)
    q, r_q = ws.q.reshape(-1, 3), ws.r.reshape(-1)
    e_q = irradiance(ws, phot).reshape(-1)
    collect = collected(ws, phot)
    # radiance of q toward the sensor per unit irradiance, times the ray's weighted solid angle
    seen = (rho_w / np.pi) * collect.reshape(-1)
    _splat(hist, zone, 2 * r_q, seen * e_q, phot.time_axis)

    nw = geo.WALL.normal
    for sc in scatterers:
        d_oq = q[None, :, :] - sc.points[:, None, :]  # (O, Q, 3)
        dist = np.linalg.norm(d_oq, axis=-1)
        cos_o = np.einsum("oqk,ok->oq", d_oq, sc.normals) / dist
        cos_q = -(d_oq @ nw) / dist
        # geometry term o -> q times the area of o; back faces contribute nothing
        g_oq = np.clip(cos_o, 0, None) * np.clip(cos_q, 0, None) / dist**2 * sc.area[:, None]
        # room light (a uniform diffuse room) reaching q, blocked by o in
        # proportion to o's projected solid angle over pi, minus what o's
        # Lambertian part reflects back (its retroreflected share returns
        # to the lamps, not to the wall)
        blocked += (1.0 - sc.rho_diffuse) * g_oq.sum(0) / np.pi
        if sc.rho_retro > 0:
            radiance_in = (rho_w / np.pi) * e_q  # L(q -> o)
            w = sc.rho_retro * radiance_in[None, :] * g_oq * seen[None, :]
            _splat(hist, np.broadcast_to(zone, w.shape).ravel(), (2 * r_q + 2 * dist).ravel(), w.ravel(), phot.time_axis)
        if sc.rho_diffuse > 0:
            _add_diffuse(hist, zone, r_q, seen, g_oq, dist, sc, phot)
    ambient = (collect * (1.0 - np.clip(blocked.reshape(nz, ns), 0.0, 1.0))).sum(1) / collect.sum(1)
    return Transport(hist, ambient)


def _lit_spots(phot: Photometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The flood-lit wall as spots for the diffuse three-bounce term: the
    coarse grid carrying the flood, plus the core as one spot on the beam
    axis (too narrow for the grid to sample). The grid places the flood's
    light; a finer grid sets its total. Returns points p (P, 3), their
    distances from the sensor r_p (P,), m, and their shares of the beam
    (P,): intensity times solid angle, sr."""
    ls, fine = laser_samples(LASER_SAMPLES), laser_samples(FLOOD_POWER_SAMPLES)
    axis, power = phot.core_spot()
    R, _ = geo.look_at(geo.SENSOR_POSITION, geo.SENSOR_FORWARD)
    core = geo.intersect_plane(geo.SENSOR_POSITION, (axis @ R)[None], geo.WALL)
    p = np.concatenate([ls.q.reshape(-1, 3), core])
    flood = (phot.flood(ls.d_cam) * ls.omega).reshape(-1)
    flood *= (phot.flood(fine.d_cam) * fine.omega).sum() / flood.sum()
    share = np.append(flood, power)
    return p, np.linalg.norm(p - geo.SENSOR_POSITION, axis=-1), share


def _add_diffuse(hist, zone, r_q, seen, g_oq, d_oq, sc: Scatterer, phot: Photometry) -> None:
    """Lambertian scatterer lit by the whole flood-lit wall: sum over laser spots p."""
    p, r_p, share = _lit_spots(phot)
    d_po = sc.points[None, :, :] - p[:, None, :]  # (P, O, 3)
    dist_po = np.linalg.norm(d_po, axis=-1)
    cos_p = (d_po @ geo.WALL.normal) / dist_po
    cos_o = -np.einsum("pok,ok->po", d_po, sc.normals) / dist_po
    # L(p -> o) cos_p a_p / |p - o|^2 with a_p = omega_p r_p^2 / cos_p, L = rho_w/pi E_L(p)
    # and E_L(p) = I(p) cos_p / r_p^2: the spot's share of the beam is I(p) omega_p
    e_o = (geo.WALL_ALBEDO / np.pi) * share[:, None] * np.clip(cos_p, 0, None)
    e_o = e_o * np.clip(cos_o, 0, None) / dist_po**2  # (P, O) irradiance at o from each p
    radiance_o = (sc.rho_diffuse / np.pi) * e_o
    w_oq = g_oq * seen[None, :]  # (O, Q)
    zones = np.broadcast_to(zone, w_oq.shape).ravel()
    base_opl = (d_oq + r_q[None, :]).ravel()
    o_index = np.repeat(np.arange(len(sc.points)), len(r_q))
    for ip in range(len(p)):
        opl = base_opl + (r_p[ip] + dist_po[ip])[o_index]
        _splat(hist, zones, opl, (radiance_o[ip][:, None] * w_oq).ravel(), phot.time_axis)


def pulse_kernel(phot: Photometry, shift_bins: float = 0.0) -> np.ndarray:
    """The rig's pulse as `pulse.kernel` draws it: (2 N_BINS - 1,) for delays
    -(N_BINS - 1)..N_BINS - 1 bins."""
    return pulse.kernel(phot.pulse, shift_bins)


def respond(x: np.ndarray, saturation: float, dead: np.ndarray | float) -> np.ndarray:
    """A zone's counts (..., N_BINS) from its expected photon counts x.

    SPAD dead time: each of the zone's SPADs registers at most one photon
    per laser cycle, so a bin keeps exp(-counts before it / dead) of its
    photons (first-photon pile-up, `dead` = SPADs x cycles in counts): the
    floor after a strong direct return sits below the floor before it. The
    zone's pulse combiner then registers at most about one event per bin
    per cycle: counts saturate as s (1 - exp(-x / s)) with s = `saturation`,
    flattening the direct peak."""
    before = np.cumsum(x, axis=-1) - x
    detected = dead * -np.expm1(-x / dead) * np.exp(-before / dead)
    return saturation * -np.expm1(-detected / saturation)


def _gain(phot: Photometry) -> float:
    """Counts per unit transport so that the centre 3x3 zone's direct peak is
    `direct_peak_counts` above the floor, before the nonlinearity."""
    return phot.direct_peak_counts / _direct_peak(phot)


@lru_cache(maxsize=None)
def _direct_peak(phot: Photometry) -> float:
    zone_size, _ = _floor_shares(geo.REFERENCE_RESOLUTION, phot)
    light = glare(transport(geo.REFERENCE_RESOLUTION, [], phot).hist, phot.glare_share, zone_size)
    h = pulse.convolve(light, pulse_kernel(phot))
    return float(h[len(h) // 2].max())


@lru_cache(maxsize=None)
def _floor_shares(resolution: str, phot: Photometry) -> tuple[np.ndarray, np.ndarray]:
    """Each zone's floor relative to the centre 3x3 zone's, (Z,) twice: dark
    counts scale with the zone's SPADs (its solid angle, the lens mapping
    solid angle onto the array), room light with its vignetted solid angle
    (the lens passes it as it passes the laser's return)."""
    ref, ws = wall_samples(geo.REFERENCE_RESOLUTION), wall_samples(resolution)
    centre = len(ref.zone_omega) // 2
    zone_size = ws.zone_omega / ref.zone_omega.mean()
    room = collected(ws, phot).sum(1) / collected(ref, phot)[centre].sum()
    return zone_size, room


def expected_counts(resolution: str, light_on: bool, scatterers: list[Scatterer], phot: Photometry, conditions: Conditions = Conditions()) -> np.ndarray:
    """Expected counts (n, n, N_BINS) float64, before noise."""
    return counts_from_transport(resolution, light_on, transport(resolution, scatterers, phot), phot, conditions)


def counts_from_transport(resolution: str, light_on: bool, light: Transport, phot: Photometry, conditions: Conditions = Conditions()) -> np.ndarray:
    """Expected counts (n, n, N_BINS) from a `transport` result: pulse,
    gain, floor and the response nonlinearity, under one capture's
    `conditions`. Lightings share one transport."""
    n = geo.RESOLUTIONS[resolution]
    fw, ref = geo.FIRMWARE[resolution], geo.FIRMWARE[geo.REFERENCE_RESOLUTION]
    iters = fw.kilo_iterations / ref.kilo_iterations
    zone_size, room = _floor_shares(resolution, phot)
    # each subcapture is its own measurement: its own laser power and clock offset
    sub = geo.zone_subcapture(resolution)
    power = np.broadcast_to(conditions.power_gain, (fw.subcaptures,))
    shift = np.broadcast_to(conditions.time_shift_bins, (fw.subcaptures,))
    # glare mixes the light of every zone, whichever subcapture measures it
    hist = glare(light.hist, phot.glare_share, zone_size)
    signal = np.empty_like(hist)
    for s in range(fw.subcaptures):
        signal[sub == s] = power[s] * pulse.convolve(hist[sub == s], pulse_kernel(phot, float(shift[s])))
    room_light = glare(room * light.ambient, phot.glare_share, zone_size)
    floor = phot.dark_counts * zone_size + (phot.ambient_counts * conditions.ambient_gain * room_light if light_on else 0.0)
    x = iters * (_gain(phot) * signal + floor[:, None])
    # a zone's SPADs (hence its dead-time budget) scale with its solid angle;
    # its combiner's events per cycle do not, only the firmware's cycles
    counts = respond(x, iters * phot.saturation_counts, iters * phot.dead_time_counts * zone_size[:, None])
    return counts.reshape(n, n, geo.N_BINS)


def sample_counts(expected: np.ndarray, phot: Photometry, rng: np.random.Generator) -> np.ndarray:
    """One noisy histogram like `expected`: Poisson shot noise plus Gaussian read noise, int32 >= 0."""
    noisy = rng.poisson(expected) + rng.normal(0.0, phot.read_noise_counts, expected.shape)
    return np.clip(np.rint(noisy), 0, None).astype(np.int32)
