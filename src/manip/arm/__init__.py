"""Arm models: rigid transforms, VAL's O/A/T angles and PUMA kinematics (mm, degrees).

Pure numeric code with no protocol dependencies; the reference server and the clients build on it.
"""

from manip.arm.kinematics import (
    PUMA560_LEE,
    PUMA600,
    READY,
    UNIMATION_LIMITS,
    JointLimits,
    OutOfRange,
    PumaGeometry,
    Solution,
    Unreachable,
    forward,
    inverse_all,
    inverse_nearest,
    jacobian,
    within_limits,
)
from manip.arm.oat import apply_increment, transform_from_xyzoat, xyzoat_from_transform
from manip.arm.transform import Transform

__all__ = [
    "PUMA560_LEE",
    "PUMA600",
    "READY",
    "UNIMATION_LIMITS",
    "JointLimits",
    "OutOfRange",
    "PumaGeometry",
    "Solution",
    "Transform",
    "Unreachable",
    "apply_increment",
    "forward",
    "inverse_all",
    "inverse_nearest",
    "jacobian",
    "transform_from_xyzoat",
    "within_limits",
    "xyzoat_from_transform",
]
