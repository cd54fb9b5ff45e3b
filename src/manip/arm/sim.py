"""The simulated Puma arm and its move process (sans-I/O: time is always an argument).

Theory of operation
===================

On the 1985 Puma-11 the *move process* was the 16 ms clock interrupt (Part II §5.2).  Each servo cycle it
checked that the arm had reached the angles commanded on the previous cycle (the collision test),
computed the next joint-angle vector with the interpolation routine of the segment being run, and sent it
to the Unimation controller.  The main process checked motion requests at once, queued them as *move
packets* and answered with a segment number before any motion happened (§5.1, §6.2).

:class:`ArmSim` plays both the arm and the move process for one connection:

* **Requests** (:meth:`ArmSim.move_joints`, :meth:`ArmSim.move_to`, :meth:`ArmSim.move_increment`,
  :meth:`ArmSim.move_ready`, :meth:`ArmSim.move_cosine`) are checked at once and either raise
  :class:`Refused` (carrying the protocol error code: AWA, NAP, SQF, JOR, TOR, BVA) or queue a segment
  and return its number.  Numbers come from a per-connection counter that starts at 1 and grows by one
  per queued segment, modulo 2^16 (erratum ``segment-numbers``).
* **Goals are planned from the end of the queue**, not from where the arm is now: a move queued behind
  others starts where they end, so inverse kinematics picks the solution nearest *that* configuration and
  incremental moves add to *that* pose.
* **Time** enters only through :meth:`ArmSim.tick`.  Servo cycles run at ``epoch + k·TICK``; a call runs
  every cycle due up to ``now`` (while the arm is idle the cycles in between are skipped, since they
  change nothing).  The caller must bring the arm up to date (``tick(now)``) before a request at ``now``.
* **Interpolation**: joint moves go to :class:`~manip.arm.trajectory.MoveInterpolator` (linear with
  parabolic blends by default, quintic on request, the cosine debugging wave, and the compliant schemes
  whose nominal path is the blended one).  Straight-line moves
  (:class:`~manip.arm.trajectory.CartesianSegment`) are checked when queued at evenly spaced points of
  the line, each solved nearest the previous one, so a line that leaves the workspace, breaks a joint
  limit or passes through a singularity is refused at once (TOR: every refusal of a transform is TOR,
  JOR is for joint angles; erratum ``transform-refusals``).  The points are a few millimetres
  apart, closer where a joint moves fast, and at most :data:`MAX_LINE_CHECKS`: the work is bounded
  whatever the distance and the speed factor (erratum ``motion-planning-bounds``).  The move process
  then solves the line's pose on every cycle as it runs, nearest the previous cycle's angles, and falls
  back on the checked path where that fails.  Segments queued behind a straight-line move wait until it
  ends, then start from rest.
* **The arm**: the actual angles follow the commanded ones, except where an :class:`Obstacle` stops a
  joint.  The collision test compares the actual angles with those commanded on the previous cycle; a
  joint off by more than ``collision_tol_deg`` (the freed joint excepted, and never under a compliant
  scheme, as on the Puma) stops the arm where it is.
* **Aborts**: a collision, the panic button (which cuts arm power) or arm power lost while segments are
  in flight stop the arm, drop the current and queued segments and emit :class:`MotionAborted`; from
  then on motion is refused with AWA until :meth:`ArmSim.reset_abort` or :meth:`ArmSim.enable_power`
  (erratum ``abort-reset``).
* **Events** out of :meth:`ArmSim.tick`: :class:`SegmentCompleted` (in queue order, once each),
  :class:`MotionAborted`, and :class:`FollowingWarning` when a joint lags by more than half the
  collision tolerance (once per episode).

Compliance (erratum ``compliant-segment-end``)
----------------------------------------------
A :class:`Compliance` object (the Puma's wrist processes and Cougar) turns the nominal commanded angles
of each cycle of a compliant segment into the compliant ones; the *correction* is their difference.
Consecutive compliant segments share one blended path and one correction (a compliant episode).  When
the episode ends -- on the cycle its last segment completes -- the correction then in force is kept:
the arm stays where the contact let it go, short of (or past) the nominal goal, instead of snapping back
to it.  Segments queued behind a compliant one that are not compliant themselves wait in the backlog
(they do not blend into it) and are handed to a fresh interpolator that starts, at rest, from where
compliance left the arm: their *start* is rebased, their goals stay what they were (absolute goals,
or increments resolved from the pose planned when they were queued).  A straight-line move right behind
a compliant episode is solved again from there, or, if the line can no longer be followed from there,
its planned path is shifted by the correction fading linearly to zero along the line.  Either way the
commanded angles never jump: each cycle moves them by at most one tick of nominal motion plus the
compliance correction made on that cycle.  With nothing queued the arm rests where compliance left it
and later moves are planned from there.
"""

from __future__ import annotations

import bisect
import enum
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Final, Protocol

import numpy as np

from manip.arm.kinematics import (
    PUMA600,
    ArmModel,
    Joints,
    JointsLike,
    KinematicsError,
    OutOfRange,
    Unreachable,
    forward,
    inverse_all,
    nearest_solution,
    within_limits,
)
from manip.arm.oat import apply_increment, xyzoat_from_transform
from manip.arm.trajectory import (
    DEFAULT_CARTESIAN_LIMITS,
    PUMA_LIMITS,
    TICK,
    CartesianLimits,
    CartesianSegment,
    MotionLimits,
    MoveInterpolator,
    MoveRequest,
    Scheme,
)
from manip.arm.transform import Transform
from manip.codecs.pdp11float import F_MIN_NORMAL

