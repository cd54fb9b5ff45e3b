"""Straight-line moves between two poses: the position along a line, the orientation about one axis.

Part of :mod:`manip.arm.trajectory`.  Converting poses to joints is the caller's job.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from manip.arm.trajectory.ends import SegmentEnds
from manip.arm.trajectory.limits import (
    DEFAULT_CARTESIAN_LIMITS,
    CartesianLimits,
    Vector,
    _check_speed,
    _check_time,
)
from manip.arm.trajectory.scaling import Profile, profile_at


def _rotation_log(r: Vector) -> tuple[Vector, float]:
    """Unit axis and angle (radians, in [0, π]) of a 3x3 rotation."""
    w = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin2 = float(np.linalg.norm(w))  # 2·sin θ
    cos2 = float(np.trace(r)) - 1.0  # 2·cos θ
    angle = math.atan2(sin2, cos2)
    if angle < 1e-12:
        return np.array([0.0, 0.0, 1.0]), 0.0
    if angle < 0.5 * math.pi or math.sin(angle) > 1e-6:
        return w / sin2, angle
    # Near π the skew part vanishes: (R + Rᵀ)/2 - cos θ·I = (1 - cos θ)·k·kᵀ.
    b = 0.5 * (r + r.T) - math.cos(angle) * np.eye(3)
    j = int(np.argmax(np.diag(b)))
    axis = b[:, j] / math.sqrt(max(float(b[j, j]), 1e-300))
    axis = axis / float(np.linalg.norm(axis))
    if float(np.dot(axis, w)) < 0.0:
        axis = -axis
    return axis, angle


def _pose(m: ArrayLike, name: str) -> Vector:
    a = np.array(m, dtype=np.float64)
    if a.shape != (4, 4):
        raise ValueError(f"{name} must be a 4x4 homogeneous matrix, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    if not np.allclose(a[3], (0.0, 0.0, 0.0, 1.0), atol=1e-9):
        raise ValueError(f"{name} bottom row must be (0, 0, 0, 1)")
    r = a[:3, :3]
    if float(np.max(np.abs(r.T @ r - np.eye(3)))) > 1e-4 or abs(float(np.linalg.det(r)) - 1.0) > 1e-4:
        raise ValueError(f"{name} rotation part is not a rotation (tolerance 1e-4)")
    a.flags.writeable = False
    return a


def _orthonormal(r: Vector) -> Vector:
    u, _, vt = np.linalg.svd(r)
    out: Vector = u @ vt
    return out


class CartesianSegment(SegmentEnds):
    """Straight-line move between two 4x4 poses (mm), with a quintic or trapezoidal time scaling.

    The position follows ``p0 + s·(p1 - p0)``; the orientation is ``R0·Rot(k, s·θ)`` where
    ``Rot(k, θ) = R0ᵀ·R1`` (the single rotation taking the start orientation to the goal's, θ in
    [0°, 180°]).  ``s`` runs from 0 to 1 along :class:`Profile`.  The duration is the smallest that
    keeps the tool speed/acceleration and the rotation rate within ``limits`` scaled by the speed factor
    (f and f²), unless ``duration`` is given explicitly.  This is the slerp form; Paul's drive
    transform visits the same positions but different intermediate orientations.

    ``turn_share`` is the share of the way over which the orientation turns: 1 (the default) turns it in
    step with the position, all the way; a faulty server's smaller share turns the hand to the goal's
    orientation ahead of the position (``Rot(k, min(1, s/turn_share)·θ)``) and carries it unturned the
    rest of the line (erratum ``straight-line-orientation``).
    """

    __slots__ = ("_angle", "_axis", "_plain", "_r0", "_turn_share", "profile")

    def __init__(
        self,
        start: ArrayLike,
        goal: ArrayLike,
        limits: CartesianLimits = DEFAULT_CARTESIAN_LIMITS,
        speed: float = 1.0,
        profile: Profile = Profile.QUINTIC,
        *,
        duration: float | None = None,
        turn_share: float = 1.0,
    ) -> None:
        if not 0.0 < turn_share <= 1.0:
            raise ValueError("turn_share must be in (0, 1]")
        self._turn_share = float(turn_share)
        self._start = _pose(start, "start")
        self._goal = _pose(goal, "goal")
        self.profile = profile
        f = _check_speed(speed)
        self._r0 = _orthonormal(self._start[:3, :3])
        self._axis, self._angle = _rotation_log(self._r0.T @ _orthonormal(self._goal[:3, :3]))
        kx, ky, kz = (float(a) for a in self._axis)
        k = ((0.0, -kz, ky), (kz, 0.0, -kx), (-ky, kx, 0.0))
        self._plain = (  # for pose_along, which runs at every servo cycle: plain floats beat numpy on 3x3
            self._r0.tolist(),
            k,
            tuple(tuple(sum(k[i][m] * k[m][j] for m in range(3)) for j in range(3)) for i in range(3)),
            self._start[:3, 3].tolist(),
            (self._goal[:3, 3] - self._start[:3, 3]).tolist(),
        )
        if duration is None:
            t_lin = profile.duration(self.distance, limits.max_speed * f, limits.max_accel * f * f)
            t_rot = profile.duration(self.angle, limits.max_rot_speed * f, limits.max_rot_accel * f * f)
            self._duration = max(t_lin, t_rot)
        else:
            if not (math.isfinite(duration) and duration >= 0.0):
                raise ValueError("duration must be finite and >= 0")
            self._duration = float(duration)

    @property
    def distance(self) -> float:
        """Length of the straight line, mm."""
        return float(np.linalg.norm(self._goal[:3, 3] - self._start[:3, 3]))

    @property
    def axis(self) -> Vector:
        """Unit rotation axis in the start frame (arbitrary when the angle is 0)."""
        return self._axis.copy()

    @property
    def angle(self) -> float:
        """Total reorientation, degrees in [0, 180]."""
        return math.degrees(self._angle)

    def progress(self, t: float) -> float:
        """The path parameter ``s(t)`` in [0, 1]."""
        x = _check_time(t)
        if self._duration == 0.0:
            return 1.0
        return profile_at(self.profile, x / self._duration)[0]

    def pose_at(self, t: float) -> Vector:
        """The commanded 4x4 pose at ``t`` seconds from the segment's start (clamped)."""
        return self.pose_along(self.progress(t))

    def pose_along(self, s: float) -> Vector:
        """The 4x4 pose at path parameter ``s`` (0 = start, 1 = goal, clamped): the same line whatever
        the timing, so a path can be checked independently of the speed factor."""
        if math.isnan(s):
            raise ValueError("the path parameter must not be NaN")
        if s <= 0.0:
            return self._start.copy()
        if s >= 1.0:
            return self._goal.copy()
        r0, k, k2, p0, dp = self._plain
        turned = min(1.0, s / self._turn_share) * self._angle
        sn, vs = math.sin(turned), 1.0 - math.cos(turned)
        # Rodrigues, Rot(k, sθ) = I + sin·K + (1 − cos)·K², then R0·Rot
        rot = [[float(i == j) + sn * k[i][j] + vs * k2[i][j] for j in range(3)] for i in range(3)]
        rows = [
            [*(sum(r0[i][m] * rot[m][j] for m in range(3)) for j in range(3)), p0[i] + s * dp[i]]
            for i in range(3)
        ]
        return np.array([*rows, [0.0, 0.0, 0.0, 1.0]])

    def done(self, t: float) -> bool:
        return _check_time(t) >= self._duration
