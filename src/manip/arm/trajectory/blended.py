"""Linear segments with parabolic blends, fed while the arm moves (the late-append rule).

Part of :mod:`manip.arm.trajectory` (its docstring gives the formula, the blend time and the rule).
"""

from __future__ import annotations

import bisect
import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from manip.arm.trajectory.limits import PUMA_LIMITS, MotionLimits, Vector, _check_speed, _check_time, _vector


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

    See :mod:`manip.arm.trajectory` for the formula, the blend time and the late-append rule.  The path starts
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