__all__ = [
    "COLLISION_TOL_DEG",
    "LINE_CHECK_DEG",
    "LINE_CHECK_MM",
    "MAX_LINE_CHECKS",
    "MAX_QUEUE",
    "MIN_SPEED_FACTOR",
    "REFINE_DEPTH",
    "SEGMENT_MODULUS",
    "STRAIGHT_JUMP_DEG",
    "AbortCause",
    "ArmDefects",
    "ArmEvent",
    "ArmSim",
    "Compliance",
    "FollowingWarning",
    "MotionAborted",
    "Obstacle",
    "Refused",
    "SegmentCompleted",
    "Sluggish",
]

#: Default collision tolerance (deg): how far a joint may be from the angle commanded on the previous cycle.
COLLISION_TOL_DEG: Final = 0.5
#: Default limit on segments accepted but not completed; one more is refused with SQF.
MAX_QUEUE: Final = 64
#: Segment numbers are words.
SEGMENT_MODULUS: Final = 1 << 16
#: Largest change of any joint between two neighbouring points a straight-line move is checked at
#: (deg).  A bigger step is looked at more closely (the gap is halved); one that does not shrink means
#: the line passes through a singularity, where no smooth joint motion follows it: TOR.  On playback a
#: cycle never strays further than this from the checked path.
STRAIGHT_JUMP_DEG: Final = 5.0
#: Largest gap (mm of travel, degrees of turn) between the points a straight-line move is checked at
#: when queued, before halving (erratum ``motion-planning-bounds``).
LINE_CHECK_MM: Final = 8.0
LINE_CHECK_DEG: Final = 2.0
#: How many times such a gap may be halved where a joint moves fast; a joint that still jumps by more
#: than STRAIGHT_JUMP_DEG across 1/2^REFINE_DEPTH of a gap (1/8 mm) marks a singularity.
REFINE_DEPTH: Final = 6
#: Most points a straight-line move is solved at when queued, besides its goal: a PUMA 600 line, at most
#: ~1.7 m long between two reachable poses, has at most ~215 gaps; the rest is for halving.  Lines
#: needing more are refused (TOR).
MAX_LINE_CHECKS: Final = 384
#: Smallest speed factor accepted: the smallest PDP-11 float, so no factor from the protocol is refused,
#: while f² (which scales accelerations) stays a normal double and every duration stays finite.
MIN_SPEED_FACTOR: Final = F_MIN_NORMAL
_EPS: Final = 1e-9
#: A straight-line move starting within this of where it was planned from (deg) is played as planned.
_SAME_START_DEG: Final = 1e-6


# ---------------------------------------------------------------------------------------- refusals
class Refused(Exception):  # noqa: N818 -- a refusal is an answer, not a failure of the simulator
    """A request the arm will not carry out; ``code`` is the protocol error code to answer with.

    ``joints`` (1-based) go into the error's ``$`` mask (JOR, and TOR when a transform's solutions break
    limits); ``detail`` is for humans.
    """

    def __init__(self, code: str, detail: str, joints: Sequence[int] = ()) -> None:
        super().__init__(f"{code}: {detail}")
        self.code = code
        self.detail = detail
        self.joints = tuple(joints)


# ------------------------------------------------------------------------------------------ events
class AbortCause(enum.Enum):
    """Why the move process aborted motion."""

    COLLISION = "collision"
    PANIC = "panic"
    POWER_LOST = "power-lost"
    GUARD = "guard"
    """A wrist guard of the stop-the-move type tripped (:meth:`ArmSim.halt`)."""


@dataclass(frozen=True, slots=True)
class SegmentCompleted:
    """Segment ``segment`` finished at servo time ``time``."""

    segment: int
    time: float


@dataclass(frozen=True, slots=True)
class MotionAborted:
    """Motion stopped at ``time``; ``joints`` are the colliding joints (1-based, empty otherwise) and
    ``dropped`` the segments abandoned (never to complete), in execution order."""

    cause: AbortCause
    time: float
    joints: tuple[int, ...]
    dropped: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class FollowingWarning:
    """Joints (1-based) lagging the commanded angles by more than half the collision tolerance."""

    time: float
    joints: tuple[int, ...]


ArmEvent = SegmentCompleted | MotionAborted | FollowingWarning


# --------------------------------------------------------------------------------- the environment
@dataclass(frozen=True)
class Obstacle:
    """Something in the way of joint ``joint`` (1-based): the actual angle cannot go below ``lower`` or
    above ``upper`` (deg; ``None`` = no bound on that side), whatever is commanded."""

    joint: int
    lower: float | None = None
    upper: float | None = None

    def __post_init__(self) -> None:
        if not 1 <= self.joint <= 6:
            raise ValueError(f"obstacle joint must be 1..6, got {self.joint}")
        if self.lower is None and self.upper is None:
            raise ValueError("an obstacle needs a lower or an upper bound")
        if self.lower is not None and self.upper is not None and not self.lower < self.upper:
            raise ValueError("obstacle lower bound must be below its upper bound")

    def clamp(self, q: Joints) -> Joints:
        """The angles the arm actually reaches when ``q`` is commanded."""
        v = list(q)
        i = self.joint - 1
        if self.lower is not None:
            v[i] = max(v[i], self.lower)
        if self.upper is not None:
            v[i] = min(v[i], self.upper)
        return _joints(v)


