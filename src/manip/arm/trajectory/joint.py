"""Self-contained joint segments, from rest to rest: the quintic move and the debugging cosine wave.

Part of :mod:`manip.arm.trajectory` (its docstring gives their formulas).
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from manip.arm.trajectory.ends import SegmentEnds
from manip.arm.trajectory.limits import PUMA_LIMITS, MotionLimits, Vector, _check_speed, _check_time, _vector
from manip.arm.trajectory.scaling import Profile, quintic_scaling


class JointSegment(Protocol):
    """What the dispatcher needs from a self-contained segment; ``t`` is relative to its start."""

    @property
    def duration(self) -> float: ...

    def position(self, t: float) -> Vector: ...

    def velocity(self, t: float) -> Vector: ...


class QuinticSegment(SegmentEnds):
    """Coordinated point-to-point joint move, fifth-degree polynomial in time (scheme QUINTIC).

    ``duration`` is the smallest time in which every joint stays within ``limits.scaled(speed)``
    (optionally rounded up to whole ``tick``\\ s).  Queries take ``t`` in seconds from the segment's
    start and clamp it to ``[0, duration]``.
    """

    __slots__ = ("_delta", "limits", "speed")

    def __init__(
        self,
        start: ArrayLike,
        goal: ArrayLike,
        limits: MotionLimits = PUMA_LIMITS,
        speed: float = 1.0,
        *,
        tick: float | None = None,
    ) -> None:
        self.limits = limits
        self.speed = _check_speed(speed)
        self._start = _vector(start, "start", limits.n_joints)
        self._goal = _vector(goal, "goal", limits.n_joints)
        self._delta = self._goal - self._start
        scaled = limits.scaled(self.speed)
        duration = max(
            Profile.QUINTIC.duration(float(d), v, a)
            for d, v, a in zip(self._delta, scaled.max_speed, scaled.max_accel, strict=True)
        )
        if tick is not None and duration > 0.0:
            if not tick > 0.0:
                raise ValueError("tick must be positive")
            duration = math.ceil(duration / tick - 1e-9) * tick
        self._duration = duration

    def _scaling(self, t: float) -> tuple[float, float, float]:
        if self._duration == 0.0:
            return 1.0, 0.0, 0.0
        return quintic_scaling(_check_time(t) / self._duration)

    def position(self, t: float) -> Vector:
        s, _, _ = self._scaling(t)
        if s >= 1.0:
            return self._goal.copy()
        out: Vector = self._start + self._delta * s
        return out

    def velocity(self, t: float) -> Vector:
        _, ds, _ = self._scaling(t)
        if ds == 0.0:
            return np.zeros_like(self._delta)
        out: Vector = (self._delta / self._duration) * ds  # this order cannot overflow for tiny moves
        return out

    def acceleration(self, t: float) -> Vector:
        _, _, dds = self._scaling(t)
        if dds == 0.0:
            return np.zeros_like(self._delta)
        out: Vector = (self._delta / self._duration / self._duration) * dds
        return out

    def done(self, t: float) -> bool:
        return _check_time(t) >= self._duration


class CosineSegment:
    """Debugging scheme: one joint follows a cosine, the others hold (scheme COSINE).

    ``q_j(t) = q0_j + amplitude·(1 - cos(2π·t/period))/2`` for ``0 <= t <= period·cycles``: the joint
    swings from its start angle to ``start + amplitude`` and back ``cycles`` times, starting and ending
    at rest on the start angle.  ``joint`` is 0-based.  No limit checking is done (this scheme is for
    debugging); :attr:`peak_velocity` and :attr:`peak_accel` let a caller check.
    """

    __slots__ = ("_start", "amplitude", "cycles", "joint", "period")

    def __init__(
        self, start: ArrayLike, joint: int, amplitude: float, period: float, cycles: int = 1
    ) -> None:
        self._start = _vector(start, "start")
        if not 0 <= joint < self._start.shape[0]:
            raise ValueError(f"joint index {joint} out of range for {self._start.shape[0]} joints")
        if not (math.isfinite(amplitude) and math.isfinite(period) and period > 0.0):
            raise ValueError("amplitude must be finite and period finite and positive")
        if cycles < 1:
            raise ValueError("cycles must be a positive integer")
        self.joint = int(joint)
        self.amplitude = float(amplitude)
        self.period = float(period)
        self.cycles = int(cycles)

    @property
    def start(self) -> Vector:
        return self._start

    @property
    def duration(self) -> float:
        return self.period * self.cycles

    @property
    def peak_velocity(self) -> float:
        """``|A|·π/P`` deg/s."""
        return abs(self.amplitude) * math.pi / self.period

    @property
    def peak_accel(self) -> float:
        """``|A|·2π²/P²`` deg/s² (reached at the start and end: the acceleration jumps there)."""
        return abs(self.amplitude) * 2.0 * math.pi**2 / self.period**2

    def _phase(self, t: float) -> float | None:
        x = _check_time(t)
        if x <= 0.0 or x >= self.duration:
            return None
        return 2.0 * math.pi * x / self.period

    def position(self, t: float) -> Vector:
        out = self._start.copy()
        w = self._phase(t)
        if w is not None:
            out[self.joint] += self.amplitude * 0.5 * (1.0 - math.cos(w))
        return out

    def velocity(self, t: float) -> Vector:
        out = np.zeros_like(self._start)
        w = self._phase(t)
        if w is not None:
            out[self.joint] = self.amplitude * math.pi / self.period * math.sin(w)
        return out

    def acceleration(self, t: float) -> Vector:
        out = np.zeros_like(self._start)
        w = self._phase(t)
        if w is not None:
            out[self.joint] = self.amplitude * 2.0 * math.pi**2 / self.period**2 * math.cos(w)
        return out

    def done(self, t: float) -> bool:
        return _check_time(t) >= self.duration
