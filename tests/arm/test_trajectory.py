"""Trajectory generation for the simulated move process: quintic, cosine, blended, Cartesian, dispatch."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from manip.arm.trajectory import (
    PUMA_LIMITS,
    TICK,
    BlendedPath,
    CartesianLimits,
    CartesianSegment,
    CosineSegment,
    MotionLimits,
    MoveInterpolator,
    MoveRequest,
    Profile,
    QuinticSegment,
    Scheme,
    quintic_scaling,
    sample_times,
    trapezoid_scaling,
)

FAST = settings(max_examples=60, deadline=None)
SLOWER = settings(max_examples=25, deadline=None)
H = 1e-3  # finite-difference step: 1 ms
REL = 1e-9  # relative slack on limit checks (rounding only)

V = PUMA_LIMITS.speed
A = PUMA_LIMITS.accel

angles = st.floats(-180.0, 180.0, allow_nan=False)
joint_vectors = st.lists(angles, min_size=6, max_size=6).map(np.array)
speeds = st.floats(0.05, 1.0)
moderate_speeds = st.floats(0.3, 1.0)


# ------------------------------------------------------------------------------------------ helpers
def _rot(axis: np.ndarray, deg: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    th = math.radians(deg)
    out: np.ndarray = np.eye(3) + math.sin(th) * kx + (1 - math.cos(th)) * kx @ kx
    return out


def _angle_deg(r: np.ndarray) -> float:
    s = math.hypot(r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1])
    return math.degrees(math.atan2(s, float(np.trace(r)) - 1.0))


def _pose(axis: np.ndarray, deg: float, p: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = _rot(axis, deg)
    m[:3, 3] = p
    return m


axes = (
    st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3)
    .map(np.array)
    .filter(lambda a: np.linalg.norm(a) > 0.1)
)
positions = st.lists(st.floats(-800.0, 800.0), min_size=3, max_size=3).map(np.array)
poses = st.builds(_pose, axes, st.floats(-180.0, 180.0), positions)


def _check_continuity(path: BlendedPath, t0: float, t1: float, f_max: float) -> None:
    """Tick sweep plus 1 ms finite differences across every blend boundary."""
    vmax, amax = V * f_max, A * f_max**2
    ts = np.arange(t0, t1 + TICK, TICK)
    qs = np.array([path.position(t) for t in ts])
    vs = np.array([path.velocity(t) for t in ts])
    assert np.all(np.abs(np.diff(qs, axis=0)) <= vmax * TICK * (1 + REL) + 1e-9)
    assert np.all(np.abs(np.diff(vs, axis=0)) <= amax * TICK * (1 + REL) + 1e-9)
    for via in path.vias:
        for k in (via.time - via.tau, via.time + via.tau):
            q_minus, q0, q_plus = path.position(k - H), path.position(k), path.position(k + H)
            left, right = (q0 - q_minus) / H, (q_plus - q0) / H
            # position continuous (no jump) and velocity continuous (the one-sided slopes agree)
            assert np.all(np.abs(q_plus - q_minus) <= 2 * H * vmax + 1e-9)
            assert np.all(np.abs(right - left) <= amax * H + 1e-6)
            assert np.allclose(path.velocity(k + H), path.velocity(k - H), atol=2 * H * amax.max() + 1e-9)
            central = (q_plus - q_minus) / (2 * H)
            assert np.allclose(central, path.velocity(k), atol=amax.max() * H + 1e-6)


# ------------------------------------------------------------------------------------------ profiles
def test_scalings_match_reference_values() -> None:
    """Anchors from the notes (§5.4): mtraj quintic and trapezoidal samples at u = 0, 0.1, …"""
    quintic = [quintic_scaling(u / 10)[0] for u in range(11)]
    assert quintic[0] == 0.0 and quintic[-1] == 1.0
    assert quintic[1] == pytest.approx(0.00856) and quintic[2] == pytest.approx(0.05792)
    assert quintic[5] == pytest.approx(0.5)
    trap = [trapezoid_scaling(u / 10)[0] for u in range(6)]
    assert trap == pytest.approx([0.0, 0.0225, 0.09, 0.2025, 0.35, 0.5])
    assert Profile.QUINTIC.peak_velocity == pytest.approx(
        max(quintic_scaling(u / 1000)[1] for u in range(1001))
    )
    assert Profile.QUINTIC.peak_accel == pytest.approx(
        max(abs(quintic_scaling(u / 10000)[2]) for u in range(10001)), rel=1e-6
    )


def test_sample_times() -> None:
    ts = sample_times(2.0)
    assert len(ts) == 126 and ts[0] == 0.0 and ts[-1] == pytest.approx(2.0)
    assert sample_times(0.0).tolist() == [0.0]
    odd = sample_times(0.05)
    assert odd.tolist() == pytest.approx([0.0, 0.016, 0.032, 0.048, 0.064])
    assert np.allclose(np.diff(sample_times(3.3, tick=0.1)), 0.1)
    with pytest.raises(ValueError):
        sample_times(-1.0)
    with pytest.raises(ValueError):
        sample_times(1.0, tick=0.0)


# ------------------------------------------------------------------------------------------ quintic
@FAST
@given(joint_vectors, joint_vectors, speeds)
def test_quintic_boundary_conditions(q0: np.ndarray, q1: np.ndarray, f: float) -> None:
    seg = QuinticSegment(q0, q1, speed=f)
    t_end = seg.duration
    assert np.array_equal(seg.position(0.0), q0) or t_end == 0.0
    assert np.array_equal(seg.position(t_end), q1)
    assert np.array_equal(seg.position(t_end + 5.0), q1)
    # A segment too short to take a tick (a subnormal step) is already at its goal.
    assert np.array_equal(seg.position(-1.0), q0) or t_end == 0.0
    for t in (0.0, t_end):
        assert np.allclose(seg.velocity(t), 0.0, atol=1e-12)
        assert np.allclose(seg.acceleration(t), 0.0, atol=1e-12)
    assert seg.done(t_end) and (t_end == 0.0 or not seg.done(t_end / 2))


@FAST
@given(joint_vectors, joint_vectors, speeds)
def test_quintic_monotonic_and_coordinated(q0: np.ndarray, q1: np.ndarray, f: float) -> None:
    seg = QuinticSegment(q0, q1, speed=f)
    delta = q1 - q0
    prev = np.zeros(6)
    for t in np.linspace(0.0, seg.duration, 101):
        progress = (seg.position(t) - q0) * np.sign(delta)
        assert np.all(progress >= prev - 1e-9)
        prev = progress
        moving = np.abs(delta) > 1e-6
        if moving.any():  # every joint is the same fraction of the way there
            frac = (seg.position(t) - q0)[moving] / delta[moving]
            assert np.ptp(frac) < 1e-9


@FAST
@given(joint_vectors, joint_vectors, speeds)
@example(np.zeros(6), np.array([0, 0, 0, 0, 0, 2.225073858507e-311]), 1.0)  # regression: T² underflowed
def test_quintic_limits_never_exceeded(q0: np.ndarray, q1: np.ndarray, f: float) -> None:
    seg = QuinticSegment(q0, q1, speed=f)
    vmax, amax = V * f, A * f * f
    ts = np.linspace(0.0, seg.duration, 400)
    vel = np.array([seg.velocity(t) for t in ts])
    acc = np.array([seg.acceleration(t) for t in ts])
    assert np.all(np.abs(vel) <= vmax * (1 + REL))
    assert np.all(np.abs(acc) <= amax * (1 + REL))
    if seg.duration > 0:  # the limits are also respected by the commanded positions themselves
        qs = np.array([seg.position(t) for t in sample_times(seg.duration, 0.004)])
        assert np.all(np.abs(np.diff(qs, axis=0)) <= vmax * 0.004 * (1 + REL) + 1e-9)
    if np.max(np.abs(q1 - q0)) > 1e-9:  # (subnormal moves have too few bits for a tight ratio)
        # and the duration is minimal: some joint reaches its speed or acceleration bound
        peak_v = np.abs(seg.velocity(seg.duration / 2)) / vmax
        peak_a = np.abs(seg.acceleration(seg.duration * (0.5 - math.sqrt(3) / 6))) / amax
        assert max(peak_v.max(), peak_a.max()) == pytest.approx(1.0)


@FAST
@given(joint_vectors, joint_vectors, speeds)
def test_quintic_duration_scales_as_inverse_speed(q0: np.ndarray, q1: np.ndarray, f: float) -> None:
    full, slow = QuinticSegment(q0, q1), QuinticSegment(q0, q1, speed=f)
    assert slow.duration == pytest.approx(full.duration / f, rel=1e-12)
    for u in (0.1, 0.37, 0.5, 0.9):  # same path, slower clock
        assert np.allclose(slow.position(u * slow.duration), full.position(u * full.duration), atol=1e-9)


def test_quintic_tick_rounding_and_errors() -> None:
    seg = QuinticSegment([0] * 6, [10, 0, 0, 0, 0, 0], tick=TICK)
    raw = QuinticSegment([0] * 6, [10, 0, 0, 0, 0, 0]).duration
    assert seg.duration >= raw and seg.duration - raw < TICK
    assert round(seg.duration / TICK, 9) == round(seg.duration / TICK)
    still = QuinticSegment([5] * 6, [5] * 6)
    assert still.duration == 0.0 and still.done(0.0) and np.array_equal(still.position(0.0), [5] * 6)
    with pytest.raises(ValueError):
        QuinticSegment([0] * 6, [1] * 6, speed=0.0)
    with pytest.raises(ValueError):
        QuinticSegment([0] * 6, [1] * 6, speed=1.5)
    with pytest.raises(ValueError):
        QuinticSegment([0] * 5, [1] * 6)
    with pytest.raises(ValueError):
        QuinticSegment([0] * 6, [math.nan] * 6)


def test_quintic_n_joints() -> None:
    limits = MotionLimits.uniform(3, 10.0, 20.0)
    seg = QuinticSegment([0, 0, 0], [10, -5, 0], limits)
    assert seg.duration == pytest.approx(max(1.875 * 10 / 10, math.sqrt(10 / math.sqrt(3) * 10 / 20)))
    assert np.allclose(seg.position(seg.duration / 2), [5, -2.5, 0])


def test_limits_scaling_and_defaults() -> None:
    half = PUMA_LIMITS.scaled(0.5)
    assert half.max_speed == tuple(v * 0.5 for v in PUMA_LIMITS.max_speed)
    assert half.max_accel == tuple(a * 0.25 for a in PUMA_LIMITS.max_accel)
    assert PUMA_LIMITS.blend_time() == pytest.approx(0.3)
    assert PUMA_LIMITS.blend_time(0.5) == pytest.approx(0.6)
    with pytest.raises(ValueError):
        MotionLimits((1.0, 2.0), (1.0,))
    with pytest.raises(ValueError):
        MotionLimits((1.0, -2.0), (1.0, 1.0))


# ------------------------------------------------------------------------------------------- cosine
@FAST
@given(joint_vectors, st.integers(0, 5), st.floats(-60, 60), st.floats(0.5, 5.0), st.integers(1, 3))
def test_cosine_returns_to_start(q0: np.ndarray, j: int, amp: float, period: float, cycles: int) -> None:
    seg = CosineSegment(q0, j, amp, period, cycles)
    assert seg.duration == pytest.approx(period * cycles)
    assert np.array_equal(seg.position(0.0), q0) and np.array_equal(seg.position(seg.duration), q0)
    assert np.allclose(seg.velocity(0.0), 0) and np.allclose(seg.velocity(seg.duration), 0)
    for k in range(cycles):
        assert np.allclose(seg.position((k + 0.5) * period)[j], q0[j] + amp)
        assert np.allclose(seg.position(k * period), q0, atol=1e-9)
    others = [i for i in range(6) if i != j]
    for t in np.linspace(0, seg.duration, 37):
        q = seg.position(t)
        assert np.array_equal(q[others], q0[others])
        assert min(0.0, amp) - 1e-9 <= q[j] - q0[j] <= max(0.0, amp) + 1e-9
        assert abs(seg.velocity(t)[j]) <= seg.peak_velocity * (1 + REL)
        assert abs(seg.acceleration(t)[j]) <= seg.peak_accel * (1 + REL)


def test_cosine_errors() -> None:
    with pytest.raises(ValueError):
        CosineSegment([0] * 6, 6, 10.0, 1.0)
    with pytest.raises(ValueError):
        CosineSegment([0] * 6, 0, 10.0, 0.0)
    with pytest.raises(ValueError):
        CosineSegment([0] * 6, 0, 10.0, 1.0, cycles=0)


# ------------------------------------------------------------------------------------- blended path
def test_blend_matches_paul_example() -> None:
    """Notes §5.2: A=(0,0), B=(100,0), C=(100,100), T=2 s, τ=0.3 s -> q(0)=(96.25, 3.75), q̈=(∓83.3)."""
    limits = MotionLimits.uniform(2, 50.0, 50.0 / 0.3)
    path = BlendedPath([0, 0], limits)
    path.append([100, 0], 1, 0.0)
    path.append([100, 100], 2, 0.0)
    start, b, c = path.vias
    assert b.time - start.time == pytest.approx(2.0) and c.time - b.time == pytest.approx(2.0)
    assert b.tau == pytest.approx(0.3)
    assert np.allclose(path.position(b.time), [96.25, 3.75])
    assert np.allclose(path.acceleration(b.time), [-250 / 3, 250 / 3])
    assert np.allclose(path.velocity(b.time - 0.3), [50, 0]) and np.allclose(
        path.velocity(b.time + 0.3), [0, 50]
    )
    # outside the blend the path is the straight line through the via points
    assert np.allclose(path.position(b.time + 1.0), [100, 50])
    assert np.allclose(path.position(path.end_time), [100, 100]) and path.done(path.end_time)


@st.composite
def via_lists(draw: st.DrawFn) -> list[np.ndarray]:
    n = draw(st.integers(1, 4))
    return [draw(joint_vectors) for _ in range(n)]


@SLOWER
@given(joint_vectors, via_lists(), moderate_speeds)
def test_blended_path_continuity_and_via_points(q0: np.ndarray, goals: list[np.ndarray], f: float) -> None:
    path = BlendedPath(q0, speed=f)
    for i, g in enumerate(goals):
        path.append(g, i, 0.0)
    tau = PUMA_LIMITS.blend_time(f)
    vias = path.vias
    assert len(vias) == len(goals) + 1 and all(v.tau == pytest.approx(tau) for v in vias)
    _check_continuity(path, 0.0, path.end_time + 0.1, f)
    # velocity and acceleration within the scaled limits everywhere
    for t in np.arange(0.0, path.end_time, 0.01):
        assert np.all(np.abs(path.velocity(t)) <= V * f * (1 + REL))
        assert np.all(np.abs(path.acceleration(t)) <= A * f * f * (1 + REL))
    # each via point is passed within its blend region: exactly Paul's offset at the nominal time,
    # and never further than f·v·τ from it during the blend
    for via in vias[1:]:
        p, v_in = np.array(via.position), np.array(via.v_in)
        v_out = np.zeros(6) if via.v_out is None else np.array(via.v_out)
        assert np.allclose(path.position(via.time), p + (v_out - v_in) * via.tau / 4, atol=1e-9)
        for t in np.linspace(via.time - via.tau, via.time + via.tau, 21):
            assert np.all(np.abs(path.position(t) - p) <= V * f * via.tau * (1 + REL) + 1e-9)
    # the last goal is reached at rest, and stays there
    assert np.allclose(path.position(path.end_time), goals[-1], atol=1e-9)
    assert np.allclose(path.velocity(path.end_time), 0.0) and np.allclose(path.velocity(path.end_time + 3), 0)
    assert np.allclose(path.position(path.end_time + 3.0), goals[-1], atol=1e-9)
    assert np.array_equal(path.position(-1.0), q0)


@SLOWER
@given(joint_vectors, via_lists(), speeds)
def test_blended_durations_scale_as_inverse_speed(q0: np.ndarray, goals: list[np.ndarray], f: float) -> None:
    full, slow = BlendedPath(q0), BlendedPath(q0, speed=f)
    for i, g in enumerate(goals):
        full.append(g, i, 0.0)
        slow.append(g, i, 0.0)
    assert slow.end_time == pytest.approx(full.end_time / f, rel=1e-9)
    for a, b in zip(full.vias, slow.vias, strict=True):
        assert b.time == pytest.approx(a.time / f, rel=1e-9)
    for u in (0.05, 0.3, 0.5, 0.77):
        assert np.allclose(slow.position(u * slow.end_time), full.position(u * full.end_time), atol=1e-7)


@st.composite
def append_schedules(draw: st.DrawFn) -> list[tuple[float, np.ndarray, float]]:
    """(gap since previous append, goal, speed factor) for 2-5 appends."""
    n = draw(st.integers(2, 5))
    return [(draw(st.floats(0.0, 3.0)), draw(joint_vectors), draw(moderate_speeds)) for _ in range(n)]


@SLOWER
@given(joint_vectors, append_schedules())
@example(  # regression: a motion started by an append must begin exactly at "now", not 1 ulp earlier
    np.zeros(6), [(1.0, np.array([0.0, 0, 0, 0, 0, 1]), 0.73828125), (0.0, np.zeros(6), 1.0)]
)
def test_append_while_moving_keeps_past_and_continuity(
    q0: np.ndarray, schedule: list[tuple[float, np.ndarray, float]]
) -> None:
    path = BlendedPath(q0)
    now, completions = 0.0, []
    probes = np.linspace(0.0, 20.0, 301)
    for i, (gap, goal, f) in enumerate(schedule):
        now += gap
        before = [(t, path.position(t), path.velocity(t)) for t in probes if t <= now]
        completions.append(path.append(goal, i, now, speed=f))
        for t, q, v in before:  # what was already commanded is not changed by the append
            assert np.array_equal(path.position(t), q) and np.array_equal(path.velocity(t), v)
    _check_continuity(path, 0.0, path.end_time + 0.1, 1.0)
    for t in np.arange(0.0, path.end_time, 0.01):  # mixed speed factors: within the full-speed limits
        assert np.all(np.abs(path.acceleration(t)) <= A * (1 + REL))
    assert completions == sorted(completions) and len(set(completions)) == len(completions)
    assert np.allclose(path.position(path.end_time), schedule[-1][1], atol=1e-9)


def test_late_append_completes_the_stop_then_restarts_from_rest() -> None:
    path = BlendedPath([0] * 6)
    path.append([30, 0, 0, 0, 0, 0], 1, 0.0)
    b = path.vias[-1]
    late = b.time - b.tau + 0.05  # the deceleration onto b has begun
    before = path.position(b.time + b.tau)
    done1 = b.time + b.tau
    done2 = path.append([30, 30, 0, 0, 0, 0], 2, late)
    vias = path.vias
    assert vias[1].v_out == (0.0,) * 6  # the stop stands
    assert vias[2].segment_id is None and vias[2].time - vias[2].tau == pytest.approx(done1)  # restart
    assert np.array_equal(path.position(done1), before)
    assert np.allclose(path.velocity(done1), 0.0)
    assert path.completed_by(done1) == (1,) and done2 > done1
    # an append in time blends instead (no stop, velocity never drops to zero on joint 2's path)
    early = BlendedPath([0] * 6)
    early.append([30, 0, 0, 0, 0, 0], 1, 0.0)
    c = early.vias[-1]
    early.append([30, 30, 0, 0, 0, 0], 2, c.time - c.tau)
    assert early.vias[1].v_out is not None and early.vias[1].v_out[1] > 0
    assert np.linalg.norm(early.velocity(c.time)) > 10.0
    # an append while idle starts at "now"
    path.append([0] * 6, 3, 100.0)
    assert path.vias[-2].time - path.vias[-2].tau == pytest.approx(100.0)
    assert np.allclose(path.position(99.0), [30, 30, 0, 0, 0, 0])


def test_blended_repeated_goal_is_a_dwell() -> None:
    path = BlendedPath([0] * 6)
    path.append([20] * 6, 1, 0.0)
    path.append([20] * 6, 2, 0.0)
    path.append([0] * 6, 3, 0.0)
    _check_continuity(path, 0.0, path.end_time + 0.1, 1.0)
    via = path.vias[2]
    assert via.v_in == (0.0,) * 6 and np.allclose(path.position(path.end_time), 0.0)


def test_blended_completions_in_order_once_each() -> None:
    path = BlendedPath([0] * 6)
    for i in range(5):
        path.append([10.0 * (i + 1)] * 6, 100 + i, 0.0)
    got: list[int] = []
    for t in sample_times(path.end_time + 0.1):
        got.extend(path.pop_completed(t))
        path.forget_before(t)
        assert np.all(np.isfinite(path.position(t)))
    assert got == [100, 101, 102, 103, 104] and path.pending() == 0
    assert len(path.vias) <= 2  # forget_before bounded the memory


def test_blended_errors() -> None:
    with pytest.raises(ValueError):
        BlendedPath([0] * 6, blend_time=0.1)  # below the safe minimum for the limits
    path = BlendedPath([0] * 6, blend_time=0.5)
    path.append([1] * 6, 1, 5.0)
    assert path.vias[0].tau == pytest.approx(0.5)
    with pytest.raises(ValueError):
        path.append([2] * 6, 2, 4.0)  # time went backwards
    with pytest.raises(ValueError):
        path.append([2] * 5, 2, 6.0)


# ---------------------------------------------------------------------------------------- Cartesian
@FAST
@given(poses, poses, speeds, st.sampled_from(Profile))
@example(  # regression: a tiny rotation was mistaken for a half turn
    _pose(np.array([0, 0, 1.0]), 0.0, np.zeros(3)),
    _pose(np.array([0, 0, 1.0]), 5.960464477539063e-08, np.zeros(3)),
    1.0,
    Profile.QUINTIC,
)
def test_cartesian_straight_line(t0: np.ndarray, t1: np.ndarray, f: float, profile: Profile) -> None:
    seg = CartesianSegment(t0, t1, speed=f, profile=profile)
    p0, p1 = t0[:3, 3], t1[:3, 3]
    d = p1 - p0
    r_goal = _angle_deg(t0[:3, :3].T @ t1[:3, :3])
    assert seg.angle == pytest.approx(r_goal, abs=1e-6)
    # a zero-length move is complete at once (the goal is returned, as for a quintic with T = 0)
    assert np.array_equal(seg.pose_at(0.0), t0 if seg.duration > 0 else t1)
    assert np.array_equal(seg.pose_at(seg.duration), t1)
    prev_s, prev_angle = -1e-12, -1e-9
    for t in np.linspace(0.0, seg.duration, 41):
        m = seg.pose_at(t)
        assert np.allclose(m[3], [0, 0, 0, 1])
        r = m[:3, :3]
        assert np.allclose(r.T @ r, np.eye(3), atol=1e-9)
        # on the segment between the two points, advancing monotonically
        s = float(np.dot(m[:3, 3] - p0, d) / np.dot(d, d)) if np.dot(d, d) > 1e-12 else seg.progress(t)
        assert np.allclose(m[:3, 3], p0 + s * d, atol=1e-6)
        assert -1e-9 <= s <= 1 + 1e-9 and s >= prev_s - 1e-9
        # a single rotation about a fixed axis, angle growing monotonically to the goal's
        rel = t0[:3, :3].T @ r
        ang = _angle_deg(rel)
        assert ang >= prev_angle - 1e-6 and ang <= r_goal + 1e-6
        if 1e-3 < ang < 179.0:
            w = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
            assert np.allclose(w / np.linalg.norm(w), seg.axis, atol=1e-6)
        prev_s, prev_angle = s, ang
    assert prev_angle == pytest.approx(r_goal, abs=1e-6)


@FAST
@given(poses, poses, speeds, st.sampled_from(Profile))
def test_cartesian_limits_and_speed_scaling(
    t0: np.ndarray, t1: np.ndarray, f: float, profile: Profile
) -> None:
    lim = CartesianLimits()
    full, seg = CartesianSegment(t0, t1, profile=profile), CartesianSegment(t0, t1, lim, f, profile)
    assert seg.duration == pytest.approx(full.duration / f, rel=1e-9)
    if seg.duration == 0.0:
        return
    h = seg.duration / 200
    ts = np.arange(0.0, seg.duration + h / 2, h)
    ps = np.array([seg.pose_at(t)[:3, 3] for t in ts])
    step = np.linalg.norm(np.diff(ps, axis=0), axis=1)
    assert np.all(step <= lim.max_speed * f * h * (1 + 1e-6) + 1e-9)
    ang = np.array([_angle_deg(t0[:3, :3].T @ seg.pose_at(t)[:3, :3]) for t in ts])
    assert np.all(np.diff(ang) <= lim.max_rot_speed * f * h * (1 + 1e-6) + 1e-6)


def test_cartesian_half_turn_and_identity() -> None:
    t0 = _pose(np.array([0, 0, 1.0]), 0.0, np.zeros(3))
    t1 = _pose(np.array([1.0, 1.0, 0]), 180.0, np.array([100.0, 0, 0]))
    seg = CartesianSegment(t0, t1)
    assert seg.angle == pytest.approx(180.0)
    assert np.allclose(np.abs(seg.axis), np.array([1, 1, 0]) / math.sqrt(2))
    mid = seg.pose_at(seg.duration / 2)
    assert _angle_deg(mid[:3, :3]) == pytest.approx(90.0) and np.allclose(mid[:3, 3], [50, 0, 0])
    axis = np.array([0.3, -0.5, 0.8])
    for deg in (180.0, 179.9999999, 179.99, 1e-7):  # around the branch points of the axis extraction
        seg = CartesianSegment(t0, _pose(axis, deg, np.zeros(3)))
        assert seg.angle == pytest.approx(deg, abs=1e-6)
        assert np.allclose(seg.axis, axis / np.linalg.norm(axis), atol=1e-5) or deg == 180.0
        for u in (0.25, 0.5, 1.0):
            frac = seg.progress(u * seg.duration)
            expected = _rot(axis, frac * deg) if deg < 180.0 else None
            r = seg.pose_at(u * seg.duration)[:3, :3]
            assert _angle_deg(r) == pytest.approx(frac * deg, abs=1e-6)
            if expected is not None:
                assert np.allclose(r, expected, atol=1e-7)
    same = CartesianSegment(t0, t0)
    assert same.duration == 0.0 and np.array_equal(same.pose_at(0.0), t0)
    fixed = CartesianSegment(t0, t1, duration=4.0, profile=Profile.TRAPEZOID)
    assert fixed.duration == 4.0 and fixed.progress(2.0) == pytest.approx(0.5)
    with pytest.raises(ValueError):
        CartesianSegment(np.eye(3), t1)
    with pytest.raises(ValueError):
        CartesianSegment(2 * np.eye(4), t1)


# ----------------------------------------------------------------------------------------- dispatch
def _run(
    m: MoveInterpolator, k_from: int, k_to: int, until_done: bool = False
) -> tuple[list[int], list[np.ndarray], bool]:
    """Sample ticks k_from..k_to-1 (time k·TICK): completed ids, joints, and the last "done"."""
    ids: list[int] = []
    qs: list[np.ndarray] = []
    done = False
    for k in range(k_from, k_to):
        s = m.sample(k * TICK)
        ids.extend(s.completed)
        qs.append(s.joints)
        done = s.done
        if until_done and done:
            break
    return ids, qs, done


def test_scheme_families() -> None:
    assert {s for s in Scheme if s.blends} == {
        Scheme.LINEAR_BLEND,
        Scheme.COMPLIANT_DEBUG,
        Scheme.COMPLIANT_MOTION,
    }
    assert {s for s in Scheme if s.compliant} == {Scheme.COMPLIANT_DEBUG, Scheme.COMPLIANT_MOTION}


Request = tuple[Scheme, np.ndarray] | tuple[Scheme, tuple[int, float, float]]
requests: st.SearchStrategy[Request] = st.one_of(
    st.tuples(st.sampled_from([Scheme.LINEAR_BLEND, Scheme.QUINTIC, Scheme.COMPLIANT_MOTION]), joint_vectors),
    st.tuples(st.just(Scheme.COSINE), st.tuples(st.integers(0, 5), st.floats(-20, 20), st.floats(0.3, 1.5))),
)


@SLOWER
@given(joint_vectors, st.lists(st.tuples(st.integers(0, 150), requests), min_size=1, max_size=6))
def test_dispatcher_reports_every_segment_once_in_order(
    q0: np.ndarray, plan: list[tuple[int, Request]]
) -> None:
    """Requests of mixed schemes queued at random ticks: every id is reported once, in queue order."""
    m = MoveInterpolator(q0)
    k, ids, qs = 0, [], [m.sample(0.0).joints]
    last_goal, peak = q0, V.copy()
    for seg_id, (gap, (scheme, data)) in enumerate(plan):
        got, seen, _ = _run(m, k + 1, k + gap + 1)
        ids += got
        qs += seen
        k += gap
        if isinstance(data, tuple):
            joint, amp, period = data
            m.enqueue(MoveRequest.cosine(seg_id, joint, amp, period), k * TICK)
            peak[joint] = max(peak[joint], abs(amp) * math.pi / period)
        else:
            m.enqueue(MoveRequest.to(seg_id, tuple(data), scheme), k * TICK)
            last_goal = data
        assert m.queued >= 1
    got, seen, done = _run(m, k + 1, k + 1 + int(200 / TICK), until_done=True)
    ids += got
    qs += seen
    assert ids == list(range(len(plan)))
    assert done and m.queued == 0
    assert np.allclose(qs[-1], last_goal, atol=1e-9)
    # never jumps: each tick moves at most (speed limit, or the cosine's peak speed) x tick
    steps = np.abs(np.diff(np.array(qs), axis=0))
    assert np.all(steps <= peak * TICK * (1 + 1e-6) + 1e-9)


def test_dispatcher_blends_consecutive_linear_segments_and_tracks_current() -> None:
    m = MoveInterpolator([0] * 6)
    m.enqueue(MoveRequest.to(1, [40, 0, 0, 0, 0, 0]), 0.0)
    m.enqueue(MoveRequest.to(2, [40, 40, 0, 0, 0, 0], Scheme.COMPLIANT_MOTION), 0.0)
    s = m.sample(0.5)
    assert s.segment == 1 and s.scheme is Scheme.LINEAR_BLEND and not s.done
    # queued while moving, before the last blend starts: it blends too (no stop at segment 2's goal)
    m.enqueue(MoveRequest.to(3, [0, 40, 0, 0, 0, 0]), 0.6)
    all_ids: list[int] = []
    closest = math.inf
    for t in np.arange(0.6 + TICK, 6.0, TICK):
        s = m.sample(t)
        all_ids.extend(s.completed)
        if s.segment == 2:
            assert s.scheme is Scheme.COMPLIANT_MOTION
        closest = min(closest, float(np.linalg.norm(s.joints - [40, 40, 0, 0, 0, 0])))
    assert all_ids == [1, 2, 3] and s.done and s.segment is None
    assert closest > 1.0  # segment 3 was blended in: the arm cut the corner at segment 2's goal
    assert np.allclose(s.joints, [0, 40, 0, 0, 0, 0])


def test_dispatcher_speed_factor_and_abort() -> None:
    slow, fast = MoveInterpolator([0] * 6), MoveInterpolator([0] * 6)
    slow.set_speed(0.5)
    for m in (slow, fast):
        m.enqueue(MoveRequest.to(7, [50] * 6, Scheme.QUINTIC), 0.0)
    t_fast = next(t for t in sample_times(30) if fast.sample(t).completed)
    t_slow = next(t for t in sample_times(30) if slow.sample(t).completed)
    assert t_slow == pytest.approx(2 * t_fast, abs=2 * TICK)

    m = MoveInterpolator([0] * 6)
    m.enqueue(MoveRequest.to(1, [50] * 6), 0.0)
    m.enqueue(MoveRequest.to(2, [0] * 6, Scheme.QUINTIC), 0.0)
    m.enqueue(MoveRequest.to(3, [10] * 6), 0.0)
    here = m.sample(0.5).joints
    assert m.abort(0.5) == (1, 2, 3)
    s = m.sample(0.6)
    assert s.done and s.completed == () and np.array_equal(s.joints, here)
    with pytest.raises(ValueError):
        m.sample(0.1)  # time went backwards
    with pytest.raises(ValueError):
        m.enqueue(MoveRequest.to(4, [0] * 5), 1.0)
    with pytest.raises(ValueError):
        MoveRequest(5, Scheme.QUINTIC)  # no goal
    with pytest.raises(ValueError):
        m.set_speed(0.0)


@FAST
@given(axes, st.floats(0.0, 180.0), st.floats(-500.0, 500.0), st.floats(0.0, 1.0))
def test_cartesian_pose_along_the_path_parameter(axis: np.ndarray, deg: float, x: float, s: float) -> None:
    """pose_along(s) is the line at path parameter s whatever the timing; pose_at(t) is it at s(t)."""
    t0 = _pose(np.array([0.2, -0.4, 1.0]), 30.0, np.array([10.0, 20.0, 30.0]))
    t1 = _pose(axis, deg, np.array([x, -x, 0.5 * x])) @ t0
    slow, fast = CartesianSegment(t0, t1, speed=1e-6), CartesianSegment(t0, t1)
    pose = slow.pose_along(s)
    assert np.array_equal(pose, fast.pose_along(s))
    assert np.allclose(pose[:3, 3], t0[:3, 3] + s * (t1[:3, 3] - t0[:3, 3]), atol=1e-9)
    assert _angle_deg(t0[:3, :3].T @ pose[:3, :3]) == pytest.approx(s * fast.angle, abs=1e-6)
    assert _angle_deg(pose[:3, :3].T @ t1[:3, :3]) == pytest.approx((1.0 - s) * fast.angle, abs=1e-6)
    assert np.allclose(pose[:3, :3].T @ pose[:3, :3], np.eye(3), atol=1e-12) and pose[3].tolist() == [
        0,
        0,
        0,
        1,
    ]
    t = 0.37 * fast.duration
    assert np.array_equal(fast.pose_at(t), fast.pose_along(fast.progress(t)))


def test_cartesian_pose_along_ends_and_bad_parameters() -> None:
    t0 = _pose(np.array([0, 0, 1.0]), 10.0, np.zeros(3))
    t1 = _pose(np.array([1.0, 0, 0]), 90.0, np.array([0.0, 50.0, 0.0]))
    seg = CartesianSegment(t0, t1)
    assert np.array_equal(seg.pose_along(0.0), t0) and np.array_equal(seg.pose_along(-1.0), t0)
    assert np.array_equal(seg.pose_along(1.0), t1) and np.array_equal(seg.pose_along(7.0), t1)
    with pytest.raises(ValueError, match="NaN"):
        seg.pose_along(math.nan)


def test_cartesian_turn_share_turns_ahead_of_the_position() -> None:
    """A faulty server's turn_share (fault straight-turn-first) turns the hand to the goal's orientation
    over that share of the line and carries it unturned the rest of the way; the position is the line's
    whatever the share, and the default turns in step with it."""
    t0 = _pose(np.array([0.3, -0.2, 1.0]), 20.0, np.array([400.0, 100.0, 300.0]))
    t1 = _pose(np.array([1.0, 0.5, 0.0]), 40.0, np.array([480.0, 10.0, 300.0])) @ t0
    ahead, in_step = CartesianSegment(t0, t1, turn_share=0.1), CartesianSegment(t0, t1)
    for s in (0.05, 0.1, 0.5, 0.9):
        pose, step = ahead.pose_along(s), in_step.pose_along(s)
        assert np.allclose(pose[:3, 3], step[:3, 3], atol=1e-9)
        turned = _angle_deg(t0[:3, :3].T @ pose[:3, :3])
        assert turned == pytest.approx(min(1.0, s / 0.1) * in_step.angle, abs=1e-6)
        assert _angle_deg(t0[:3, :3].T @ step[:3, :3]) == pytest.approx(s * in_step.angle, abs=1e-6)
    for share in (0.0, -0.5, 1.5, math.nan):
        with pytest.raises(ValueError, match="turn_share"):
            CartesianSegment(t0, t1, turn_share=share)
