"""The simulated arm and move process: queueing, servo cycles, collisions, the panic button, aborts."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any
from unittest.mock import patch

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from manip.arm import sim
from manip.arm.kinematics import PUMA600, READY, Joints, Unreachable, forward
from manip.arm.sim import (
    MAX_LINE_CHECKS,
    MIN_SPEED_FACTOR,
    STRAIGHT_JUMP_DEG,
    AbortCause,
    ArmEvent,
    ArmSim,
    FollowingWarning,
    MotionAborted,
    Obstacle,
    Refused,
    SegmentCompleted,
)
from manip.arm.trajectory import PUMA_LIMITS, TICK, Scheme
from manip.arm.transform import Transform
from manip.codecs.messages import ErrorReply, Reply, decode_server_packet, encode_request
from manip.reference_server import ServerConfig, ServerSession
from manip.reference_server.faults import FaultSet
from manip.spec import SPEC
from manip.spec.constants import ServerOp

GOAL = (10.0, -80.0, 100.0, 20.0, 30.0, 40.0)
OTHER = (-20.0, -100.0, 80.0, -10.0, 20.0, -30.0)


def _arm(**kw: object) -> ArmSim:
    arm = ArmSim(powered=True, **kw)  # type: ignore[arg-type]
    arm.tick(0.0)
    return arm


def _run(arm: ArmSim, until: float, step: float = TICK) -> tuple[list[ArmEvent], float]:
    """Tick every ``step`` from the arm's clock to ``until``."""
    events: list[ArmEvent] = []
    t = arm.time
    while t < until - 1e-12:
        t = min(until, t + step)
        events += arm.tick(t)
    return events, t


def _run_idle(arm: ArmSim, limit: float = 30.0) -> tuple[list[ArmEvent], float]:
    events: list[ArmEvent] = []
    t = arm.time
    while arm.moving:
        assert t < limit, "the arm never came to rest"
        t += TICK
        events += arm.tick(t)
    return events, t


def _completed(events: list[ArmEvent]) -> list[int]:
    return [e.segment for e in events if isinstance(e, SegmentCompleted)]


def _close(a: tuple[float, ...], b: tuple[float, ...], tol: float = 1e-6) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) <= tol


# ------------------------------------------------------------------------------------- basics
def test_starts_at_ready_unpowered_and_refuses_motion() -> None:
    arm = ArmSim()
    assert arm.actual == READY and arm.commanded == READY and not arm.powered
    with pytest.raises(Refused) as info:
        arm.move_joints(GOAL, 0.0)
    assert info.value.code == "NAP"
    assert arm.next_segment == 1  # a refusal uses no segment number


def test_moves_over_ticks_to_the_goal_and_reports_completion() -> None:
    arm = _arm()
    n = arm.move_joints(GOAL, 0.001)
    assert n == 1 and arm.moving and arm.actual == READY  # queued, not moved yet
    events, _ = _run(arm, 0.2)
    assert not _completed(events)
    assert not _close(arm.actual, READY) and not _close(arm.actual, GOAL)
    events, _ = _run_idle(arm)
    assert _completed(events) == [1]
    assert _close(arm.actual, GOAL) and arm.commanded == arm.actual


def test_segment_numbers_increase_in_queue_order_and_complete_in_order() -> None:
    arm = _arm()
    numbers = [arm.move_joints(g, 0.0) for g in (GOAL, OTHER, READY, GOAL)]
    assert numbers == [1, 2, 3, 4]
    events, _ = _run_idle(arm)
    assert _completed(events) == numbers
    assert _close(arm.actual, GOAL)


def test_segment_numbers_wrap_modulo_2_16() -> None:
    arm = _arm()
    arm._next_segment = 0xFFFE  # skip 65533 moves
    numbers = [arm.move_joints(g, 0.0) for g in (GOAL, OTHER, READY)]
    assert numbers == [0xFFFE, 0xFFFF, 0]


def test_queue_full_is_refused_with_sqf() -> None:
    arm = _arm(max_queue=3)
    for g in (GOAL, OTHER, READY):
        arm.move_joints(g, 0.0)
    with pytest.raises(Refused) as info:
        arm.move_joints(GOAL, 0.0)
    assert info.value.code == "SQF"


def test_joint_limits_are_checked_before_queueing() -> None:
    arm = _arm()
    with pytest.raises(Refused) as info:
        arm.move_joints((0.0, -90.0, 90.0, 0.0, 150.0, 0.0), 0.0)
    assert info.value.code == "JOR" and info.value.joints == (5,)
    assert not arm.moving and arm.next_segment == 1
    # a faulty server clamps instead
    n = arm.move_joints((0.0, -90.0, 90.0, 0.0, 150.0, 0.0), 0.0, check_limits=False)
    _run_idle(arm)
    assert n == 1 and arm.actual[4] == pytest.approx(100.0)


