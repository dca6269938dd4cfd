"""Coverage sub-task (paper Sec. IV-A, IV-B): interception, shifting spiral, outcome estimator.

Compiled kernels for the tree search: `coverage_outcome` (the paper's estimator),
`sharp_coverage_outcome` (the sharp estimator: flight detections and the spiral's footprint), and
`spiral_phases` for the path; the intercept itself is the mission's vehicle's
(`hptrack.models.mission.intercept_flight`). Python objects for planners: `CoverageSubtask`,
`estimate_coverage`.
"""

from hptrack.coverage.estimator import (
    CoverageEstimate,
    coverage_cdf,
    coverage_outcome,
    estimate_coverage,
)
from hptrack.coverage.intercept import (
    Intercept,
    intercept_path,
    intercept_waypoint,
    plan_intercept,
)
from hptrack.coverage.sharp_estimator import sharp_coverage_outcome
from hptrack.coverage.spiral import ShiftingSpiral, ellipse_axes, spiral_phases
from hptrack.coverage.subtask import CoverageSubtask

__all__ = [
    "CoverageEstimate",
    "CoverageSubtask",
    "Intercept",
    "ShiftingSpiral",
    "coverage_cdf",
    "coverage_outcome",
    "ellipse_axes",
    "estimate_coverage",
    "intercept_path",
    "intercept_waypoint",
    "plan_intercept",
    "sharp_coverage_outcome",
    "spiral_phases",
]
