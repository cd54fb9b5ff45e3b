"""Trajectory generation for the simulated Puma "move process" (sans-I/O, time is always an argument).

Theory of operation
===================

The 1985 Puma-11 ran a *move process* off the 16 ms clock interrupt.  Each servo cycle it computed
the next joint-angle vector by dispatching to the interpolation routine of the segment being executed
(Part II §5.2 of the protocol note): a linear interpolation with quadratic transitions between
segments, a fifth-degree polynomial, a debugging "cosine wave" on one joint, and two compliant
schemes whose nominal path is the linear/quadratic one.  This module reproduces the *nominal* paths.
Nothing here reads a clock or sleeps: every query takes the time ``t`` (seconds) as an argument, and
the only mutable objects (:class:`BlendedPath`, :class:`MoveInterpolator`) change state solely through
explicit calls.  Joint angles are degrees; Cartesian positions millimetres; 4x4 homogeneous matrices
are plain ``numpy`` arrays.

Limits and the speed factor
---------------------------
:class:`MotionLimits` holds a per-joint maximum speed (deg/s) and acceleration (deg/s²).  The
protocol's speed factor ``0 < f <= 1`` (opcode 216) scales **speeds by f and accelerations by f²**
(:meth:`MotionLimits.scaled`).  That is a pure change of time scale ``t -> t/f``: the geometric path
is unchanged and every duration (segment time, blend time) is multiplied by exactly ``1/f``.  Scaling
accelerations by ``f`` instead would make slow moves relatively more abrupt and change the shape of
the blends.

Schemes
-------
* :class:`QuinticSegment` - ``q(t) = q0 + (qf - q0)·s(t/T)`` with ``s(u) = 10u³ - 15u⁴ + 6u⁵``: zero
  velocity and acceleration at both ends.  Peak speed is ``1.875·|Δq|/T`` and peak acceleration
  ``(10/√3)·|Δq|/T²``, so ``T`` is the smallest value meeting both bounds on every joint; the slowest
  joint decides and all joints arrive together (a coordinated move).
* :class:`CosineSegment` - ``q_j(t) = q0_j + A·(1 - cos(2πt/P))/2`` for one joint ``j``, the other
  joints held.  It starts and ends (after whole cycles) at the start angle, at rest.  Debugging only.
* :class:`BlendedPath` - Paul's linear segments with parabolic blends.  Between via points the joints
  move at constant velocity ``V_k = (P_k - P_{k-1})/T_k``; in a window of half-width ``τ`` centred on
  the nominal arrival time ``c_k`` at via ``P_k`` the velocity changes linearly (constant
  acceleration) from the incoming to the outgoing velocity:
  ``q(t) = P + V_in·(t - c) + (V_out - V_in)·(t - c + τ)²/(4τ)``.  The via point is not reached
  exactly (the path passes ``(V_out - V_in)·τ/4`` from it at ``t = c``).  A motion starts from rest
  with the same formula and ``V_in = 0``, and stops with ``V_out = 0``, ending exactly on the goal.
* Compliant schemes - for now the nominal path of :data:`Scheme.LINEAR_BLEND`; the Cougar velocity
  corrections are to be layered on top later.
* :class:`CartesianSegment` - straight-line move between two poses: the position moves along the
  segment and the orientation turns about one fixed axis (angle-axis / slerp), both driven by one
  scalar time-scaling profile (:class:`Profile`: quintic or trapezoidal).  Converting poses to joints
  (inverse kinematics at every tick, TOR/JOR errors) is the caller's job.

Blend time
----------
With ``|V| <= f·v_j`` on every joint, the worst blend reverses a full-speed motion, a velocity
change of ``2·f·v_j`` over ``2τ``.  Choosing ``τ = max_j v_j / (f·a_j)`` therefore keeps every blend
within ``f²·a_j``; it also scales as ``1/f``.  Each segment lasts at least the sum of the half-widths
of the blends at its two ends so that blends never overlap.  The half-width of the blend at a via point
is fixed by the segment *arriving* there (the start of a motion uses the first segment's value), so it
is known when that segment is queued.  When consecutive segments have different speed factors the
acceleration stays within ``max(f_k, f_{k+1})²·a_j``.

Queueing while moving (the late-append rule)
--------------------------------------------
Segments are appended to a :class:`BlendedPath` while the arm moves, each with the time ``now`` at
which it was queued.  The decision for a via point is taken when its blend would begin, at
``c - τ``:

* queued at or before ``c - τ``: the path blends through the via point into the new segment;
* queued later: the arm is already decelerating to rest on the via point.  That deceleration is
  completed unchanged, and the new segment starts from rest at the goal, at ``max(now, c + τ)``.

Either way appending at ``now`` never changes the path at any time ``t <= now``: what the arm has
already been commanded stays valid, and position and velocity remain continuous.  (A query for a time
after ``now`` describes the plan as known so far; the move process samples in increasing time.)

Segment completion
------------------
Every segment carries its protocol segment number.  A segment completes when the blend at its end is
over, at ``c + τ``: for the last segment that is the moment the arm comes to rest on the goal; for a
via segment it is the moment the path settles on the next straight line.  Completion times increase
strictly, so "segment completed" notifications come out in queue order, once each.

The dispatcher
--------------
:class:`MoveInterpolator` is what the server's move process calls: :meth:`MoveInterpolator.enqueue`
takes a :class:`MoveRequest` (scheme, goal, segment number) and :meth:`MoveInterpolator.sample`
returns, for tick time ``t``, the joint vector, whether the arm is idle, and the segments that
completed since the previous call.  Consecutive blend-family segments (linear and both compliant
schemes) share one :class:`BlendedPath` and blend into each other; a quintic or cosine segment starts
from rest once the previous motion has stopped, and the motion after it starts from rest too.
"""

