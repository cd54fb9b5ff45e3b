"""Scalar time scalings ``s(u)`` from 0 to 1: the quintic and the trapezoidal profile.

Part of :mod:`manip.arm.trajectory`.
"""

from __future__ import annotations

import enum
import math

#: Peak of ds/du and |d²s/du²| of the quintic ``s(u) = 10u³ - 15u⁴ + 6u⁵`` on [0, 1].
QUINTIC_PEAK_VELOCITY = 1.875
QUINTIC_PEAK_ACCEL = 10.0 / math.sqrt(3.0)

#: Fraction of the duration spent accelerating (and again decelerating) in the trapezoidal profile.
#: 1/3 gives a cruise velocity of 1.5x the mean, the usual default for a trapezoidal ("LSPB") profile.
TRAPEZOID_BLEND_FRACTION = 1.0 / 3.0


class Profile(enum.Enum):
    """Scalar time-scaling ``s(u)``, ``u = t/T``, from 0 to 1 with zero velocity at both ends."""

    QUINTIC = "quintic"
    TRAPEZOID = "trapezoid"

    @property
    def peak_velocity(self) -> float:
        """``max ds/du`` on [0, 1]."""
        if self is Profile.QUINTIC:
            return QUINTIC_PEAK_VELOCITY
        return 1.0 / (1.0 - TRAPEZOID_BLEND_FRACTION)

    @property
    def peak_accel(self) -> float:
        """``max |d²s/du²|`` on [0, 1]."""
        if self is Profile.QUINTIC:
            return QUINTIC_PEAK_ACCEL
        b = TRAPEZOID_BLEND_FRACTION
        return 1.0 / (b * (1.0 - b))

    def duration(self, distance: float, max_speed: float, max_accel: float) -> float:
        """Shortest ``T`` moving ``distance`` with this profile within the speed and acceleration."""
        d = abs(distance)
        if d == 0.0:
            return 0.0
        return max(self.peak_velocity * d / max_speed, math.sqrt(self.peak_accel * d / max_accel))


def quintic_scaling(u: float) -> tuple[float, float, float]:
    """``(s, ds/du, d²s/du²)`` of ``s = 10u³ - 15u⁴ + 6u⁵``, ``u`` clamped to [0, 1]."""
    x = min(max(u, 0.0), 1.0)
    x2 = x * x
    s = x2 * x * (10.0 + x * (-15.0 + 6.0 * x))
    ds = 30.0 * x2 * (1.0 - x) * (1.0 - x)
    dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return s, ds, dds


def trapezoid_scaling(u: float, blend: float = TRAPEZOID_BLEND_FRACTION) -> tuple[float, float, float]:
    """``(s, ds/du, d²s/du²)`` of the trapezoidal-velocity profile, ``u`` clamped to [0, 1].

    Constant acceleration for ``u < b``, constant velocity ``1/(1 - b)``, constant deceleration for
    ``u > 1 - b``, where ``b = blend`` (0 < b <= 1/2).
    """
    b = float(blend)
    if not 0.0 < b <= 0.5:
        raise ValueError(f"blend fraction must satisfy 0 < b <= 1/2, got {blend!r}")
    x = min(max(u, 0.0), 1.0)
    a = 1.0 / (b * (1.0 - b))
    if x < b:
        return 0.5 * a * x * x, a * x, a
    if x <= 1.0 - b:
        return (x - 0.5 * b) / (1.0 - b), 1.0 / (1.0 - b), 0.0
    y = 1.0 - x
    return 1.0 - 0.5 * a * y * y, a * y, -a


def profile_at(profile: Profile, u: float) -> tuple[float, float, float]:
    """Dispatch to :func:`quintic_scaling` or :func:`trapezoid_scaling`."""
    return quintic_scaling(u) if profile is Profile.QUINTIC else trapezoid_scaling(u)