def test_requests_must_not_be_older_than_the_last_servo_cycle() -> None:
    arm = _arm()
    arm.tick(1.0)
    with pytest.raises(ValueError, match="tick first"):
        arm.move_joints(GOAL, 0.5)


@pytest.mark.parametrize("moving", [False, True])
def test_a_request_at_the_instant_of_a_cycle_is_served_whatever_the_rounding(moving: bool) -> None:
    # A virtual clock lands on cycle k exactly, but computes "now" with other rounding than the arm's
    # epoch + k * TICK: the cycle then falls a few ulps after now and must not count as later.
    arm = _arm()
    if moving:
        arm.move_joints(GOAL, 0.0)
    k = 227
    now = math.nextafter(k * TICK, 0.0) - 4e-14
    assert now < k * TICK
    arm.tick(now)
    assert arm.time <= now
    assert arm.move_joints(GOAL, now) > 0


def test_idle_cycles_are_skipped() -> None:
    arm = _arm()
    started = time.perf_counter()
    arm.tick(10_000.0)
    assert time.perf_counter() - started < 0.05
    assert arm.time == pytest.approx(10_000.0)


# ----------------------------------------------------------------------------------- schemes
def _duration(arm: ArmSim, goal: tuple[float, ...]) -> float:
    start = arm.time
    arm.move_joints(goal, start)
    _, end = _run_idle(arm)
    return end - start


@pytest.mark.parametrize("scheme", [Scheme.LINEAR_BLEND, Scheme.QUINTIC])
def test_speed_factor_scales_durations(scheme: Scheme) -> None:
    full = _duration(_arm(scheme=scheme), GOAL)
    slow = _arm(scheme=scheme)
    slow.set_speed(0.5)
    assert _duration(slow, GOAL) == pytest.approx(2 * full, abs=2 * TICK)


def test_speed_factor_bounds() -> None:
    arm = _arm()
    for bad in (0.0, -0.5, 1.0001, math.inf):
        with pytest.raises(Refused) as info:
            arm.set_speed(bad)
        assert info.value.code == "BVA"
    arm.set_speed(1.0)
    arm.set_speed(1e-3)
    assert arm.speed == 1e-3


def test_quintic_segments_arrive_at_rest_on_the_goal() -> None:
    arm = _arm(scheme=Scheme.QUINTIC)
    arm.move_joints(GOAL, 0.0)
    arm.move_joints(OTHER, 0.0)
    events, _ = _run_idle(arm)
    assert _completed(events) == [1, 2] and _close(arm.actual, OTHER)


def test_cosine_debugging_wave_returns_to_its_start() -> None:
    arm = _arm()
    n = arm.move_cosine(1, 20.0, 1.0, 0.0)
    _, _ = _run(arm, 0.5)
    assert arm.actual[0] == pytest.approx(20.0, abs=0.1)
    events, _ = _run_idle(arm)
    assert _completed(events) == [n] and _close(arm.actual, READY)
    with pytest.raises(Refused, match="JOR"):
        arm.move_cosine(5, 150.0, 1.0, arm.time)


def test_moves_plan_from_the_end_of_the_queue() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    pose = forward(OTHER)
    arm.move_to(pose, 0.0)
    assert arm.planned == arm.solve(pose, GOAL)  # nearest solution to GOAL, where the queue ends
    _run_idle(arm)
    assert arm.pose().almost_equal(pose, 1e-6)


def test_incremental_moves_accumulate() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    start = arm.pose()
    arm.move_increment((0.0, 0.0, -20.0, 0.0, 0.0, 0.0), arm.time)
    arm.move_increment((5.0, 0.0, -20.0, 0.0, 0.0, 0.0), arm.time)
    _run_idle(arm)
    assert np.allclose(arm.pose().p, start.p + np.array((5.0, 0.0, -40.0)), atol=1e-6)
    assert np.allclose(arm.pose().rotation, start.rotation, atol=1e-6)


def test_straight_line_moves_follow_the_line() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    start = arm.pose()
    goal = Transform.trans(-80.0, 40.0, -60.0) @ start
    n = arm.move_to(goal, arm.time, straight=True)
    a, b = start.p, goal.p
    seen = 0
    while arm.moving:
        arm.tick(arm.time + TICK)
        p = arm.pose().p
        along = float(np.dot(p - a, b - a) / np.dot(b - a, b - a))
        assert -1e-9 <= along <= 1 + 1e-9
        assert np.linalg.norm(p - (a + along * (b - a))) < 1e-6
        seen += 1
    assert seen > 10 and n == 2
    assert arm.pose().almost_equal(goal, 1e-6)


def test_segments_behind_a_straight_line_wait_for_it() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    line = arm.move_increment((0.0, 0.0, -30.0, 0.0, 0.0, 0.0), arm.time, straight=True)
    after = arm.move_joints(OTHER, arm.time)
    events, _ = _run_idle(arm)
    assert _completed(events) == [line, after] and _close(arm.actual, OTHER)


