"""The receiver's veiling glare: stray light of the lens and window spread
over the whole SPAD array. The rig draws it (`rig.histograms`) and the
twin's calibration fits it (`twin.calibrate`): one formula for both."""

from __future__ import annotations

import numpy as np


def glare(light: np.ndarray, share: float, spads: np.ndarray) -> np.ndarray:
    """What each zone collects (Z, ...) from the light `light` (Z, ...)
    focused on it, once the receiver's veiling glare has spread `share` of
    all of it over the SPAD array: every zone takes the part its SPADs
    `spads` (Z,) hold. A dim zone beside a bright one then holds the bright
    one's return at the bright one's time: the real far column's early
    second peak (docs/rig_zones.md, "Glare")."""
    area = (spads / spads.sum()).reshape((-1,) + (1,) * (light.ndim - 1))
    return (1.0 - share) * light + share * area * light.sum(axis=0, keepdims=True)