@dataclass(frozen=True)
class Sluggish:
    """Joint ``joint`` (1-based) trails its command by ``lag`` degrees on every cycle its command moves
    (at most by the step commanded) and reaches it once the command stands still: a joint that follows,
    but late (a worn drive).  A lag above half the collision tolerance and within it draws a
    :class:`FollowingWarning` and nothing more."""

    joint: int
    lag: float

    def __post_init__(self) -> None:
        if not 1 <= self.joint <= 6:
            raise ValueError(f"sluggish joint must be 1..6, got {self.joint}")
        if not (math.isfinite(self.lag) and self.lag > 0.0):
            raise ValueError("the lag must be a positive number of degrees")

    def follow(self, previous: Joints, q: Joints) -> Joints:
        """The angles reached when ``q`` is commanded after ``previous`` was."""
        v = list(q)
        i = self.joint - 1
        step = v[i] - previous[i]
        if step:
            v[i] -= math.copysign(min(self.lag, abs(step)), step)
        return _joints(v)


class Compliance(Protocol):
    """Seam for the compliant schemes: turns the nominal commanded angles into the compliant ones.

    Called once per servo cycle while a compliant segment runs, with the cycle time, the nominal angles
    of the blended path and the angles the arm actually reached (the Puma side of Cougar,
    :class:`~manip.reference_server.cougar_wrist.CougarWrist`, is one).  Without one the compliant
    schemes follow their nominal path.  What happens to the correction when the segment ends: see the
    module docstring.
    """

    def adjust(self, t: float, nominal: Joints, actual: Joints) -> Joints: ...


# ----------------------------------------------------------------------------------- move packets
@dataclass(frozen=True)
class _JointPacket:
    request: MoveRequest


@dataclass(frozen=True)
class _Checked:
    """The solutions ``solved`` of a straight line at the points ``at`` (path parameters from 0 to 1,
    increasing) it was checked at; the first is where it starts, the last the solution at the goal."""

    at: tuple[float, ...]
    solved: tuple[Joints, ...]

    def along(self, s: float) -> Joints:
        """The checked path at ``s``: joint-interpolated between the neighbouring points."""
        i = min(max(bisect.bisect_right(self.at, s), 1), len(self.at) - 1)
        s_a, s_b = self.at[i - 1], self.at[i]
        f = min(max((s - s_a) / (s_b - s_a), 0.0), 1.0)
        return _joints([a + (b - a) * f for a, b in zip(self.solved[i - 1], self.solved[i], strict=True)])


@dataclass(frozen=True)
class _PathPacket:
    """A straight-line move from ``start``: ``line`` (its geometry and timing) and ``checked``, its
    solutions where it was checked.  ``offset`` (a start shifted behind a compliant episode) fades to
    zero along the line."""

    segment: int
    line: CartesianSegment
    checked: _Checked
    start: Joints
    goal: Transform
    speed: float
    offset: Joints | None = None

    @property
    def end(self) -> Joints:
        return self.checked.solved[-1]


@dataclass
class _Playback:
    """A straight-line move being run: ``done`` of its ``ticks`` servo cycles, ``previous`` the
    solution of the last one (without the offset)."""

    packet: _PathPacket
    ticks: int
    previous: Joints
    done: int = 0


def _joints(v: Sequence[float] | np.ndarray) -> Joints:
    return (float(v[0]), float(v[1]), float(v[2]), float(v[3]), float(v[4]), float(v[5]))


def _sq_distance(a: Sequence[float], b: Sequence[float]) -> float:
    return sum((x - y) ** 2 for x, y in zip(a, b, strict=True))


# --------------------------------------------------------------------------------------------- arm
@dataclass
class _KeptQueue:
    """The joint segments a faulty server keeps through an abort (``ArmDefects.keep_queue_on_abort``)."""

    queued: dict[int, MoveRequest] = field(default_factory=dict)
    """Joint segments queued, by id."""
    kept: list[MoveRequest] = field(default_factory=list)
    """Those an abort kept, to run once motion is allowed again."""


@dataclass(frozen=True)
class ArmDefects:
    """How a faulty server's move process departs from Part II of the 1985 guide; the defaults are the
    guide's (no defect).  The reference server's fault switches choose them
    (:mod:`manip.reference_server.defects`); an :class:`ArmSim` is given them when it is made."""

    enforce_power: bool = True
    """Refuse motion without arm power (NAP)."""
    enforce_abort: bool = True
    """Refuse motion after an abort (AWA)."""
    power_resets_abort: bool = True
    """Enable high power clears an abort (erratum ``abort-reset``; False: only Reset abort does)."""
    collision_test: bool = True
    """Compare the actual angles with those commanded (False: no collision is ever seen)."""
    collision_test_compliant: bool = False
    """Run the collision test under compliance too (Part II §5.2 inhibits it)."""
    hold_compliant_end: bool = True
    """End a compliant episode where compliance left the arm (False snaps back to the nominal goal)."""
    increment_from_actual: bool = False
    """Resolve incremental moves from where the arm stands, not where the queue ends."""
    stop_between_segments: float | None = None
    """Seconds to rest between queued joint segments instead of blending them (None: they blend, Part II
    §5.1)."""
    reverse_waiting: bool = False
    """Run the segments waiting behind the running one newest first (with :attr:`stop_between_segments`:
    the segments then run one at a time)."""
    keep_queue_on_abort: bool = False
    """An abort drops only the segment in execution, and the queued ones run once motion is allowed
    again (Part II §6.2 drops them all)."""
    segment_step: int = 1
    """The increment of the segment counter."""
    servo_rate: float = 1.0
    """Servo cycles per period of the clock (2: the servo runs twice as fast)."""
    command_lead: float = 0.0
    """Servo cycles of the path's velocity added to each command (0: the path as interpolated; more runs
    the arm ahead of its path, and past a goal before it settles there)."""
    turn_share: float = 1.0
    """The share of a straight line's way over which the hand turns to the goal's orientation (1: all the
    way, with the position; less turns it ahead of the position and carries it unturned the rest of the
    line)."""