from __future__ import annotations

import bisect
import enum
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_CARTESIAN_LIMITS",
    "PUMA_LIMITS",
    "QUINTIC_PEAK_ACCEL",
    "QUINTIC_PEAK_VELOCITY",
    "TICK",
    "TRAPEZOID_BLEND_FRACTION",
    "BlendedPath",
    "CartesianLimits",
    "CartesianSegment",
    "CosineSegment",
    "JointSegment",
    "MotionLimits",
    "MoveInterpolator",
    "MoveRequest",
    "Profile",
    "QuinticSegment",
    "Scheme",
    "TickSample",
    "ViaPoint",
    "profile_at",
    "quintic_scaling",
    "sample_times",
    "trapezoid_scaling",
]

Vector = NDArray[np.float64]

#: The move process period: the Puma-11 clock interrupt ran every 16 ms.
TICK = 0.016

#: Peak of ds/du and |d²s/du²| of the quintic ``s(u) = 10u³ - 15u⁴ + 6u⁵`` on [0, 1].
QUINTIC_PEAK_VELOCITY = 1.875
QUINTIC_PEAK_ACCEL = 10.0 / math.sqrt(3.0)

#: Fraction of the duration spent accelerating (and again decelerating) in the trapezoidal profile.
#: 1/3 gives a cruise velocity of 1.5x the mean, the usual default for a trapezoidal ("LSPB") profile.
TRAPEZOID_BLEND_FRACTION = 1.0 / 3.0


# ---------------------------------------------------------------------------------------------- helpers
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


# ----------------------------------------------------------------------------------------------- limits
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


# ------------------------------------------------------------------------------ scalar time scalings
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


# ------------------------------------------------------------------------------------ joint segments
class JointSegment(Protocol):
    """What the dispatcher needs from a self-contained segment; ``t`` is relative to its start."""

    @property
    def duration(self) -> float: ...

    def position(self, t: float) -> Vector: ...

    def velocity(self, t: float) -> Vector: ...