def test_straight_line_out_of_the_workspace_is_refused_at_once() -> None:
    arm = _arm()
    far = Transform.trans(0.0, 0.0, 5000.0) @ arm.pose()
    with pytest.raises(Refused) as info:
        arm.move_to(far, 0.0, straight=True)
    assert info.value.code == "TOR" and not arm.moving and arm.next_segment == 1
    with pytest.raises(Refused, match="TOR"):
        arm.move_to(far, 0.0)


def test_transforms_beyond_the_limits_are_tor_and_joint_angles_jor() -> None:
    """Erratum transform-refusals: a transform whose every solution breaks a limit (joint 3 past its
    upper limit: no second configuration helps) is TOR with the joint, on the arm and on the wire, while
    the same joint angles asked for directly are JOR; the fault swap-tor-jor exchanges the two codes."""
    q = list(READY)
    q[2] = PUMA600.limits.upper[2] + 10.0
    pose = forward(q)
    arm = _arm()
    for refuse in (lambda: arm.solve(pose, READY), lambda: arm.move_to(pose, 0.0)):
        with pytest.raises(Refused) as info:
            refuse()
        assert info.value.code == "TOR" and info.value.joints == (3,)
    with pytest.raises(Refused) as info:
        arm.move_joints(q, 0.0)
    assert info.value.code == "JOR" and info.value.joints == (3,)
    assert not arm.moving and arm.next_segment == 1

    def codes(faults: FaultSet) -> list[tuple[str, str]]:
        session = ServerSession(ServerConfig(powered_at_open=True, faults=faults))
        session.on_open(0.0, 1)
        out = []
        for number, (op, values) in enumerate(
            [
                ("solve-forwards", {"transform": pose.to_floats(), "current": READY}),
                ("set-joint-angles", {"joints": q}),
            ],
            start=2,
        ):
            (packet,) = session.on_request(
                0.0, SPEC.request(op).opcode, number, encode_request(op, **values)
            ).packets
            reply = decode_server_packet(packet.opcode, packet.data, SPEC.request(op).opcode)
            assert isinstance(reply, ErrorReply) and reply.error.args == (0b100,)
            out.append((reply.error.code, reply.error.render()))
        return out

    (tor, tor_text), (jor, _) = codes(FaultSet())
    assert (tor, jor) == ("TOR", "JOR") and tor_text.endswith("puts joint(s) 3 out of range")
    assert [c for c, _ in codes(FaultSet.parse(["swap-tor-jor"]))] == ["JOR", "TOR"]


def test_configuration_preference_picks_the_solution() -> None:
    pose = forward(GOAL)
    arm = _arm()
    natural = arm.solve(pose, READY)
    arm.set_configuration(lefty=True)
    lefty = arm.solve(pose, READY)
    arm.set_configuration(lefty=False)
    righty = arm.solve(pose, READY)
    assert lefty != righty and natural in (lefty, righty)
    for q in (lefty, righty):
        assert forward(q).almost_equal(pose, 1e-6)


# -------------------------------------------------------------------------- aborts and faults
def test_obstacle_stops_the_arm_with_a_collision() -> None:
    arm = _arm()
    arm.place_obstacle(Obstacle(2, upper=-85.0))
    arm.move_joints(GOAL, 0.0)
    arm.move_joints(OTHER, 0.0)
    events, _ = _run(arm, 5.0)
    aborts = [e for e in events if isinstance(e, MotionAborted)]
    assert len(aborts) == 1
    abort = aborts[0]
    assert abort.cause is AbortCause.COLLISION and abort.joints == (2,) and abort.dropped == (1, 2)
    assert any(isinstance(e, FollowingWarning) and e.joints == (2,) for e in events)
    assert events.index(abort) > next(i for i, e in enumerate(events) if isinstance(e, FollowingWarning))
    assert arm.actual[1] == pytest.approx(-85.0) and arm.commanded == arm.actual and not arm.moving
    with pytest.raises(Refused, match="AWA"):
        arm.move_joints(READY, arm.time)
    arm.reset_abort()
    n = arm.move_joints(READY, arm.time)  # away from the obstacle
    events, _ = _run_idle(arm)
    assert _completed(events) == [n] and _close(arm.actual, READY)


def test_free_joint_is_exempt_from_the_collision_test() -> None:
    arm = _arm()
    arm.place_obstacle(Obstacle(2, upper=-85.0))
    arm.free(2)
    arm.move_joints(GOAL, 0.0)
    events, _ = _run_idle(arm)
    assert _completed(events) == [1] and arm.actual[1] == -85.0
    with pytest.raises(Refused, match="BVA"):
        arm.free(7)


class _Nominal:
    """A compliance model that changes nothing (the seam is called; the path stays nominal)."""

    calls = 0

    def adjust(self, t: float, nominal: tuple[float, ...], actual: tuple[float, ...]) -> tuple[float, ...]:
        self.calls += 1
        return nominal


