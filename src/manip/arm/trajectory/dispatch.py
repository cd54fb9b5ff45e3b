"""The move process's dispatcher: move requests queued in, one joint vector per servo tick out.

Part of :mod:`manip.arm.trajectory` (its docstring says how consecutive schemes follow one another).
"""

from __future__ import annotations

import enum
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

from numpy.typing import ArrayLike

from manip.arm.trajectory.blended import BlendedPath
from manip.arm.trajectory.joint import CosineSegment, JointSegment, QuinticSegment
from manip.arm.trajectory.limits import PUMA_LIMITS, MotionLimits, Vector, _check_speed, _check_time, _vector


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