class QuinticSegment:
    """Coordinated point-to-point joint move, fifth-degree polynomial in time (scheme QUINTIC).

    ``duration`` is the smallest time in which every joint stays within ``limits.scaled(speed)``
    (optionally rounded up to whole ``tick``\\ s).  Queries take ``t`` in seconds from the segment's
    start and clamp it to ``[0, duration]``.
    """

    __slots__ = ("_delta", "_duration", "_goal", "_start", "limits", "speed")

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

    @property
    def start(self) -> Vector:
        return self._start

    @property
    def goal(self) -> Vector:
        return self._goal

    @property
    def duration(self) -> float:
        return self._duration

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


# ------------------------------------------------------------------------------------ blended path
class ViaPoint(NamedTuple):
    """One knot of a :class:`BlendedPath`, as reported by :attr:`BlendedPath.vias`.

    ``time`` is the nominal arrival time (centre of the blend), ``tau`` the blend half-width;
    ``v_out`` is ``None`` while still undecided (the path then stops there).  ``segment_id`` is the
    segment ending at this via point, ``None`` for the point a motion starts from.
    """

    position: tuple[float, ...]
    time: float
    tau: float
    v_in: tuple[float, ...]
    v_out: tuple[float, ...] | None
    segment_id: int | None

    @property
    def completion_time(self) -> float:
        return self.time + self.tau


@dataclass(slots=True)
class _Via:
    p: Vector
    c: float
    tau: float
    v_in: Vector
    v_out: Vector | None
    segment_id: int | None
    blend_start: float  # stored, not recomputed as c - tau, so a motion starts exactly at its start time

    @property
    def blend_end(self) -> float:
        return self.c + self.tau


