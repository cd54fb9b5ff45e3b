"""Joint and Cartesian motion limits, the servo tick, and the argument checks every segment shares.

Part of :mod:`manip.arm.trajectory` (its docstring explains the speed factor and the blend time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

Vector = NDArray[np.float64]

#: The move process period: the Puma-11 clock interrupt ran every 16 ms.
TICK = 0.016


def _vector(x: ArrayLike, name: str, n: int | None = None) -> Vector:
    """A read-only float64 copy of a finite 1-D vector (of length ``n`` when given)."""
    v = np.array(x, dtype=np.float64)
    if v.ndim != 1:
        raise ValueError(f"{name} must be a 1-D vector, got shape {v.shape}")
    if n is not None and v.shape[0] != n:
        raise ValueError(f"{name} has {v.shape[0]} elements, expected {n}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be finite")
    v.flags.writeable = False
    return v


def _check_speed(speed: float) -> float:
    f = float(speed)
    if not (math.isfinite(f) and 0.0 < f <= 1.0):
        raise ValueError(f"speed factor must satisfy 0 < f <= 1, got {speed!r}")
    return f


def _check_time(t: float, name: str = "t") -> float:
    x = float(t)
    if math.isnan(x):
        raise ValueError(f"{name} must not be NaN")
    return x


def sample_times(duration: float, tick: float = TICK) -> Vector:
    """Tick times ``0, tick, 2·tick, …`` up to the first one at or after ``duration``.

    A 2 s move at 16 ms gives 126 samples, the last exactly at 2 s.  Times are computed as ``k·tick``
    (not by accumulation); a duration within 1e-9 ticks of a whole number of ticks is not rounded up.
    """
    d, h = float(duration), float(tick)
    if not (math.isfinite(d) and d >= 0.0):
        raise ValueError(f"duration must be finite and >= 0, got {duration!r}")
    if not (math.isfinite(h) and h > 0.0):
        raise ValueError(f"tick must be finite and > 0, got {tick!r}")
    steps = math.ceil(d / h - 1e-9)
    return np.arange(steps + 1, dtype=np.float64) * h


@dataclass(frozen=True)
class MotionLimits:
    """Per-joint maximum speed (deg/s) and acceleration (deg/s²), at speed factor 1.

    :data:`PUMA_LIMITS` holds the defaults for the six PUMA joints.  They are *assumed*, conservative
    figures of the right order for a PUMA 560/600 (no 1985 MIT value is known): 60 deg/s and
    200 deg/s² for the three major joints (waist, shoulder, elbow; 60 deg/s at the full 0.86 m reach is
    about 0.9 m/s), 120 deg/s and 400 deg/s² for the lighter wrist joints.  Both groups have
    ``v/a = 0.3 s``, so the default blend half-width is 0.3 s at full speed.
    """

    max_speed: tuple[float, ...]
    max_accel: tuple[float, ...]

    def __post_init__(self) -> None:
        speed = tuple(float(x) for x in self.max_speed)
        accel = tuple(float(x) for x in self.max_accel)
        if not speed or len(speed) != len(accel):
            raise ValueError("max_speed and max_accel must be non-empty and of the same length")
        if not all(math.isfinite(x) and x > 0.0 for x in speed + accel):
            raise ValueError("limits must be finite and positive")
        object.__setattr__(self, "max_speed", speed)
        object.__setattr__(self, "max_accel", accel)

    @classmethod
    def uniform(cls, n_joints: int, speed: float, accel: float) -> MotionLimits:
        """The same limits on ``n_joints`` joints."""
        return cls((speed,) * n_joints, (accel,) * n_joints)

    @property
    def n_joints(self) -> int:
        return len(self.max_speed)

    @property
    def speed(self) -> Vector:
        """Maximum speeds as a (fresh) float64 array."""
        return np.array(self.max_speed, dtype=np.float64)

    @property
    def accel(self) -> Vector:
        """Maximum accelerations as a (fresh) float64 array."""
        return np.array(self.max_accel, dtype=np.float64)

    def scaled(self, speed: float) -> MotionLimits:
        """The limits in force at speed factor ``f``: speeds times ``f``, accelerations times ``f²``."""
        f = _check_speed(speed)
        return MotionLimits(tuple(v * f for v in self.max_speed), tuple(a * f * f for a in self.max_accel))

    def blend_time(self, speed: float = 1.0) -> float:
        """Smallest safe blend half-width τ at speed factor ``f``: ``max_j v_j/(f·a_j)`` seconds."""
        f = _check_speed(speed)
        return max(v / a for v, a in zip(self.max_speed, self.max_accel, strict=True)) / f


PUMA_LIMITS = MotionLimits(
    (60.0, 60.0, 60.0, 120.0, 120.0, 120.0), (200.0, 200.0, 200.0, 400.0, 400.0, 400.0)
)


@dataclass(frozen=True)
class CartesianLimits:
    """Limits for straight-line moves: tool speed (mm/s) and acceleration (mm/s²), and the rate of
    reorientation (deg/s, deg/s²) about the single rotation axis.

    Defaults (:data:`DEFAULT_CARTESIAN_LIMITS`) are assumed values: 250 mm/s and 1000 mm/s² (half the
    0.5 m/s usually quoted for PUMA straight-line motion), 60 deg/s and 200 deg/s².
    """

    max_speed: float = 250.0
    max_accel: float = 1000.0
    max_rot_speed: float = 60.0
    max_rot_accel: float = 200.0

    def __post_init__(self) -> None:
        for name in ("max_speed", "max_accel", "max_rot_speed", "max_rot_accel"):
            x = float(getattr(self, name))
            if not (math.isfinite(x) and x > 0.0):
                raise ValueError(f"{name} must be finite and positive")
            object.__setattr__(self, name, x)


DEFAULT_CARTESIAN_LIMITS = CartesianLimits()
