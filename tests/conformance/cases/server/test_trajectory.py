"""How server.motion.straight-line judges the hand's turn on a straight line (clause
straight-move.orientation, erratum straight-line-orientation): the reference server's turn and the other
ways a server written from the 1985 guide may turn the hand pass; a turn made ahead of the line or left
until its end, one off the way and one that goes back fail.  Pure geometry on sampled Here transforms."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from manip.arm.kinematics import PUMA600, forward
from manip.arm.oat import rotation_from_oat, xyzoat_from_transform
from manip.arm.trajectory import CartesianSegment
from manip.conformance.cases.server.trajectory import (
    LINE_POSE,
    STRAIGHT_TURN,
    TURN_BACK_TOL_DEG,
    TURN_WAY_TOL_DEG,
    UNSEEN_WAY,
    Sample,
    TurnSeen,
    largest_unseen,
    turn_seen,
)

SAMPLES = 101
"""Samples of each path, evenly spaced along it (the case samples every 6 ms of a move of about 1 s)."""

Rotation = np.ndarray
Path = Callable[[float], Rotation]
"""The hand's rotation at path parameter s (0 at the start, 1 at the goal)."""

START = forward(LINE_POSE, PUMA600.geometry)
_, _, _, O0, A0, T0 = xyzoat_from_transform(START)
R0 = np.array(START.rotation)
R1 = rotation_from_oat(O0 + STRAIGHT_TURN[0], A0 + STRAIGHT_TURN[1], T0 + STRAIGHT_TURN[2])
P0 = np.array(START.p).ravel()
P1 = P0 + np.array([80.0, -90.0, 0.0])


def _here(rotation: Rotation, s: float) -> tuple[float, ...]:
    """Here's 12 floats (column after column) of ``rotation`` at ``s`` along the line."""
    return (*rotation.T.ravel().tolist(), *(P0 + s * (P1 - P0)).tolist())


def _seen(path: Path) -> TurnSeen:
    return turn_seen(_here(R0, 0.0), [_here(path(s), s) for s in np.linspace(0.0, 1.0, SAMPLES)])


def _passes(seen: TurnSeen) -> bool:
    return seen.off_way[0] <= TURN_WAY_TOL_DEG and seen.back <= TURN_BACK_TOL_DEG and seen.off_pace is None


def _segment(share: float = 1.0) -> Path:
    start, goal = np.eye(4), np.eye(4)
    start[:3, :3], goal[:3, :3] = R0, R1
    segment = CartesianSegment(start, goal, turn_share=share)
    return lambda s: segment.pose_along(s)[:3, :3]


def _oat_stepped(s: float) -> Rotation:
    """VAL's O A T stepped together, as a server interpolating the incremental move's angles would."""
    return rotation_from_oat(*(v + s * d for v, d in zip((O0, A0, T0), STRAIGHT_TURN, strict=True)))


def _axis_angle(k: Sequence[float], rad: float) -> Rotation:
    axis = np.asarray(k, dtype=float) / np.linalg.norm(k)
    kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    out: Rotation = np.eye(3) + math.sin(rad) * kx + (1 - math.cos(rad)) * kx @ kx
    return out


def _paul(s: float) -> Rotation:
    """Paul's drive transform: the approach vector tilted about a fixed axis of the hand's x-y plane
    while the hand rolls about it, both in step."""
    m = R0.T @ R1
    tilt = math.acos(max(-1.0, min(1.0, m[2, 2])))
    psi = math.atan2(m[1, 2], m[0, 2])
    k = (-math.sin(psi), math.cos(psi), 0.0)
    rest = _axis_angle(k, tilt).T @ m
    roll = math.atan2(rest[1, 0], rest[0, 0])
    return R0 @ _axis_angle(k, s * tilt) @ _axis_angle((0.0, 0.0, 1.0), s * roll)


def _back_and_on(s: float) -> float:
    """A pace that turns 30% of the way, back to 10%, then on to the goal."""
    return s if s < 0.3 else 0.6 - s if s < 0.5 else 0.1 + 1.8 * (s - 0.5)


def _detour(s: float) -> Rotation:
    """The turn about one axis, with a detour of up to 15 degrees about the hand's x axis on the way."""
    return _segment()(s) @ _axis_angle((1.0, 0.0, 0.0), math.radians(15.0) * math.sin(math.pi * s))