class BlendedPath:
    """Linear segments with parabolic blends (Paul), fed incrementally (scheme LINEAR_BLEND).

    See the module docstring for the formula, the blend time and the late-append rule.  The path starts
    at rest on ``start``; :meth:`append` queues a goal, and :meth:`position` / :meth:`velocity` /
    :meth:`acceleration` give the commanded joints at absolute time ``t`` (the same time base as the
    ``now`` given to :meth:`append`).

    ``blend_time`` overrides τ at speed factor 1 (it is still divided by each segment's speed factor);
    it must be at least :meth:`MotionLimits.blend_time` so that accelerations stay within the limits.
    """

    def __init__(
        self,
        start: ArrayLike,
        limits: MotionLimits = PUMA_LIMITS,
        speed: float = 1.0,
        *,
        blend_time: float | None = None,
    ) -> None:
        self.limits = limits
        self.speed = _check_speed(speed)
        self._start = _vector(start, "start", limits.n_joints)
        minimum = limits.blend_time(1.0)
        if blend_time is None:
            self._tau1 = minimum
        else:
            if not (math.isfinite(blend_time) and blend_time >= minimum * (1.0 - 1e-12)):
                raise ValueError(f"blend_time must be >= {minimum} s for these limits, got {blend_time!r}")
            self._tau1 = float(blend_time)
        self._vias: list[_Via] = []
        self._starts: list[float] = []  # blend_start of each via, for bisection
        self._last_now = -math.inf
        self._completions: deque[tuple[float, int]] = deque()

    # -- building
    def _push(self, via: _Via) -> None:
        self._vias.append(via)
        self._starts.append(via.blend_start)

    def append(self, goal: ArrayLike, segment_id: int, now: float, speed: float | None = None) -> float:
        """Queue a move to ``goal``, requested at time ``now``; returns its completion time.

        ``now`` must not decrease from one call to the next.  The path at times ``<= now`` is never
        changed.
        """
        now = _check_time(now, "now")
        if not math.isfinite(now):
            raise ValueError("now must be finite")
        if now < self._last_now:
            raise ValueError(f"append times must not decrease ({now} < {self._last_now})")
        self._last_now = now
        f = self.speed if speed is None else _check_speed(speed)
        p_goal = _vector(goal, "goal", self.limits.n_joints)
        tau = self._tau1 / f
        v_max = self.limits.speed * f

        last = self._vias[-1] if self._vias else None
        if last is not None and last.v_out is None and now <= last.blend_start:
            origin, tau_in, t_origin = last, last.tau, last.c
        else:
            if last is not None:
                # Too late to blend: the stop at ``last`` stands; start again from rest.
                last.v_out = np.zeros_like(last.v_in)
                t0 = max(now, last.blend_end)
                p0 = last.p
            else:
                t0, p0 = now, self._start
            zero = np.zeros_like(p_goal)
            origin = _Via(p0, t0 + tau, tau, zero, None, None, t0)
            self._push(origin)
            tau_in, t_origin = tau, origin.c

        delta = p_goal - origin.p
        duration = max(float(np.max(np.abs(delta) / v_max)), tau_in + tau)
        v = delta / duration
        v.flags.writeable = False
        origin.v_out = v
        arrival_time = t_origin + duration
        arrival = _Via(p_goal, arrival_time, tau, v, None, int(segment_id), arrival_time - tau)
        self._push(arrival)
        self._completions.append((arrival.blend_end, int(segment_id)))
        return arrival.blend_end

    # -- evaluation
    def _locate(self, t: float) -> int:
        """Index of the last via whose blend has started by ``t`` (-1 if none)."""
        return bisect.bisect_right(self._starts, t) - 1

    def _eval(self, t: float) -> tuple[Vector, Vector, Vector]:
        x = _check_time(t)
        zero = np.zeros_like(self._start)
        i = self._locate(x)
        if i < 0:
            p = self._vias[0].p if self._vias else self._start
            return p.copy(), zero, zero
        via = self._vias[i]
        v_out = via.v_out if via.v_out is not None else zero
        dt = x - via.c
        if x >= via.blend_end and not np.any(v_out):
            return via.p.copy(), zero, zero  # at rest on the via point (exactly, not up to rounding)
        if x <= via.blend_end:
            k = x - via.blend_start
            dv = v_out - via.v_in
            pos: Vector = via.p + via.v_in * dt + dv * (k * k / (4.0 * via.tau))
            vel: Vector = via.v_in + dv * (k / (2.0 * via.tau))
            acc: Vector = dv / (2.0 * via.tau)
            return pos, vel, acc
        pos = via.p + v_out * dt
        return pos, v_out.copy(), zero

    def position(self, t: float) -> Vector:
        return self._eval(t)[0]

    def velocity(self, t: float) -> Vector:
        return self._eval(t)[1]

    def acceleration(self, t: float) -> Vector:
        return self._eval(t)[2]

    # -- status
    @property
    def vias(self) -> tuple[ViaPoint, ...]:
        """The knots still held (see :meth:`forget_before`), oldest first."""
        return tuple(
            ViaPoint(
                tuple(float(x) for x in v.p),
                v.c,
                v.tau,
                tuple(float(x) for x in v.v_in),
                None if v.v_out is None else tuple(float(x) for x in v.v_out),
                v.segment_id,
            )
            for v in self._vias
        )

    @property
    def end_time(self) -> float:
        """Time from which the arm rests on the last goal unless more is appended (-inf if idle)."""
        return self._vias[-1].blend_end if self._vias else -math.inf

    @property
    def final_position(self) -> Vector:
        """Where the arm comes to rest if nothing more is appended."""
        return (self._vias[-1].p if self._vias else self._start).copy()

    def done(self, t: float) -> bool:
        """True when every queued segment has completed by ``t`` (the arm is at rest)."""
        return _check_time(t) >= self.end_time

    def completed_by(self, t: float) -> tuple[int, ...]:
        """Ids of not-yet-popped segments whose completion time is ``<= t`` (pure query)."""
        x = _check_time(t)
        return tuple(sid for when, sid in self._completions if when <= x)

    def pop_completed(self, t: float) -> tuple[int, ...]:
        """Like :meth:`completed_by`, but each id is returned only once (in queue order)."""
        x = _check_time(t)
        out: list[int] = []
        while self._completions and self._completions[0][0] <= x:
            out.append(self._completions.popleft()[1])
        return tuple(out)

    def pending(self) -> int:
        """Number of segments not yet popped by :meth:`pop_completed`."""
        return len(self._completions)

    def forget_before(self, t: float) -> None:
        """Drop knots no longer needed for times ``>= t``, to bound memory in long sessions."""
        i = self._locate(_check_time(t))
        if i > 0:
            del self._vias[:i]
            del self._starts[:i]


