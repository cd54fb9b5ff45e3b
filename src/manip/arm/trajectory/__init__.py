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

from manip.arm.trajectory.blended import BlendedPath, ViaPoint
from manip.arm.trajectory.cartesian import CartesianSegment
from manip.arm.trajectory.dispatch import MoveInterpolator, MoveRequest, Scheme, TickSample
from manip.arm.trajectory.joint import CosineSegment, JointSegment, QuinticSegment
from manip.arm.trajectory.limits import (
    DEFAULT_CARTESIAN_LIMITS,
    PUMA_LIMITS,
    TICK,
    CartesianLimits,
    MotionLimits,
    sample_times,
)
from manip.arm.trajectory.scaling import (
    QUINTIC_PEAK_ACCEL,
    QUINTIC_PEAK_VELOCITY,
    TRAPEZOID_BLEND_FRACTION,
    Profile,
    profile_at,
    quintic_scaling,
    trapezoid_scaling,
)

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