class ArmSim:
    """One connection's simulated arm and move process.  See the module docstring.

    ``start`` is where the arm stands (default: the model's ready position); ``powered`` whether arm
    power is on at the start (off by default, as on a freshly connected Puma: Enable high power first).
    ``defects`` are a faulty server's (none by default).
    """

    def __init__(
        self,
        model: ArmModel = PUMA600,
        limits: MotionLimits = PUMA_LIMITS,
        *,
        start: JointsLike | None = None,
        powered: bool = False,
        tick_period: float = TICK,
        scheme: Scheme = Scheme.LINEAR_BLEND,
        cartesian_limits: CartesianLimits = DEFAULT_CARTESIAN_LIMITS,
        collision_tol_deg: float = COLLISION_TOL_DEG,
        max_queue: int = MAX_QUEUE,
        compliance: Compliance | None = None,
        defects: ArmDefects | None = None,
    ) -> None:
        if scheme is Scheme.COSINE:
            raise ValueError("the cosine scheme needs its own parameters; use move_cosine")
        if not (math.isfinite(tick_period) and tick_period > 0.0):
            raise ValueError("tick_period must be finite and positive")
        self.model = model
        self.limits = limits
        self.defects = defects = defects or ArmDefects()
        self.tick_period = float(tick_period) / defects.servo_rate
        self.scheme = scheme
        self.cartesian_limits = cartesian_limits
        self.collision_tol_deg = float(collision_tol_deg) if defects.collision_test else math.inf
        self.max_queue = int(max_queue)
        self.compliance = compliance

        here = _joints(model.ready if start is None else start)
        self.commanded: Joints = here
        """Angles sent to the controller on the last servo cycle."""
        self._path_before: Joints | None = None
        """The path's angles on the last servo cycle (with :attr:`ArmDefects.command_lead` only)."""
        self.actual: Joints = here
        """Angles the arm actually reached (the sensed angles)."""
        self.powered = bool(powered)
        self.aborted = False
        self.abort_cause: AbortCause | None = None
        self.speed = 1.0
        self.lefty: bool | None = None
        """Configuration preference from Set configuration (None until set)."""
        self.hand_open = True
        self.free_joint: int | None = None
        self.obstacle: Obstacle | None = None
        self.sluggish: Sluggish | None = None
        """A joint that trails its command (a condition of the arm's world)."""
        self._resting_since: float | None = None
        self._kept = _KeptQueue()

        self._next_segment = 1
        self._interp = MoveInterpolator(here, limits, 1.0)
        self._backlog: deque[_JointPacket | _PathPacket] = deque()
        self._playback: _Playback | None = None
        self._planned: Joints = here
        self._planned_oat: tuple[float, float, float] | None = None
        self._scheme_now: Scheme | None = None
        self._correction: Joints | None = None
        """Compliant minus nominal angles on the last compliant cycle of the running episode."""
        self._compliant_tail = False
        """The interpolator's last segment is compliant: segments that are not wait in the backlog."""
        self._lag_warned = False
        self._panic_at: float | None = None
        self._epoch: float | None = None
        self._cycle = 0  # index of the next servo cycle
        self._clock = -math.inf

    # ------------------------------------------------------------------------------------ status
    @property
    def time(self) -> float:
        """Time of the last servo cycle run (-inf before the first)."""
        return self._clock

    @property
    def queued(self) -> int:
        """Segments accepted and not yet completed (running or waiting)."""
        running = 1 if self._playback is not None else 0
        return self._interp.queued + len(self._backlog) + running

    @property
    def moving(self) -> bool:
        """True while any segment is running or waiting."""
        return self.queued > 0

    @property
    def planned(self) -> Joints:
        """Where the arm will stand once every queued segment has run."""
        return self._planned

    @property
    def next_segment(self) -> int:
        """The number the next queued segment will get."""
        return self._next_segment

    def pose(self) -> Transform:
        """The transform of the actual angles (what Here reports)."""
        return forward(self.actual, self.model.geometry)

    # ----------------------------------------------------------------------------- power, abort
    def enable_power(self) -> None:
        """Arm power on; also clears an abort (erratum ``abort-reset``)."""
        self.powered = True
        if self.defects.power_resets_abort:
            self.reset_abort()

    def kill_power(self) -> None:
        """Arm power off.  Segments in flight are aborted on the next servo cycle (cause POWER_LOST)."""
        self.powered = False

    def reset_abort(self) -> None:
        """Accept motion requests again after an abort."""
        self.aborted = False
        self.abort_cause = None
        kept, self._kept.kept = self._kept.kept, []
        for request in kept:  # only with ArmDefects.keep_queue_on_abort (a faulty server)
            self._enqueue(_JointPacket(request), self._clock)

    def press_panic(self, at: float | None = None) -> None:
        """The panic button: cuts arm power and aborts motion on the first servo cycle at or after ``at``
        (the next cycle when ``at`` is None)."""
        self._panic_at = -math.inf if at is None else float(at)

    def halt(self, cause: AbortCause) -> list[ArmEvent]:
        """Abort motion now (at the last servo cycle run), as the move process does on an error: the arm
        stops where it is, the current and queued segments are dropped, and motion is refused (AWA) until
        reset.  Returns the events: segments that had just completed, then the :class:`MotionAborted`.
        Used for a wrist guard that stops the move; an idle arm is left alone (no events)."""
        if not self.moving or not math.isfinite(self._clock):
            return []
        events: list[ArmEvent] = []
        self._abort(self._clock, cause, (), events)
        return events

    @property
    def correction(self) -> Joints | None:
        """Compliant minus nominal commanded angles on the last cycle of the compliant episode running
        (None outside one)."""
        return self._correction

    @property
    def current_scheme(self) -> Scheme | None:
        """Interpolation scheme of the segment run on the last servo cycle (None when idle or playing a
        straight-line move); a :class:`Compliance` reads it to tell the two compliant schemes apart."""
        return self._scheme_now

    def place_obstacle(self, obstacle: Obstacle | None) -> None:
        """Put an obstacle in the arm's way (None removes it)."""
        self.obstacle = obstacle

    # ---------------------------------------------------------------------------- settings
    def set_speed(self, factor: float) -> None:
        """Speed factor for segments queued from now on: 0 < factor <= 1, else BVA (also below
        :data:`MIN_SPEED_FACTOR`, which no PDP-11 float is)."""
        if not (math.isfinite(factor) and 0.0 < factor <= 1.0):
            raise Refused("BVA", f"speed factor {factor!r} is not in 0 < n <= 1")
        if factor < MIN_SPEED_FACTOR:
            raise Refused("BVA", f"speed factor {factor!r} is below the smallest PDP-11 float")
        self.speed = float(factor)
        self._interp.set_speed(self.speed)

    def set_configuration(self, lefty: bool) -> None:
        """Prefer the lefty (True) or righty arm configuration when solving transforms of later moves."""
        self.lefty = bool(lefty)

    def set_hand(self, open_: bool) -> None:
        """Open (True) or close the binary hand; the hand is worked by the arm's controller, so it needs
        arm power (NAP) and no pending abort (AWA) like any motion."""
        self.check_motion()
        self.hand_open = bool(open_)

    def free(self, joint: int) -> None:
        """Free joint ``joint`` (1-based): its brake is off and the collision test ignores it."""
        if not 1 <= joint <= 6:
            raise Refused("BVA", f"joint {joint} is not 1..6")
        self.check_motion()
        self.free_joint = joint

    def unfree(self) -> None:
        self.free_joint = None

    # ---------------------------------------------------------------------------------- motion
    def check_motion(self, now: float | None = None) -> None:
        """Refuse motion while aborted (AWA) or without power (NAP); with ``now`` (a segment to be queued
        at that time) also with a full queue (SQF) or before the last servo cycle (ValueError)."""
        if now is not None and now < self._clock:
            raise ValueError(f"request at {now} before the last servo cycle {self._clock}; tick first")
        if self.aborted and self.defects.enforce_abort:
            cause = self.abort_cause.value if self.abort_cause else "abort"
            raise Refused("AWA", f"motion aborted ({cause}); reset first")
        if not self.powered and self.defects.enforce_power:
            raise Refused("NAP", "arm power is off")
        if now is not None and self.queued >= self.max_queue:
            raise Refused("SQF", f"{self.queued} segments queued")

    def move_joints(
        self, goal: JointsLike, now: float, *, scheme: Scheme | None = None, check_limits: bool = True
    ) -> int:
        """Queue a joint-interpolated move to ``goal`` (deg); JOR when a joint is out of range.

        With ``check_limits=False`` (a faulty server) out-of-range goals are clamped to the limits.
        """
        self.check_motion(now)
        q = _joints(goal)
        lim = self.model.limits
        if check_limits:
            bad = within_limits(q, lim)
            if bad:
                raise Refused("JOR", "goal out of range", bad)
        else:
            q = _joints([min(max(v, lo), hi) for v, lo, hi in zip(q, lim.lower, lim.upper, strict=True)])
        return self._queue_joints(q, now, scheme)

    def move_ready(self, now: float) -> int:
        """Queue a move to the ready position (arm straight up)."""
        self.check_motion(now)
        return self._queue_joints(self.model.ready, now, None)

    def move_to(self, pose: Transform, now: float, *, straight: bool = False) -> int:
        """Queue a move to ``pose``: joint-interpolated, or along a straight line with ``straight``."""
        self.check_motion(now)
        if straight:
            return self._queue_straight(pose, now)
        return self._queue_joints(self.solve(pose, self._planned), now, None)

    def move_increment(self, delta: Sequence[float], now: float, *, straight: bool = False) -> int:
        """Queue an incremental move by dX dY dZ (mm, world) dO dA dT (deg, VAL angles) from the pose
        where the queue ends."""
        self.check_motion(now)
        if len(delta) != 6:
            raise ValueError("an increment is dX dY dZ dO dA dT")
        from_actual = self.defects.increment_from_actual
        base = forward(self.actual if from_actual else self._planned, self.model.geometry)
        oat = None if from_actual else self._planned_oat
        if oat is None:
            _, _, _, o, a, t = xyzoat_from_transform(base)
            oat = (o, a, t)
        dx, dy, dz, do, da, dt = (float(v) for v in delta)
        target = apply_increment(base, dx, dy, dz, do, da, dt, oat=oat)
        number = self.move_to(target, now, straight=straight)
        self._planned_oat = (oat[0] + do, oat[1] + da, oat[2] + dt)
        return number

    def move_cosine(self, joint: int, amplitude: float, period: float, now: float, cycles: int = 1) -> int:
        """Queue the cosine-wave debugging segment on ``joint`` (1-based); it ends where it starts."""
        self.check_motion(now)
        if not 1 <= joint <= 6:
            raise Refused("BVA", f"joint {joint} is not 1..6")
        start = self._planned[joint - 1]
        low, high = sorted((start, start + amplitude))
        if low < self.model.limits.lower[joint - 1] or high > self.model.limits.upper[joint - 1]:
            raise Refused("JOR", "the wave leaves the joint's range", (joint,))
        try:
            request = MoveRequest.cosine(self._allocate(), joint - 1, amplitude, period, cycles)
        except ValueError as exc:
            raise Refused("BVA", str(exc)) from exc
        self._enqueue(_JointPacket(request), now)
        return request.segment_id

    # ----------------------------------------------------------------------------- the servo loop
    def tick(self, now: float) -> list[ArmEvent]:
        """Run every servo cycle due by ``now``; return what happened, in order."""
        now = float(now)
        if math.isnan(now):
            raise ValueError("now must not be NaN")
        if self._epoch is None:
            self._epoch = now
        events: list[ArmEvent] = []
        h = self.tick_period
        while True:
            if not self.moving:
                # Idle cycles change nothing: jump to the last one due (or to the panic, if sooner).
                last = math.floor((now - self._epoch) / h + _EPS)
                if self._panic_at is not None and self._panic_at <= now:
                    last = min(last, math.ceil((self._panic_at - self._epoch) / h - _EPS))
                self._cycle = max(self._cycle, last)
            t = self._epoch + self._cycle * h
            if t > now + _EPS * h:
                return events
            # A cycle due within rounding after ``now`` runs at ``now``: a request served at that same
            # instant must not find the servo ahead of it (clocks that land on the tick exactly, such
            # as a virtual one, compute ``now`` and ``t`` with different rounding).
            t = min(t, now)
            self._cycle += 1
            self._clock = t
            self._servo(t, events)

    def _servo(self, t: float, events: list[ArmEvent]) -> None:
        """One servo cycle at time ``t``."""
        if self._panic_at is not None and t >= self._panic_at:
            self._panic_at = None
            self.powered = False
            self._abort(t, AbortCause.PANIC, (), events)
            return
        if self.moving and not self.powered:
            self._abort(t, AbortCause.POWER_LOST, (), events)
            return
        compliant = self._scheme_now is not None and self._scheme_now.compliant
        if self.moving and (self.defects.collision_test_compliant or not compliant):
            lagging = self._lagging(self.collision_tol_deg)
            if lagging:
                self._abort(t, AbortCause.COLLISION, lagging, events)
                return
            warn = self._lagging(0.5 * self.collision_tol_deg)
            if warn and not self._lag_warned:
                events.append(FollowingWarning(t, warn))
            self._lag_warned = bool(warn)
        q = self._next_command(t, events)
        if self.defects.command_lead:
            q = self._led(q)
        reached = self.sluggish.follow(self.commanded, q) if self.sluggish is not None else q
        self.commanded = q
        self.actual = self.obstacle.clamp(reached) if self.obstacle is not None else reached

    def _led(self, q: Joints) -> Joints:
        """The faulty server of :attr:`ArmDefects.command_lead`: the path's angles ``q`` plus its velocity
        times the lead (nothing added at rest)."""
        before, self._path_before = self._path_before, q
        if before is None:
            return q
        lead = self.defects.command_lead
        return _joints([x + lead * (x - b) for x, b in zip(q, before, strict=True)])

    def _lagging(self, tol: float) -> tuple[int, ...]:
        return tuple(
            j
            for j, (a, c) in enumerate(zip(self.actual, self.commanded, strict=True), start=1)
            if j != self.free_joint and abs(a - c) > tol
        )

    def _next_command(self, t: float, events: list[ArmEvent]) -> Joints:
        play = self._playback
        if play is not None:
            q = self._line_step(play)
            if play.done == play.ticks:
                events.append(SegmentCompleted(play.packet.segment, t))
                self._playback = None
                self._restart(q, t)
            return q
        sample = self._interp.sample(t)
        events.extend(SegmentCompleted(sid, t) for sid in sample.completed)
        self._scheme_now = sample.scheme
        nominal = q = _joints(sample.joints)
        if sample.scheme is not None and sample.scheme.compliant:
            if self.compliance is not None:
                q = _joints(self.compliance.adjust(t, nominal, self.actual))
            self._correction = _joints([a - b for a, b in zip(q, nominal, strict=True)])
        elif self._correction is not None and not self.defects.hold_compliant_end:
            self._correction = None
        elif self._correction is not None:
            # The episode's last segment completed on this cycle: the arm stays where the contact let
            # it go (erratum compliant-segment-end), not on the nominal goal; never past a joint limit.
            lim = self.model.limits
            q = _joints(
                [
                    min(max(a + b, lo), hi)
                    for a, b, lo, hi in zip(nominal, self._correction, lim.lower, lim.upper, strict=True)
                ]
            )
        if sample.done and self.defects.stop_between_segments is not None:
            self._rest_then_resume(q, t, self.defects.stop_between_segments)
        elif sample.done:
            if self._compliant_tail:
                self._restart(q, t)  # rebase what waits behind the episode
            if self._backlog and isinstance(self._backlog[0], _PathPacket):
                packet = self._backlog.popleft()
                assert isinstance(packet, _PathPacket)
                self._play(packet, q)
        return q

    def _rest_then_resume(self, here: Joints, t: float, rest: float) -> None:
        """The faulty server of :attr:`ArmDefects.stop_between_segments`: after each segment, ``rest``
        seconds at rest, then what waits starts from where the arm stands (a straight-line segment
        played from there, as one that follows a blended segment is)."""
        if self._resting_since is None:
            self._resting_since = t
        if not self._backlog or t - self._resting_since < rest:
            return
        self._resting_since = None
        self._interp = MoveInterpolator(here, self.limits, self.speed)
        packet = self._backlog.popleft()
        if isinstance(packet, _PathPacket):
            self._play(packet, here)
        else:
            self._interp.enqueue(packet.request, t)

    def _restart(self, here: Joints, t: float) -> None:
        """A fresh interpolator at rest on ``here`` (where the arm stands at ``t``), fed the joint packets
        that wait in the backlog."""
        self._interp = MoveInterpolator(here, self.limits, self.speed)
        self._compliant_tail = False
        self._correction = None
        self._flush(t)
        if not self.queued:
            self._planned, self._planned_oat = here, None

    def _joins(self, packet: _JointPacket) -> bool:
        """Whether ``packet`` may join the interpolator's path (nothing but compliant segments may blend
        out of a compliant one: the others start from where compliance leaves the arm)."""
        return packet.request.scheme.compliant or not self._compliant_tail

    def _flush(self, t: float) -> None:
        """Hand the joint packets at the head of the backlog to the interpolator."""
        while self._backlog and isinstance(self._backlog[0], _JointPacket) and self._joins(self._backlog[0]):
            packet = self._backlog.popleft()
            assert isinstance(packet, _JointPacket)
            self._interp.enqueue(packet.request, t)
            self._compliant_tail = packet.request.scheme.compliant

    def _from(self, packet: _PathPacket, here: Joints) -> _PathPacket:
        """``packet`` starting from ``here``: as planned when it starts where it was planned from;
        otherwise (behind a compliant episode) checked and solved again from ``here``, or, when the line
        can no longer be followed from there, played as planned plus the offset fading linearly to
        zero."""
        offset = _joints([a - b for a, b in zip(here, packet.start, strict=True)])
        if max(abs(d) for d in offset) <= _SAME_START_DEG:
            return packet
        try:
            line, checked = self._plan_line(here, packet.goal, packet.speed)
        except Refused:
            return replace(packet, offset=offset)
        return _PathPacket(packet.segment, line, checked, here, packet.goal, packet.speed)

    def _play(self, packet: _PathPacket, here: Joints) -> None:
        """Start the straight-line ``packet`` from ``here`` (:meth:`_from`): it commands the arm, no
        joint-interpolated scheme, until its last cycle."""
        packet = self._from(packet, here)
        ticks = max(1, math.ceil(packet.line.duration / self.tick_period - _EPS))
        self._playback = _Playback(packet, ticks, packet.start)
        self._scheme_now = None

    def _line_step(self, play: _Playback) -> Joints:
        """The next servo cycle of a straight-line move.

        The line's pose at the cycle's time is solved nearest the previous cycle's angles: the move
        process does the inverse kinematics as the line runs, so a slow line costs no more to queue than
        a fast one.  Where that fails or strays from the checked path (joint-interpolated between the
        checked points) by more than :data:`STRAIGHT_JUMP_DEG` -- which only a line grazing a boundary
        between two checked points can do -- the checked path is commanded instead.  The last cycle
        commands the planned end exactly.
        """
        packet, line = play.packet, play.packet.line
        play.done += 1
        k, n = play.done, play.ticks
        if k >= n:
            q = packet.end
        else:
            s = line.progress(min(k * self.tick_period, line.duration))
            guide = packet.checked.along(s)
            try:
                q = nearest_solution(
                    line.pose_along(s), play.previous, self.model.geometry, self.model.limits
                ).q
            except KinematicsError:
                q = guide
            if _deviation(q, guide) > STRAIGHT_JUMP_DEG:
                q = guide
        play.previous = q
        if packet.offset is None:
            return q
        fade = (n - k) / n
        lim = self.model.limits
        return _joints(
            [
                min(max(v + d * fade, lo), hi)
                for v, d, lo, hi in zip(q, packet.offset, lim.lower, lim.upper, strict=True)
            ]
        )

    def _abort(self, t: float, cause: AbortCause, joints: tuple[int, ...], events: list[ArmEvent]) -> None:
        dropped = list(self._interp.abort(t))
        if self.defects.keep_queue_on_abort:  # the segments behind the one in execution are kept
            queued = self._kept.queued
            kept = [queued.pop(sid) for sid in dropped[1:] if sid in queued]
            self._kept.kept += kept
            dropped = [sid for sid in dropped if sid not in {r.segment_id for r in kept}]
        finished = self._interp.sample(t).completed  # segments that ended just before the abort
        events.extend(SegmentCompleted(sid, t) for sid in finished)
        if self._playback is not None:
            dropped.append(self._playback.packet.segment)
        for packet in self._backlog:
            dropped.append(packet.segment if isinstance(packet, _PathPacket) else packet.request.segment_id)
        self._playback = None
        self._backlog.clear()
        stop = self.actual  # the arm stops where it is
        self.commanded, self._path_before = stop, None
        self._interp = MoveInterpolator(stop, self.limits, self.speed)
        self._planned, self._planned_oat = stop, None
        self._scheme_now = None
        self._correction, self._compliant_tail = None, False
        self._lag_warned = False
        self.aborted, self.abort_cause = True, cause
        events.append(MotionAborted(cause, t, joints, tuple(dropped)))

    # ---------------------------------------------------------------------------- queueing
    def _allocate(self) -> int:
        number = self._next_segment
        self._next_segment = (number + self.defects.segment_step) % SEGMENT_MODULUS
        return number

    def _enqueue(self, packet: _JointPacket | _PathPacket, now: float) -> None:
        if (
            isinstance(packet, _JointPacket)
            and self._playback is None
            and not self._backlog
            and self._joins(packet)
            and (self.defects.stop_between_segments is None or not self._interp.queued)
        ):
            self._interp.enqueue(packet.request, now)
            self._compliant_tail = packet.request.scheme.compliant
        elif self.defects.reverse_waiting:
            self._backlog.appendleft(packet)
        else:
            self._backlog.append(packet)

    def _queue_joints(self, goal: Joints, now: float, scheme: Scheme | None) -> int:
        request = MoveRequest.to(self._allocate(), goal, scheme or self.scheme, self.speed)
        if self.defects.keep_queue_on_abort:
            self._kept.queued[request.segment_id] = request
        self._enqueue(_JointPacket(request), now)
        self._planned, self._planned_oat = goal, None
        return request.segment_id

    def solve(self, pose: Transform, near: JointsLike) -> Joints:
        """Joint angles for ``pose`` nearest ``near``, in the preferred configuration when there is one
        (Solve forwards); TOR when no angles reach it or every solution breaks a limit (then with the
        joints the nearest configuration breaks; erratum ``transform-refusals``)."""
        near = _joints(near)
        g, lim = self.model.geometry, self.model.limits
        try:
            best = nearest_solution(pose, near, g, lim)
        except Unreachable as exc:
            raise Refused("TOR", exc.reason) from exc
        except OutOfRange as exc:
            raise Refused("TOR", str(exc), exc.joints) from exc
        if self.lefty is not None and best.lefty != self.lefty:
            alternatives = [
                s
                for s in inverse_all(pose, g, lim, current=near)
                if not s.out_of_range and s.lefty == self.lefty
            ]
            if alternatives:
                return min(alternatives, key=lambda s: _sq_distance(s.q, near)).q
        return best.q

    def _queue_straight(self, pose: Transform, now: float) -> int:
        line, checked = self._plan_line(self._planned, pose, self.speed)
        packet = _PathPacket(self._allocate(), line, checked, self._planned, pose, self.speed)
        self._enqueue(packet, now)
        self._planned, self._planned_oat = packet.end, None
        return packet.segment

    def _plan_line(self, start: Joints, pose: Transform, speed: float) -> tuple[CartesianSegment, _Checked]:
        """Check the straight line from ``start`` to ``pose`` (erratum ``motion-planning-bounds``).

        The goal first: one solution, so a goal out of reach costs no more (TOR).  Then points of the line,
        each solved nearest the previous one: evenly spaced at most :data:`LINE_CHECK_MM` of travel and
        :data:`LINE_CHECK_DEG` of turn apart, and where two neighbours' solutions differ by more than
        :data:`STRAIGHT_JUMP_DEG` on a joint, the gap is halved until they do not -- a joint that still
        jumps across 1/2^:data:`REFINE_DEPTH` of the spacing means the line passes through a singularity
        (or must change configuration to keep within the limits).  TOR when a point is out of the
        workspace, at a singularity, when every solution of a point breaks a joint limit (with those
        joints), or when more than :data:`MAX_LINE_CHECKS` points would be needed.  The speed factor
        only times the line: it changes neither the verdict nor the work.
        """
        g, lim = self.model.geometry, self.model.limits
        try:
            nearest_solution(pose, start, g, lim)
        except Unreachable as exc:
            raise Refused("TOR", f"the goal is out of the workspace ({exc.reason})") from exc
        except OutOfRange:
            pass  # reachable, so the line is short enough to walk: where it breaks a limit is said there
        line = CartesianSegment(
            forward(start, g).matrix,
            pose.matrix,
            self.cartesian_limits,
            speed,
            turn_share=self.defects.turn_share,
        )
        spacing = max(line.distance / LINE_CHECK_MM, line.angle / LINE_CHECK_DEG)
        n = min(max(1, math.ceil(spacing - _EPS)), MAX_LINE_CHECKS)
        finest = (1.0 + _EPS) / (n << REFINE_DEPTH)
        at, solved = [0.0], [start]
        budget = MAX_LINE_CHECKS
        for i in range(1, n + 1):
            pending = [i / n]  # where to go next, the nearest last
            while pending:
                if budget == 0:
                    raise Refused(
                        "TOR", f"the line passes too near a singularity to check in {MAX_LINE_CHECKS} points"
                    )
                budget -= 1
                s_a, q_a, s_b = at[-1], solved[-1], pending[-1]
                try:
                    q_b = nearest_solution(line.pose_along(s_b), q_a, g, lim).q
                except Unreachable as exc:
                    raise Refused("TOR", f"the line leaves the workspace ({exc.reason})") from exc
                except OutOfRange as exc:
                    raise Refused("TOR", f"the line breaks a joint limit ({exc})", exc.joints) from exc
                if _deviation(q_b, q_a) <= STRAIGHT_JUMP_DEG:
                    at.append(pending.pop())
                    solved.append(q_b)
                elif s_b - s_a <= finest:
                    raise Refused("TOR", "the line passes through a singularity")
                else:
                    pending.append(0.5 * (s_a + s_b))
        return line, _Checked(tuple(at), tuple(solved))


def _deviation(a: Sequence[float], b: Sequence[float]) -> float:
    """The largest difference of one joint between ``a`` and ``b``."""
    return max(abs(x - y) for x, y in zip(a, b, strict=True))
