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
# (origin tag 14): tag id -> component, number of estimates after |z| > 2
# rejection, and mean / standard deviation per axis in cm.
TABLE6 = {
    0: {"component": "lidar", "n_estimates": 11340, "x_mean_cm": 47.03, "x_std_cm": 0.02, "y_mean_cm": 25.42, "y_std_cm": 0.04, "z_mean_cm": 38.87, "z_std_cm": 0.05},
    5: {"component": "relay_wall", "n_estimates": 11282, "x_mean_cm": 43.14, "x_std_cm": 0.06, "y_mean_cm": 80.39, "y_std_cm": 0.19, "z_mean_cm": 41.48, "z_std_cm": 0.14},
    6: {"component": "relay_wall", "n_estimates": 11417, "x_mean_cm": 86.07, "x_std_cm": 0.02, "y_mean_cm": 82.72, "y_std_cm": 0.18, "z_mean_cm": 12.79, "z_std_cm": 0.17},
    7: {"component": "relay_wall", "n_estimates": 11237, "x_mean_cm": 129.44, "x_std_cm": 0.12, "y_mean_cm": 84.21, "y_std_cm": 0.36, "z_mean_cm": 40.13, "z_std_cm": 0.17},
    10: {"component": "table", "n_estimates": 11307, "x_mean_cm": 0.07, "x_std_cm": 0.09, "y_mean_cm": 76.28, "y_std_cm": 0.13, "z_mean_cm": -0.54, "z_std_cm": 0.13},
    11: {"component": "table", "n_estimates": 9531, "x_mean_cm": 145.92, "x_std_cm": 0.17, "y_mean_cm": 76.85, "y_std_cm": 0.26, "z_mean_cm": 1.65, "z_std_cm": 0.26},
    12: {"component": "table", "n_estimates": 11326, "x_mean_cm": -0.50, "x_std_cm": 0.11, "y_mean_cm": 38.75, "y_std_cm": 0.13, "z_mean_cm": -0.86, "z_std_cm": 0.17},
    13: {"component": "table", "n_estimates": 10772, "x_mean_cm": 147.23, "x_std_cm": 0.07, "y_mean_cm": 39.40, "y_std_cm": 0.08, "z_mean_cm": 1.98, "z_std_cm": 0.11},
    14: {"component": "table", "n_estimates": 11492, "x_mean_cm": 0.01, "x_std_cm": 0.16, "y_mean_cm": -0.00, "y_std_cm": 0.08, "z_mean_cm": 0.01, "z_std_cm": 0.25},
    15: {"component": "table", "n_estimates": 11331, "x_mean_cm": 148.80, "x_std_cm": 0.11, "y_mean_cm": 1.86, "y_std_cm": 0.07, "z_mean_cm": 1.54, "z_std_cm": 0.17},
}
