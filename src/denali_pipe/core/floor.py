"""A capture's floor against the background subtracted from it.

The room light and the sensor's dark level drift between a capture and the
background capture subtracted from it, and every repeat of a capture shares
the drift: after subtraction each zone holds a constant offset over its
kept bins that no twin renders. On the demo's dim zones it is the largest
part of the signal (sd ~35 counts per bin against an object return of
10-20: docs/twin.md). The transforms add it to the noisy twins
(`transforms.sim_to_real`); the twin's calibration takes it out of the
captures before it fits (`twin.calibrate`).
"""

from __future__ import annotations

import numpy as np


def kept_bins(counts: np.ndarray, axis: int | tuple[int, ...] | None = None) -> np.ndarray:
    """The bins the preprocessing kept (bool): not exactly 0 in any of
    `counts` along `axis` (captures, repeats; None: element by element). It
    zeroes a later-starting zone's bins before its start
    (`preprocess.histograms`), and a background-subtracted count is never
    exactly 0 otherwise."""
    nonzero = np.asarray(counts) != 0
    return nonzero if axis is None else nonzero.any(axis=axis)


# The captures' common offset is taken out only where it lies this many
# standard errors from 0: a shift within the noise moved the transforms' scale
# of low-SNR twins by 3 % (tests/test_transforms.py's recovery: -0.2 counts
# over 362 captures), one of -15 counts left in tripled it.
OFFSET_SIGNIFICANCE = 3.0


def common_offset(offsets: np.ndarray) -> float:
    """The mean of captures' floor offsets (N,) counts where it is
    significant (`OFFSET_SIGNIFICANCE`), else 0 (also with fewer than 2)."""
    if len(offsets) < 2:
        return 0.0
    mean, se = float(offsets.mean()), float(offsets.std(ddof=1) / np.sqrt(len(offsets)))
    return mean if abs(mean) > OFFSET_SIGNIFICANCE * se else 0.0


def offset_spread(offsets: np.ndarray, noise_var: np.ndarray) -> float:
    """The offsets' own variance tau^2 (counts^2): the spread of captures'
    readings (N,) less their noise variances (N,), where that excess is
    significant (their variance above the mean noise by `OFFSET_SIGNIFICANCE`
    times a sample variance's relative sd, sqrt(2 / (N - 1))), else 0: a
    spread within the noise is not taken for offsets."""
    if len(offsets) < 2:
        return 0.0
    var, noise = float(offsets.var(ddof=1)), float(noise_var.mean())
    return var - noise if var > noise * (1 + OFFSET_SIGNIFICANCE * np.sqrt(2 / (len(offsets) - 1))) else 0.0
