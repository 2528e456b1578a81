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

# Table 6: AprilTag position estimates of the static tags in the world frame
# (origin tag 14): per tag id its component, the number of estimates kept
# after |z| > 2 rejection, and the mean and standard deviation per axis in cm.
TABLE6_COLUMNS = ("component", "n_estimates", "x_mean_cm", "x_std_cm", "y_mean_cm", "y_std_cm", "z_mean_cm", "z_std_cm")
_TABLE6_ROWS = {
    0: ("lidar", 11340, 47.03, 0.02, 25.42, 0.04, 38.87, 0.05),
    5: ("relay_wall", 11282, 43.14, 0.06, 80.39, 0.19, 41.48, 0.14),
    6: ("relay_wall", 11417, 86.07, 0.02, 82.72, 0.18, 12.79, 0.17),
    7: ("relay_wall", 11237, 129.44, 0.12, 84.21, 0.36, 40.13, 0.17),
    10: ("table", 11307, 0.07, 0.09, 76.28, 0.13, -0.54, 0.13),
    11: ("table", 9531, 145.92, 0.17, 76.85, 0.26, 1.65, 0.26),
    12: ("table", 11326, -0.50, 0.11, 38.75, 0.13, -0.86, 0.17),
    13: ("table", 10772, 147.23, 0.07, 39.40, 0.08, 1.98, 0.11),
    14: ("table", 11492, 0.01, 0.16, -0.00, 0.08, 0.01, 0.25),
    15: ("table", 11331, 148.80, 0.11, 1.86, 0.07, 1.54, 0.17),
}
TABLE6 = {tag: dict(zip(TABLE6_COLUMNS, row)) for tag, row in _TABLE6_ROWS.items()}