# ---------------------------------------------------------------------------------- Cartesian moves
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


class CartesianSegment:
    """Straight-line move between two 4x4 poses (mm), with a quintic or trapezoidal time scaling.

    The position follows ``p0 + s·(p1 - p0)``; the orientation is ``R0·Rot(k, s·θ)`` where
    ``Rot(k, θ) = R0ᵀ·R1`` (the single rotation taking the start orientation to the goal's, θ in
    [0°, 180°]).  ``s`` runs from 0 to 1 along :class:`Profile`.  The duration is the smallest that
    keeps the tool speed/acceleration and the rotation rate within ``limits`` scaled by the speed factor
    (f and f²), unless ``duration`` is given explicitly.  This is the slerp form; Paul's drive
    transform visits the same positions but different intermediate orientations.
    """

    __slots__ = ("_angle", "_axis", "_duration", "_goal", "_plain", "_r0", "_start", "profile")

    def __init__(
        self,
        start: ArrayLike,
        goal: ArrayLike,
        limits: CartesianLimits = DEFAULT_CARTESIAN_LIMITS,
        speed: float = 1.0,
        profile: Profile = Profile.QUINTIC,
        *,
        duration: float | None = None,
    ) -> None:
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
    def start(self) -> Vector:
        return self._start

    @property
    def goal(self) -> Vector:
        return self._goal

    @property
    def duration(self) -> float:
        return self._duration

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
        sn, vs = math.sin(s * self._angle), 1.0 - math.cos(s * self._angle)
        # Rodrigues, Rot(k, sθ) = I + sin·K + (1 − cos)·K², then R0·Rot
        rot = [[float(i == j) + sn * k[i][j] + vs * k2[i][j] for j in range(3)] for i in range(3)]
        rows = [
            [*(sum(r0[i][m] * rot[m][j] for m in range(3)) for j in range(3)), p0[i] + s * dp[i]]
            for i in range(3)
        ]
        return np.array([*rows, [0.0, 0.0, 0.0, 1.0]])

    def done(self, t: float) -> bool:
        return _check_time(t) >= self._duration


# ------------------------------------------------------------------------------------------ dispatch
class Scheme(enum.Enum):
    """The move process's five interpolation schemes (Part II §5.2)."""

    LINEAR_BLEND = "linear-blend"
    QUINTIC = "quintic"
    COSINE = "cosine"
    COMPLIANT_DEBUG = "compliant-debug"
    COMPLIANT_MOTION = "compliant-motion"

    @property
    def blends(self) -> bool:
        """True for the schemes whose (nominal) path is linear with parabolic blends."""
        return self in (Scheme.LINEAR_BLEND, Scheme.COMPLIANT_DEBUG, Scheme.COMPLIANT_MOTION)

    @property
    def compliant(self) -> bool:
        return self in (Scheme.COMPLIANT_DEBUG, Scheme.COMPLIANT_MOTION)


