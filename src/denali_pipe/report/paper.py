"""The paper's published numbers that our tables sit beside: the one place the
project keeps them (from the DENALI paper's supplement)."""

from __future__ import annotations

# Table 4: on-disk size of the real release in GB, per modality and resolution.
TABLE4_GB = {
    "lidar_histograms": {"3x3": 0.18, "8x8": 1.22},
    "tracking_rgb": {"3x3": 10.01, "8x8": 10.20},
    "tracking_depth": {"3x3": 23.48, "8x8": 23.49},
    "colocated_rgb": {"3x3": 3.79, "8x8": 3.89},
    "colocated_depth": {"3x3": 9.92, "8x8": 9.92},
    "metadata": {"3x3": 0.20, "8x8": 0.20},
}
