"""What every self-contained segment of :mod:`manip.arm.trajectory` answers alike: where it starts,
where it ends and how long it takes (joint vectors or poses, seconds), read-only once made."""

from __future__ import annotations

from manip.arm.trajectory.limits import Vector

__all__ = ["SegmentEnds"]


class SegmentEnds:
    """The start, goal and duration a segment sets in its ``__init__``, as read-only properties."""

    __slots__ = ("_duration", "_goal", "_start")

    _start: Vector
    _goal: Vector
    _duration: float

    @property
    def start(self) -> Vector:
        return self._start

    @property
    def goal(self) -> Vector:
        return self._goal

    @property
    def duration(self) -> float:
        return self._duration