@dataclass(frozen=True)
class MoveRequest:
    """One queued motion segment ("move packet").

    ``goal`` is the joint vector (degrees) for every scheme but COSINE, which uses ``joint`` (0-based),
    ``amplitude`` (deg), ``period`` (s) and ``cycles`` instead.  ``speed`` overrides the interpolator's
    speed factor for this segment (a cosine segment's timing is its period: no speed factor applies).
    """

    segment_id: int
    scheme: Scheme
    goal: tuple[float, ...] = ()
    speed: float | None = None
    joint: int = 0
    amplitude: float = 0.0
    period: float = 1.0
    cycles: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "goal", tuple(float(x) for x in self.goal))
        if self.scheme is Scheme.COSINE:
            if not (math.isfinite(self.period) and self.period > 0.0 and self.cycles >= 1):
                raise ValueError("a cosine segment needs period > 0 and cycles >= 1")
        elif not self.goal:
            raise ValueError(f"a {self.scheme.value} segment needs a goal")
        if self.speed is not None:
            _check_speed(self.speed)

    @classmethod
    def to(
        cls,
        segment_id: int,
        goal: Sequence[float],
        scheme: Scheme = Scheme.LINEAR_BLEND,
        speed: float | None = None,
    ) -> MoveRequest:
        """A move to joint angles ``goal``."""
        return cls(segment_id, scheme, tuple(goal), speed)

    @classmethod
    def cosine(
        cls, segment_id: int, joint: int, amplitude: float, period: float, cycles: int = 1
    ) -> MoveRequest:
        """A cosine-wave debugging segment on one joint."""
        return cls(segment_id, Scheme.COSINE, (), None, joint, amplitude, period, cycles)


class TickSample(NamedTuple):
    """What one servo cycle gets from :meth:`MoveInterpolator.sample`.

    ``done`` is True when the arm is at rest with nothing queued; ``completed`` lists the segments that
    completed since the previous sample (queue order); ``segment``/``scheme`` describe the segment being
    executed (the oldest not yet completed), ``None`` when idle.
    """

    joints: Vector
    done: bool
    completed: tuple[int, ...]
    segment: int | None
    scheme: Scheme | None


@dataclass
class _Timed:
    """A self-contained segment running from absolute time ``t0``."""

    segment: JointSegment
    t0: float

    @property
    def end(self) -> float:
        return self.t0 + self.segment.duration


@dataclass
class _Queued:
    request: MoveRequest
    speed: float
    at: float