def _paced(pace: Callable[[float], float]) -> Path:
    in_step = _segment()
    return lambda s: in_step(pace(s))


@pytest.mark.parametrize(
    "path",
    [
        _segment(),
        _oat_stepped,
        _paul,
        _paced(lambda s: s * s),  # the turn lags the position
        _paced(lambda s: min(1.0, s / 0.6)),  # timed apart: over before the line ends
        _paced(lambda s: 10 * s**3 - 15 * s**4 + 6 * s**5),  # another profile in time
    ],
    ids=["one-axis", "oat-stepped", "paul", "lagging", "timed-apart", "quintic-pace"],
)
def test_a_turn_the_guide_allows_passes(path: Path) -> None:
    seen = _seen(path)
    assert seen.whole == pytest.approx(math.degrees(math.acos((np.trace(R0.T @ R1) - 1) / 2)), abs=1e-6)
    assert _passes(seen), seen


@pytest.mark.parametrize(
    ("path", "fails"),
    [
        (_segment(0.1), "midway"),  # the reference server's fault straight-turn-first
        (_paced(lambda s: max(0.0, (s - 0.9) / 0.1)), "midway"),  # left until the end of the line
        (_detour, "way"),
        (_paced(_back_and_on), "back"),
    ],
    ids=["turn-first", "turn-last", "off-the-way", "turning-back"],
)
def test_a_turn_off_its_way_or_pace_fails(path: Path, fails: str) -> None:
    seen = _seen(path)
    assert not _passes(seen), seen
    broken = {
        "way": seen.off_way[0] > TURN_WAY_TOL_DEG,
        "back": seen.back > TURN_BACK_TOL_DEG,
        "midway": seen.off_pace is not None,
    }
    assert [name for name, bad in broken.items() if bad] == [fails], seen


def test_sparse_samples_still_show_a_turn_made_ahead_of_the_line() -> None:
    """A real-time target under load may be sampled only a few times on the line: one sample before half
    way with the turn already made shows it (the turn never goes back), and a turn in step passes."""
    first = _here(R0, 0.0)
    for path, off_pace in ((_segment(0.1), True), (_segment(), False)):
        samples = [_here(path(s), s) for s in (0.2, 1.0)]
        assert (turn_seen(first, samples).off_pace is not None) == off_pace


# ------------------------------------------------------------------ where the samples saw the path
def _readings(ways: Sequence[float]) -> list[Sample]:
    """One reading per share of the way (a 1-float 'Joint angles'), 10 ms apart."""
    return [Sample(i * 0.01, i * 0.01 + 0.002, (w,)) for i, w in enumerate(ways)]


@given(st.lists(st.floats(-0.5, 1.5), max_size=30), st.floats(0.0, 1.0))
def test_the_largest_unseen_stretch_holds_no_reading_and_no_longer_one_is_empty(
    ways: list[float], at: float
) -> None:
    """No reading lies inside the stretch found, and any stretch of [0, 1] longer than it holds a
    reading or an end of the way (checked at an arbitrary place, not by the same scan)."""
    gap = largest_unseen(_readings(ways), lambda q: q[0])
    clipped = [min(1.0, max(0.0, w)) for w in ways]
    assert 0.0 <= gap.start <= gap.end <= 1.0
    assert not any(gap.start < w < gap.end for w in clipped)
    longer = gap.share + 1e-9
    x = at * max(0.0, 1.0 - longer)
    if x + longer <= 1.0:
        assert any(x <= w <= x + longer for w in [0.0, 1.0, *clipped])
    assert (gap.before is None) == (gap.start == 0.0 and not any(w == 0.0 for w in clipped))


def test_a_path_seen_only_at_its_ends_is_one_stretch_unseen_between_two_readings() -> None:
    readings = _readings([0.0, 0.0, 1.0, 1.0])
    gap = largest_unseen(readings, lambda q: q[0])
    assert (gap.start, gap.end, gap.before, gap.after) == (0.0, 1.0, readings[1], readings[2])
    assert largest_unseen(_readings([0.6, 1.0]), lambda q: q[0])[:3] == (0.0, 0.6, None)
    assert largest_unseen(_readings([0.0, 0.2, 0.45, 0.7, 0.9, 1.0]), lambda q: q[0]).share <= UNSEEN_WAY