def test_compliant_schemes_inhibit_the_collision_test() -> None:
    for scheme, aborted in ((Scheme.LINEAR_BLEND, True), (Scheme.COMPLIANT_MOTION, False)):
        compliance = _Nominal()
        arm = _arm(compliance=compliance)
        arm.place_obstacle(Obstacle(1, upper=5.0))
        arm.move_joints(GOAL, 0.0, scheme=scheme)
        events, _ = _run(arm, 4.0)
        assert any(isinstance(e, MotionAborted) for e in events) is aborted
        assert (compliance.calls > 0) is not aborted


def test_panic_button_cuts_power_and_aborts_at_its_time() -> None:
    arm = _arm()
    arm.press_panic(at=0.5)
    arm.move_joints(GOAL, 0.0)
    arm.move_joints(OTHER, 0.0)
    events, _ = _run(arm, 0.48)
    assert not events
    events, _ = _run(arm, 3.0)
    (abort,) = events
    assert isinstance(abort, MotionAborted) and abort.cause is AbortCause.PANIC
    assert 0.5 <= abort.time < 0.5 + TICK and abort.dropped == (1, 2)
    assert not arm.powered and arm.aborted
    stopped = arm.actual
    _run(arm, 5.0)
    assert arm.actual == stopped
    with pytest.raises(Refused, match="AWA"):
        arm.move_joints(READY, arm.time)
    arm.reset_abort()
    with pytest.raises(Refused, match="NAP"):
        arm.move_joints(READY, arm.time)
    arm.enable_power()
    arm.move_joints(READY, arm.time)


def test_panic_button_while_idle_still_aborts() -> None:
    arm = _arm()
    arm.press_panic(at=100.0)
    events = arm.tick(200.0)
    assert [type(e) for e in events] == [MotionAborted]
    assert events[0].time == pytest.approx(100.0, abs=TICK)


def test_losing_power_while_moving_aborts() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run(arm, 0.3)
    arm.kill_power()
    events, _ = _run(arm, 0.4)
    assert [e.cause for e in events if isinstance(e, MotionAborted)] == [AbortCause.POWER_LOST]
    arm.enable_power()  # also clears the abort
    assert not arm.aborted
    arm.kill_power()
    assert arm.tick(1.0) == []  # idle: nothing to abort


def test_segments_that_finished_before_an_abort_still_complete() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    events, _ = _run_idle(arm)
    assert _completed(events) == [1]
    arm.move_joints(OTHER, arm.time)
    arm.press_panic()
    events = arm.tick(arm.time + TICK)
    assert [type(e) for e in events] == [MotionAborted]
    assert events[0].dropped == (2,)  # type: ignore[union-attr]


# ------------------------------------------------------------- the end of a compliant episode
class _Drift:
    """A compliance model whose correction drifts, as integrated New Theta Dot does: each cycle it
    grows by a rate drawn once per episode plus noise, at most ``step`` degrees per joint per cycle; it
    starts from zero on an episode's first cycle and is clamped to the joint limits."""

    def __init__(self, seed: int, step: float) -> None:
        self.rng = np.random.default_rng(seed)
        self.step = step
        self.last = -math.inf
        self.offset = np.zeros(6)
        self.rate = np.zeros(6)
        self.episodes = 0

    def adjust(self, t: float, nominal: tuple[float, ...], actual: tuple[float, ...]) -> tuple[float, ...]:
        if t - self.last > 1.5 * TICK:
            self.offset = np.zeros(6)
            self.rate = self.rng.uniform(-0.8, 0.8, 6) * self.step
            self.episodes += 1
        self.last = t
        self.offset = self.offset + self.rate + self.rng.uniform(-0.2, 0.2, 6) * self.step
        lim = READY_LIMITS
        q = np.clip(np.asarray(nominal) + self.offset, lim.lower, lim.upper)
        self.offset = q - np.asarray(nominal)
        return tuple(float(v) for v in q)


READY_LIMITS = PUMA600.limits
STEP_BOUND = PUMA_LIMITS.speed * TICK
"""The most any joint's nominal command moves in one cycle (speed factor 1)."""


def _trace(arm: ArmSim, until: float | None = None, limit: float = 60.0) -> list[Joints]:
    """The commanded angles of every cycle from now until ``until`` (or until the arm is idle)."""
    out = [arm.commanded]
    while (arm.moving if until is None else arm.time < until - 1e-9) and arm.time < limit:
        arm.tick(arm.time + TICK)
        out.append(arm.commanded)
    return out


def _steps(trace: Sequence[Sequence[float]]) -> np.ndarray:
    return np.abs(np.diff(np.asarray(trace), axis=0))


