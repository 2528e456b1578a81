"""The capture campaign's nuisances: what changes between sets, locations and
captures of a real campaign although the scene is nominally the same.

Magnitudes are standard deviations from `config.rig.nuisances`; each draw
comes from a seed derived from the config seed and stable names, so a rerun
reproduces it, and `rig_truth.json` records every value drawn.

- Per capture set (one mounting of the object, one session):
  - object tilt about the plate's horizontal axis and yaw about the vertical,
    sd 1.5 deg each: the plate is re-mounted on its post for every set, and
    the release's averaged tag-1 poses are tilted 3.1-4.8 deg (mean 4.2) from
    level across locations, so the mounting is not square to a few degrees;
  - laser power, relative sd 2 %: VCSEL output falls ~0.3-0.5 %/K and the
    sensor's temperature differs by a few K between sessions;
  - room light (ambient), relative sd 5 %: lamps warm up and age, and
    daylight around the blinds changes between sessions.
- Per gantry location of a set: gantry repeatability, sd 1 mm in x and y.
  Belt-driven stepper gantries repeat to 0.1-1 mm after homing; the release's
  tag-1 positions scatter 2-5 mm (sd) about a regular grid, an upper bound
  that includes the tracking error. The object tag moves with the gantry, so
  the tracking frames show the offset too, and the labels (calibrated from
  the background sets) differ from an object set's true position by it.
- Per capture (repeat): timing drift, sd 0.15 bins (12 ps): the laser
  driver's and TDC's delay drift with temperature between captures, left
  after the sensor's on-chip reference-SPAD correction.
- Per subcapture of a capture (the 8x8 mode's 8 sequential measurements,
  docs/rig_zones.md), about the capture's values:
  - clock offset, sd 0.1 bins (8 ps): each subcapture is referenced to its
    own reference-SPAD histogram, whose peak is located only as well as its
    counts allow; at 8x8's 10 kilo-iterations per subcapture a ~4-bin wide
    reference peak of a few hundred counts places its centroid to ~0.1 bins;
  - laser power, sd 0.5 %: the VCSEL's output falls ~0.3-0.5 %/K and its die
    warms by about a kelvin over the sequence of pulse trains.
  With one subcapture (3x3) both deviations are zero.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from denali_pipe.core import geometry as geo
from denali_pipe.core.seeds import rng_for
from denali_pipe.rig.histograms import Conditions


@dataclass(frozen=True)
class SetNuisance:
    """One capture set's mounting and session: the object's tilt and yaw
    (deg) about its mount point, laser power and room light relative to nominal."""

    tilt_deg: float
    yaw_deg: float
    power_gain: float
    ambient_gain: float

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def object_pose(self, tag1: geo.Pose, gantry_offset: np.ndarray) -> geo.Pose:
        """The object's local frame -> world at the gantry location where tag 1
        sits at `tag1` (the tracked scene's pose), mounted with this set's
        tilt and yaw and moved by the location's gantry offset (m)."""
        nominal = tag1 @ geo.OBJECT_MOUNT
        # local x is horizontal along the plate, local y up: tilt about x, yaw about y
        mounting = geo.rot_y(self.yaw_deg) @ geo.rot_x(self.tilt_deg)
        return geo.Pose(nominal.R @ mounting, nominal.t + gantry_offset)


def draw_set(nuisances: dict, seed: int, set_name: str) -> SetNuisance:
    """The set's nuisance draw (`nuisances` = the `rig.nuisances` config)."""
    rng = rng_for(seed, set_name, "nuisance")
    tilt, yaw, power, ambient = rng.standard_normal(4)
    return SetNuisance(
        tilt_deg=float(nuisances["object_tilt_deg"] * tilt),
        yaw_deg=float(nuisances["object_yaw_deg"] * yaw),
        power_gain=float(1.0 + nuisances["power_drift"] * power),
        ambient_gain=float(1.0 + nuisances["ambient_drift"] * ambient),
    )


def gantry_offset(nuisances: dict, seed: int, set_name: str, location: int) -> np.ndarray:
    """(3,) world offset (m) of the gantry carriage from its nominal position
    at `location` in this set: horizontal only (the carriage rides on rails)."""
    dx, dy = rng_for(seed, set_name, location, "gantry").standard_normal(2)
    return nuisances["gantry_repeatability_m"] * np.array([dx, dy, 0.0])


def capture_conditions(nuisances: dict, seed: int, set_name: str, location: int, repeat: int, s: SetNuisance, subcaptures: int) -> Conditions:
    """One capture's operating conditions: the set's power and room light,
    its own clock offset, and each of its `subcaptures` sequential
    measurements' deviations in laser power and clock offset about the
    capture's (none with one subcapture)."""
    rng = rng_for(seed, set_name, location, repeat, "clock")
    shift = nuisances["timing_drift_bins"] * rng.standard_normal()
    dev_power, dev_shift = rng.standard_normal((2, subcaptures))
    dev_power, dev_shift = dev_power - dev_power.mean(), dev_shift - dev_shift.mean()
    return Conditions(
        power_gain=tuple(s.power_gain * (1.0 + nuisances["subcapture_power_drift"] * dev_power)),
        ambient_gain=s.ambient_gain,
        time_shift_bins=tuple(shift + nuisances["subcapture_timing_bins"] * dev_shift),
    )