class MoveInterpolator:
    """The move process's dispatcher: queue of move packets in, one joint vector per tick out.

    Call :meth:`enqueue` when a motion request is accepted and :meth:`sample` on every tick; times are
    absolute seconds and must not decrease across calls.  Blend-family segments (LINEAR_BLEND and the
    compliant schemes) queued back to back blend into one another through a shared
    :class:`BlendedPath` (with its late-append rule); QUINTIC and COSINE segments run from rest to rest,
    starting when the previous motion has stopped.  Range checking of goals is the caller's job.
    """

    def __init__(self, start: ArrayLike, limits: MotionLimits = PUMA_LIMITS, speed: float = 1.0) -> None:
        self.limits = limits
        self.speed = _check_speed(speed)
        self._rest = _vector(start, "start", limits.n_joints)
        self._free_at = -math.inf
        self._clock = -math.inf
        self._active: _Timed | BlendedPath | None = None
        self._pending: deque[_Queued] = deque()
        self._inflight: deque[tuple[int, Scheme]] = deque()
        self._backlog: list[int] = []  # completions found by abort(), reported by the next sample()

    # -- inputs
    def set_speed(self, speed: float) -> None:
        """Opcode 216: the speed factor for segments queued from now on."""
        self.speed = _check_speed(speed)

    def _tick(self, t: float) -> float:
        x = _check_time(t)
        if not math.isfinite(x):
            raise ValueError("time must be finite")
        if x < self._clock:
            raise ValueError(f"time went backwards ({x} < {self._clock})")
        self._clock = x
        return x

    def enqueue(self, request: MoveRequest, now: float) -> None:
        """Queue ``request`` at time ``now`` (the move packet joins the move process's queue)."""
        now = self._tick(now)
        if request.scheme is not Scheme.COSINE and len(request.goal) != self.limits.n_joints:
            raise ValueError(f"goal has {len(request.goal)} joints, expected {self.limits.n_joints}")
        if request.scheme is Scheme.COSINE and not 0 <= request.joint < self.limits.n_joints:
            raise ValueError(f"joint index {request.joint} out of range")
        speed = self.speed if request.speed is None else request.speed
        if isinstance(self._active, BlendedPath) and request.scheme.blends and not self._pending:
            self._active.append(request.goal, request.segment_id, now, speed)
            self._inflight.append((request.segment_id, request.scheme))
        else:
            self._pending.append(_Queued(request, speed, now))

    # -- the servo cycle
    def _position(self, t: float) -> Vector:
        if isinstance(self._active, BlendedPath):
            return self._active.position(t)
        if isinstance(self._active, _Timed):
            return self._active.segment.position(t - self._active.t0)
        return self._rest.copy()

    def _collect(self, t: float, out: list[int]) -> None:
        if isinstance(self._active, BlendedPath):
            ids = self._active.pop_completed(t)
            self._active.forget_before(t)
            for sid in ids:
                out.append(sid)
                self._inflight.popleft()
        elif isinstance(self._active, _Timed) and t >= self._active.end:
            out.append(self._inflight.popleft()[0])

    def _start_next(self) -> None:
        item = self._pending.popleft()
        req, t0 = item.request, max(self._free_at, item.at)
        self._inflight.append((req.segment_id, req.scheme))
        if req.scheme.blends:
            path = BlendedPath(self._rest, self.limits, item.speed)
            path.append(req.goal, req.segment_id, t0, item.speed)
            while self._pending and self._pending[0].request.scheme.blends:
                nxt = self._pending.popleft()
                path.append(nxt.request.goal, nxt.request.segment_id, max(t0, nxt.at), nxt.speed)
                self._inflight.append((nxt.request.segment_id, nxt.request.scheme))
            self._active = path
        elif req.scheme is Scheme.QUINTIC:
            self._active = _Timed(QuinticSegment(self._rest, req.goal, self.limits, item.speed), t0)
        else:
            seg = CosineSegment(self._rest, req.joint, req.amplitude, req.period, req.cycles)
            self._active = _Timed(seg, t0)

    def _advance(self, t: float) -> list[int]:
        completed: list[int] = []
        while True:
            if self._active is not None:
                self._collect(t, completed)
                if isinstance(self._active, BlendedPath):
                    finished = bool(self._pending) and self._active.done(t)
                    end, final = self._active.end_time, self._active.final_position
                else:
                    finished = t >= self._active.end
                    end = self._active.end
                    final = self._active.segment.position(self._active.segment.duration)
                if not finished:
                    break
                self._rest, self._free_at, self._active = final, end, None
            if not self._pending:
                break
            self._start_next()
        return completed

    def sample(self, t: float) -> TickSample:
        """The commanded joints at tick time ``t`` and the segments completed since the last call."""
        t = self._tick(t)
        completed = [*self._backlog, *self._advance(t)]
        self._backlog.clear()
        if isinstance(self._active, BlendedPath):
            idle = self._active.done(t) and not self._pending
        else:
            idle = self._active is None and not self._pending
        current = self._inflight[0] if self._inflight else (None, None)
        return TickSample(self._position(t), idle, tuple(completed), current[0], current[1])

    def abort(self, t: float) -> tuple[int, ...]:
        """Stop where the arm is at ``t`` (power failure, panic button) and drop every queued segment.

        Returns the ids of the segments abandoned (in execution, then queued), which will never be
        reported as completed.
        """
        t = self._tick(t)
        self._backlog.extend(self._advance(t))  # finished by ``t``: reported by the next sample()
        here = self._position(t)
        dropped = tuple(sid for sid, _ in self._inflight) + tuple(q.request.segment_id for q in self._pending)
        self._inflight.clear()
        self._pending.clear()
        self._active = None
        self._rest, self._free_at = here, t
        return dropped

    # -- status
    @property
    def queued(self) -> int:
        """Segments accepted but not yet completed (executing or waiting)."""
        return len(self._inflight) + len(self._pending)