def test_a_compliant_segment_ends_where_compliance_left_the_arm() -> None:
    arm = _arm(compliance=_Drift(seed=5, step=0.05))
    first = arm.move_joints(GOAL, 0.0, scheme=Scheme.COMPLIANT_MOTION)
    events, _ = _run_idle(arm)
    assert _completed(events) == [first]
    rest = arm.commanded
    assert max(abs(a - b) for a, b in zip(rest, GOAL, strict=True)) > 1.0  # short of (or past) the goal
    assert arm.planned == rest and arm.actual == rest and arm.correction is None
    _run(arm, arm.time + 1.0)
    assert arm.commanded == rest  # it stays there
    # The next move starts from there: no jump, and it reaches its own (absolute) goal exactly.
    arm.move_joints(OTHER, arm.time)
    trace = _trace(arm)
    assert trace[0] == rest
    assert np.all(_steps(trace) <= STEP_BOUND + 1e-9)
    assert _close(arm.commanded, OTHER, 1e-9)


def test_the_segment_queued_behind_a_compliant_one_starts_from_where_it_ended() -> None:
    arm = _arm(compliance=_Drift(seed=6, step=0.05))
    first = arm.move_joints(GOAL, 0.0, scheme=Scheme.COMPLIANT_MOTION)
    second = arm.move_joints(OTHER, 0.0)
    completions: list[tuple[int, float, tuple[float, ...]]] = []
    trace = [arm.commanded]
    while arm.moving:
        completions += [
            (e.segment, e.time, arm.commanded)
            for e in arm.tick(arm.time + TICK)
            if isinstance(e, SegmentCompleted)
        ]
        trace.append(arm.commanded)
    (n1, t1, end1), (n2, _, end2) = completions
    assert (n1, n2) == (first, second)
    assert max(abs(a - b) for a, b in zip(end1, GOAL, strict=True)) > 1.0
    assert _close(end2, OTHER, 1e-9)
    # From the compliant segment's last cycle on, every cycle moves at most one tick of nominal motion.
    k = round(t1 / TICK)
    assert np.all(_steps(trace[k - 1 :]) <= STEP_BOUND + 1e-9)


def test_a_straight_line_behind_a_compliant_segment_starts_from_where_it_ended() -> None:
    arm = _arm(compliance=_Drift(seed=7, step=0.02))
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    arm.move_joints(OTHER, arm.time, scheme=Scheme.COMPLIANT_MOTION)
    goal = Transform.trans(30.0, -20.0, 10.0) @ forward(OTHER)
    line = arm.move_to(goal, arm.time, straight=True)
    events: list[ArmEvent] = []
    while arm.current_scheme is not None or not events:
        events += arm.tick(arm.time + TICK)
    start = arm.commanded  # where compliance left the arm: the line starts here
    assert max(abs(a - b) for a, b in zip(start, OTHER, strict=True)) > 0.5
    a, b = forward(start).p, goal.p
    trace = [start]
    while arm.moving:
        events += arm.tick(arm.time + TICK)
        trace.append(arm.commanded)
        p = arm.pose().p
        along = float(np.dot(p - a, b - a) / np.dot(b - a, b - a))
        assert np.linalg.norm(p - (a + along * (b - a))) < 1e-6  # on the line from the rebased start
    assert line in _completed(events) and arm.pose().almost_equal(goal, 1e-6)
    assert np.max(_steps(trace)) < STRAIGHT_JUMP_DEG


_SCHEMES = st.sampled_from(
    [Scheme.LINEAR_BLEND, Scheme.QUINTIC, Scheme.COMPLIANT_MOTION, Scheme.COMPLIANT_DEBUG]
)
_GOALS = st.tuples(*(st.floats(-30.0, 30.0) for _ in range(6))).map(
    lambda d: tuple(r + x for r, x in zip(READY, d, strict=True))
)
_SEGMENTS = st.lists(
    st.tuples(_SCHEMES, _GOALS, st.sampled_from([0.0, 0.0, 0.1, 0.4, 1.0, 2.5])), min_size=1, max_size=6
)


@settings(max_examples=40, deadline=None)
@given(_SEGMENTS, st.integers(0, 2**32 - 1), st.floats(0.005, 0.1))
def test_the_commanded_path_is_continuous_across_segment_boundaries(
    segments: list[tuple[Scheme, tuple[float, ...], float]], seed: int, step: float
) -> None:
    """Whatever the corrections and however the segments are queued (at once, while moving, when
    idle), no cycle moves a joint's command by more than one tick of nominal motion plus the correction
    made on that cycle; non-compliant segments end on their goals, compliant ones where compliance left
    the arm, and every segment completes once, in order."""
    arm = _arm(compliance=_Drift(seed, step))
    numbers: list[int] = []
    trace = [arm.commanded]
    completed: list[int] = []
    t = 0.0
    for scheme, goal, gap in segments:
        t += gap
        while arm.time < t - 1e-9:
            completed += _completed(arm.tick(arm.time + TICK))
            trace.append(arm.commanded)
        numbers.append(arm.move_joints(goal, arm.time, scheme=scheme))
    while arm.moving:
        completed += _completed(arm.tick(arm.time + TICK))
        trace.append(arm.commanded)
    assert completed == numbers
    assert np.all(_steps(trace) <= STEP_BOUND + step + 1e-9)
    last_scheme, last_goal, _ = segments[-1]
    if not last_scheme.compliant:
        assert _close(arm.commanded, last_goal, 1e-9)
    assert arm.planned == arm.commanded == arm.actual
    _run(arm, arm.time + 0.5)
    assert arm.commanded == trace[-1]  # at rest where it ended


