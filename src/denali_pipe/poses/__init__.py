"""The tracking-pose stage: AprilTag detection, PnP, z-score filtering and scene calibration.

    detect_set(store) -> per-set pose table          (`poses` job, one per set)
    calibrate([tables]) -> Calibration                (`calibrate` job on the light-on background
                                                       sets: object positions, scene.json dict)
    report.table6.table6(filtered), report.fig12.write_fig12(...)
                                                      (`table6` job: calibrate() over every light-on set)

Modules: `detect` (detectors, corner refinement), `template` (corners from a
photometric fit of a tag's pattern), `pnp` (intrinsics, board and single-tag
PnP, IPPE, rays and planes), `layout` (the static tags and the camera per
set), `estimate` (per frame and per set), `filtering` (|z| > 2 rejection),
`calibrate` (pooled outputs).
"""

from denali_pipe.poses.calibrate import Calibration, calibrate, detection_rates, object_positions, scene_dict
from denali_pipe.poses.detect import DETECTORS, Detection, TagDetector, refine_corners
from denali_pipe.poses.estimate import COLUMNS, detect_set, estimate_frames
from denali_pipe.poses.filtering import filter_estimates, summarise, zscore_keep
from denali_pipe.poses.layout import Layout, estimate_layout
from denali_pipe.poses.pnp import REAL_TRACKING_INTRINSICS, Intrinsics, tracking_intrinsics
from denali_pipe.poses.template import TemplateFit, fit_template

__all__ = [
    "COLUMNS", "DETECTORS", "REAL_TRACKING_INTRINSICS", "Calibration", "Detection", "Intrinsics", "Layout", "TagDetector",
    "TemplateFit", "calibrate", "detect_set", "detection_rates", "estimate_frames", "estimate_layout", "filter_estimates",
    "fit_template", "object_positions", "refine_corners", "scene_dict", "summarise", "tracking_intrinsics", "zscore_keep",
]  # fmt: skip
