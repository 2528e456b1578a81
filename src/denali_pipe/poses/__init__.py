"""The tracking-pose stage: AprilTag detection, PnP, z-score filtering and scene calibration.

    detect_set(store) -> per-set pose table          (`poses` job, one per set)
    calibrate([tables]) -> Calibration                (`calibrate` job on the light-on background
                                                       sets: object positions, scene.json dict)
    report.table6.table6(filtered), report.fig12.write_fig12(...)
                                                      (`table6` job: calibrate() over every light-on set)

Modules: `detect` (detectors, corner refinement), `pnp` (intrinsics, board and
single-tag PnP, IPPE, planes), `estimate` (per frame and per set),
`filtering` (|z| > 2 rejection), `calibrate` (pooled outputs).
"""

from denali_pipe.poses.calibrate import Calibration, calibrate, detection_rates, object_positions, replane, scene_dict
from denali_pipe.poses.detect import DETECTORS, Detection, TagDetector, refine_corners
from denali_pipe.poses.estimate import COLUMNS, detect_set, estimate_frames
from denali_pipe.poses.filtering import filter_estimates, summarise, zscore_keep
from denali_pipe.poses.pnp import REAL_TRACKING_INTRINSICS, Intrinsics, tracking_intrinsics

__all__ = [
    "COLUMNS", "DETECTORS", "REAL_TRACKING_INTRINSICS", "Calibration", "Detection", "Intrinsics", "TagDetector",
    "calibrate", "detect_set", "detection_rates", "estimate_frames", "filter_estimates", "object_positions",
    "refine_corners", "replane", "scene_dict", "summarise", "tracking_intrinsics", "zscore_keep",
]  # fmt: skip