class _Twist:
    """A compliance model that turns joint 6 steadily (as a torque about the tool axis would), up to
    its limit."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self.offset = 0.0

    def adjust(self, t: float, nominal: tuple[float, ...], actual: tuple[float, ...]) -> tuple[float, ...]:
        self.offset += self.rate
        q6 = min(nominal[5] + self.offset, PUMA600.limits.upper[5])
        self.offset = q6 - nominal[5]
        return (*nominal[:5], q6)


def test_a_line_that_cannot_be_followed_from_where_compliance_left_the_arm_fades_in() -> None:
    arm = _arm(compliance=_Twist(3.0))
    start = (10.0, -80.0, 100.0, 20.0, 30.0, 50.0)
    arm.move_joints(start, 0.0, scheme=Scheme.COMPLIANT_MOTION)
    goal = Transform.trans(0.0, 0.0, -30.0) @ forward(start)
    line = arm.move_to(goal, 0.0, straight=True)
    events: list[ArmEvent] = []
    while arm.current_scheme is not None or not events:
        events += arm.tick(arm.time + TICK)
    here = arm.commanded
    assert here[5] == PUMA600.limits.upper[5]  # twisted to the limit: the line from here breaks it
    with pytest.raises(Refused):  # a joint limit, or the wrist flipping to avoid it
        ArmSim(powered=True, start=here).move_to(goal, 0.0, straight=True)
    trace = [here]
    while arm.moving:
        events += arm.tick(arm.time + TICK)
        trace.append(arm.commanded)
    assert line in _completed(events) and not arm.aborted
    assert arm.pose().almost_equal(goal, 1e-6)  # the fade is over by the end of the line
    offset = here[5] - start[5]
    n = len(trace) - 1
    assert np.max(_steps(trace)) <= offset / n + STRAIGHT_JUMP_DEG
    assert np.all(np.asarray(trace) <= np.asarray(PUMA600.limits.upper) + 1e-9)


# ---------------------------------------------------------- bounded planning (erratum motion-planning-bounds)
class _Solves:
    """Counts the inverse-kinematics solutions the simulator asks for (the unit of planning work); past
    ``limit`` since the last :meth:`take` the next one fails at once, so unbounded work fails the test
    instead of hanging it."""

    def __init__(self, limit: int | None = None) -> None:
        self.count = 0
        self.limit = limit

    def __enter__(self) -> _Solves:
        self._patches = [
            patch.object(sim, name, self._counting(getattr(sim, name)))
            for name in ("nearest_solution", "inverse_all")
        ]
        for p in self._patches:
            p.start()
        return self

    def __exit__(self, *exc: object) -> None:
        for p in self._patches:
            p.stop()

    def _counting(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        def counted(*args: Any, **kwargs: Any) -> Any:
            self.count += 1
            if self.limit is not None and self.count > self.limit:
                raise AssertionError(f"more than {self.limit} solutions")
            return fn(*args, **kwargs)

        return counted

    def take(self) -> int:
        n, self.count = self.count, 0
        return n


#: The most solutions one request may cost: its goal, the checked points, the preferred configuration.
REQUEST_BOUND = MAX_LINE_CHECKS + 3


def test_a_slow_straight_line_costs_no_more_to_queue_than_a_fast_one() -> None:
    """The reproduced hang: an incremental straight move at speed factor 1e-6 was solved at every one of
    its ~5 million servo cycles before it was answered; now it is checked at the same points as at full
    speed, and solved cycle by cycle as it runs, on the line."""
    counts, checked = [], []
    for speed in (1.0, 1e-6, MIN_SPEED_FACTOR):
        arm = _arm()
        arm.move_joints(GOAL, 0.0)
        _run_idle(arm)
        arm.set_speed(speed)
        start = arm.pose()
        with _Solves(limit=REQUEST_BOUND) as solves:
            line = arm.move_increment((10.0, 0.0, -10.0, 0.0, 0.0, 0.0), arm.time, straight=True)
            counts.append(solves.take())
            checked.append(arm.planned)
            goal = Transform.trans(10.0, 0.0, -10.0) @ start
            for _ in range(200):  # every cycle is solved on the line, however slow
                arm.tick(arm.time + TICK)
                assert solves.take() <= 1
                p, a, b = arm.pose().p, start.p, goal.p
                along = float(np.dot(p - a, b - a) / np.dot(b - a, b - a))
                assert np.linalg.norm(p - (a + along * (b - a))) < 1e-6
        assert arm.moving == (speed < 1.0) and line == 2
    assert counts[0] == counts[1] == counts[2] < 40
    assert checked[0] == checked[1] == checked[2]


def test_the_reproduced_hang_through_the_server_session() -> None:
    """The conformance run's case, through the session: incremental straight moves at speed factor 1e-6,
    by 10 mm (accepted: a segment number) and by dX = 1e30 (TOR), each answered after a bounded number
    of solutions (the first took hours, the second minutes)."""
    session = ServerSession(ServerConfig(powered_at_open=True))
    session.on_open(100.0, 1)
    session.arm.move_joints(GOAL, 100.0)
    session.tick(110.0)
    requests: list[tuple[str, dict[str, Any]]] = [
        ("set-speed", {"factor": 1e-6}),
        ("incremental-straight-move", {"delta": (10.0, 0.0, -10.0, 0.0, 0.0, 0.0)}),
        ("incremental-straight-move", {"delta": (1e30, 0.0, 0.0, 0.0, 0.0, 0.0)}),
    ]
    replies = []
    with _Solves(limit=REQUEST_BOUND) as solves:
        for number, (op, values) in enumerate(requests, start=2):
            out = session.on_request(110.0, SPEC.request(op).opcode, number, encode_request(op, **values))
            (packet,) = out.packets
            replies.append(decode_server_packet(packet.opcode, packet.data, SPEC.request(op).opcode))
            assert solves.take() <= 40
    _, line, far = replies
    assert isinstance(line, Reply) and line.values["segment"] == 2
    assert isinstance(far, ErrorReply) and far.error.code == "TOR"


def test_unreachable_goals_are_refused_after_one_solution() -> None:
    arm = _arm()
    arm.set_speed(1e-6)
    for delta in (
        (1e6, 0.0, 0.0, 0.0, 0.0, 0.0),
        (1e30, 0.0, 0.0, 0.0, 0.0, 0.0),
        (0.0, 0.0, -1e4, 0.0, 0.0, 0.0),
    ):
        with _Solves() as solves, pytest.raises(Refused, match="TOR"):
            arm.move_increment(delta, 0.0, straight=True)
        assert solves.count == 1
    assert not arm.moving and arm.next_segment == 1


def test_a_line_needing_more_points_than_allowed_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    monkeypatch.setattr(sim, "MAX_LINE_CHECKS", 5)
    with _Solves() as solves, pytest.raises(Refused, match=r"TOR.*too near a singularity"):
        arm.move_increment((0.0, 0.0, -60.0, 0.0, 0.0, 0.0), arm.time, straight=True)
    assert solves.count == 1 + 5 and not arm.moving


def test_a_line_through_a_singularity_is_refused_at_every_speed() -> None:
    """Joint 6 at its limit: following the line needs it beyond, so the nearest solutions jump to the
    other wrist (a 180 degree turn of joint 4) however finely the line is cut."""
    here = (10.0, -80.0, 100.0, 20.0, 30.0, PUMA600.limits.upper[5] - 1.0)
    for speed in (1.0, 1e-6):
        arm = ArmSim(powered=True, start=here)
        arm.set_speed(speed)
        with pytest.raises(Refused) as info:
            arm.move_increment((0.0, 0.0, 0.0, 0.0, 0.0, 30.0), 0.0, straight=True)
        assert info.value.code == "TOR"


def test_a_fast_joint_near_the_elbow_singularity_is_followed_not_refused() -> None:
    """Near the stretched elbow joint 3 turns fast for a small move: the check halves the gaps there
    instead of calling it a singularity."""
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    start = arm.pose()
    arm.move_increment((0.0, 0.0, -30.0, 0.0, 0.0, 0.0), arm.time, straight=True)
    trace = [arm.commanded]
    while arm.moving:
        arm.tick(arm.time + TICK)
        trace.append(arm.commanded)
    assert arm.pose().almost_equal(Transform.trans(0.0, 0.0, -30.0) @ start, 1e-6)
    assert np.max(_steps(trace)) < STRAIGHT_JUMP_DEG


def test_a_cycle_that_cannot_be_solved_follows_the_checked_path() -> None:
    arm = _arm()
    arm.move_joints(GOAL, 0.0)
    _run_idle(arm)
    goal = Transform.trans(-40.0, 30.0, -20.0) @ arm.pose()
    line = arm.move_to(goal, arm.time, straight=True)
    end = arm.planned

    def fail(*args: object, **kwargs: object) -> object:
        raise Unreachable("injected")

    trace = [arm.commanded]
    events: list[ArmEvent] = []
    with patch.object(sim, "nearest_solution", fail):
        while arm.moving:
            events += arm.tick(arm.time + TICK)
            trace.append(arm.commanded)
    assert _completed(events) == [line] and arm.commanded == end and not arm.aborted
    assert np.max(_steps(trace)) < STRAIGHT_JUMP_DEG
    assert arm.pose().almost_equal(goal, 1e-6)


def test_speed_factors_below_the_smallest_pdp11_float_are_refused() -> None:
    arm = _arm()
    for bad in (1e-300, MIN_SPEED_FACTOR / 2.0):
        with pytest.raises(Refused, match="BVA"):
            arm.set_speed(bad)
    arm.set_speed(MIN_SPEED_FACTOR)
    arm.move_increment((0.0, 0.0, -5.0, 0.0, 0.0, 0.0), 0.0, straight=True)
    arm.move_increment((0.0, 0.0, -5.0, 0.0, 0.0, 0.0), 0.0)
    _run(arm, 1.0)
    assert arm.moving and _close(arm.commanded, READY, 1e-9)


# The motion requests a conformance run throws at the server: mostly moves that can be made, extremes too.
_HUGE = st.sampled_from([0.0, 180.0, -180.0, 360.0, 720.0, 1e6, -1e6, 1e30, -1e30, 1.7e38, -1.7e38])
_NUMBER = st.one_of(st.floats(-40.0, 40.0), st.floats(-40.0, 40.0), st.floats(-2000.0, 2000.0), _HUGE)
_SMALL = st.tuples(*(st.floats(-40.0, 40.0) for _ in range(3)), *(st.floats(-15.0, 15.0) for _ in range(3)))
_DELTA = st.one_of(_SMALL, _SMALL, _SMALL, st.tuples(*(_NUMBER for _ in range(6))))
_LEGAL = st.tuples(
    *(st.floats(lo, hi) for lo, hi in zip(PUMA600.limits.lower, PUMA600.limits.upper, strict=True))
)
_NEAR = st.tuples(*(st.floats(-15.0, 15.0) for _ in range(6))).map(
    lambda d: tuple(g + x for g, x in zip(GOAL, d, strict=True))
)
_POSE = st.one_of(
    st.tuples(st.one_of(_NEAR, _NEAR, _LEGAL), st.one_of(_SMALL, _SMALL, _DELTA).map(lambda d: d[:3])).map(
        lambda qd: tuple(float(x) for x in (Transform.trans(*qd[1]) @ forward(qd[0])).to_floats())
    ),
    st.tuples(*(_NUMBER for _ in range(12))),
)
_SPEED = st.one_of(
    st.sampled_from([1e-6, 1e-30, MIN_SPEED_FACTOR]), st.sampled_from([1.0, 0.01, 0.0, -1.0, 2.0])
)
_MOTION = st.one_of(
    st.tuples(st.just("incremental-straight-move"), st.fixed_dictionaries({"delta": _DELTA})),
    st.tuples(st.just("straight-move"), st.fixed_dictionaries({"transform": _POSE})),
    st.tuples(st.just("incremental-move"), st.fixed_dictionaries({"delta": _DELTA})),
    st.tuples(st.just("move"), st.fixed_dictionaries({"transform": _POSE})),
)
_REQUEST = st.one_of(
    _MOTION,
    _MOTION,
    _MOTION,
    st.tuples(st.just("set-speed"), st.fixed_dictionaries({"factor": _SPEED})),
    st.tuples(st.just("solve-forwards"), st.fixed_dictionaries({"transform": _POSE, "current": _LEGAL})),
    st.tuples(
        st.just("set-joint-angles"), st.fixed_dictionaries({"joints": st.one_of(_NEAR, _NEAR, _LEGAL)})
    ),
    st.tuples(st.sampled_from(["ready", "reset-abort", "here"]), st.just({})),
)


@settings(max_examples=60, deadline=None)
@given(_SPEED, st.lists(st.tuples(_REQUEST, st.integers(0, 8)), min_size=1, max_size=12))
def test_every_motion_request_is_answered_with_bounded_work(
    speed: float, steps: list[tuple[tuple[str, dict[str, Any]], int]]
) -> None:
    """However large, far, slow or singular, a motion request costs at most the bounded check of one
    line; every servo cycle at most one solution (no compliance here: nothing is solved again)."""
    session = ServerSession(ServerConfig(powered_at_open=True))
    now, number = 100.0, 0o1000
    session.on_open(now, number)
    session.arm.move_joints(GOAL, now)  # away from the singularities of ready
    with _Solves(limit=REQUEST_BOUND) as solves:
        for (op, values), gap in [(("set-speed", {"factor": speed}), 0), *steps]:
            for _ in range(gap):  # the driver's servo: one cycle per call
                now += TICK
                session.tick(now)
                assert solves.take() <= 1
            number += 1
            out = session.on_request(now, SPEC.request(op).opcode, number, encode_request(op, **values))
            assert solves.take() <= REQUEST_BOUND, op
            (reply,) = out.packets
            assert reply.opcode in (ServerOp.RESPONSE, ServerOp.NON_FATAL_ERROR) and not out.close
            if reply.opcode == ServerOp.NON_FATAL_ERROR:
                msg = decode_server_packet(reply.opcode, reply.data)
                assert isinstance(msg, ErrorReply) and msg.error.code != "BUG", msg
                event(f"{op}: {msg.error.code}")
            else:
                event(f"{op}: done")
