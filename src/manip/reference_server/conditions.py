"""Conditions of the arm's world the reference server can be started in: not faults, the world's doing.

A conforming server meets them too: the panic button, an obstacle in a joint's way, a calibration that
finds no zero index, a joint that lags its command, a wrist computer that falls silent.  The suite checks
how the server reports them (the world arranges them for a case: :mod:`manip.reference_server.world`;
``manip-server --fault NAME`` starts a server in one, for every connection).  Unlike a fault switch
(:mod:`manip.reference_server.faults`) a condition breaks nothing: its ``clauses`` are those whose
behaviour it sets off.

:class:`WorldCondition` names them; :class:`WorldConditions` is the set a server's connections meet, with
their arguments, and where the session meets them (:meth:`~WorldConditions.place`,
:meth:`~WorldConditions.opened`, :meth:`~WorldConditions.check`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace
from typing import Final, Self

from manip.arm.sim import ArmSim, Obstacle, Sluggish
from manip.reference_server import errors
from manip.spec import SPEC

__all__ = ["WorldCondition", "WorldConditions"]


class WorldCondition(enum.StrEnum):
    """A condition of the arm's world: its name (``--fault NAME``), what happens, the clauses whose
    behaviour it sets off, and what ``NAME=ARG`` means."""

    description: str
    clauses: tuple[str, ...]
    argument: str | None

    def __new__(cls, name: str, description: str, clauses: tuple[str, ...], argument: str | None) -> Self:
        unknown = [c for c in clauses if c not in SPEC.clauses]
        if unknown:
            raise ValueError(f"condition {name} names unknown clauses {unknown}")
        member = str.__new__(cls, name)
        member._value_ = name
        member.description, member.clauses, member.argument = description, clauses, argument
        return member

    PANIC_BUTTON = (
        "panic-button",
        "The panic button is pressed: arm power off, motion aborted with an asynchronous error.",
        ("motion.abort", "motion.reset", "async-error.request-number"),
        "seconds after the connection opens (default 1)",
    )
    OBSTACLE = (
        "obstacle",
        "An obstacle stops one joint; moving into it is a collision (asynchronous COL error).",
        ("motion.abort", "motion.reset", "async-error.request-number"),
        "JOINT:LOWER:UPPER in degrees, either bound may be empty (e.g. 2::-60)",
    )
    CALIBRATE_NZI = (
        "calibrate-nzi",
        "Calibrate finds no zero index: fatal F NZI with the joint mask, then the connection closes.",
        ("calibrate.nzi", "error.fatal-request-number", "error.fatal-then-close"),
        "joint numbers, comma separated (default 2,3)",
    )
    SLUGGISH_JOINT = (
        "sluggish-joint",
        "One joint trails its command while it moves, by more than half the collision tolerance and "
        "within it: an asynchronous warning (W COL), and the motion goes on.",
        ("async-warning.format", "async-error.request-number"),
        "JOINT:LAG, the joint and its lag in degrees (default 2:0.35)",
    )
    WRIST_SILENT = (
        "wrist-silent",
        "The wrist computer stops answering (hung, or its link cut): a request that needs its data waits "
        "the wrist timeout and is answered E WNR.",
        ("wrist.no-answer",),
        None,
    )


DEFAULT_PANIC_DELAY: Final = 1.0
DEFAULT_NZI_JOINTS: Final = (2, 3)
DEFAULT_SLUGGISH: Final = Sluggish(2, 0.35)


@dataclass(frozen=True)
class WorldConditions:
    """The conditions a server's connections meet from their start, and their arguments."""

    on: frozenset[WorldCondition] = frozenset()
    panic_delay: float = DEFAULT_PANIC_DELAY
    """Seconds after the connection opens at which the panic button is pressed."""
    obstacle: Obstacle | None = None
    nzi_joints: tuple[int, ...] = DEFAULT_NZI_JOINTS
    sluggish: Sluggish = DEFAULT_SLUGGISH
    """The joint that trails its command, and by how much."""

    def __post_init__(self) -> None:
        if WorldCondition.OBSTACLE in self.on and self.obstacle is None:
            raise ValueError("the obstacle condition needs an Obstacle")
        if not self.nzi_joints or any(not 1 <= j <= 6 for j in self.nzi_joints):
            raise ValueError("calibrate-nzi joints must be 1..6")
        if self.panic_delay < 0.0:
            raise ValueError("the panic delay must not be negative")

    def __contains__(self, condition: object) -> bool:
        return condition in self.on

    def merged(self, other: WorldConditions) -> WorldConditions:
        """The conditions of both; the arguments of a condition ``other`` has are ``other``'s."""
        on = other.on
        return WorldConditions(
            self.on | on,
            panic_delay=other.panic_delay if WorldCondition.PANIC_BUTTON in on else self.panic_delay,
            obstacle=other.obstacle if WorldCondition.OBSTACLE in on else self.obstacle,
            nzi_joints=other.nzi_joints if WorldCondition.CALIBRATE_NZI in on else self.nzi_joints,
            sluggish=other.sluggish if WorldCondition.SLUGGISH_JOINT in on else self.sluggish,
        )

    def with_condition(self, condition: WorldCondition, arg: str | None) -> WorldConditions:
        """These conditions and ``condition``, its argument read from ``arg`` (None: its default)."""
        on = self.on | {condition}
        if condition is WorldCondition.PANIC_BUTTON:
            delay = DEFAULT_PANIC_DELAY if arg is None else float(arg)
            return replace(self, on=on, panic_delay=delay)
        if condition is WorldCondition.CALIBRATE_NZI:
            joints = DEFAULT_NZI_JOINTS if arg is None else tuple(int(j) for j in arg.split(","))
            return replace(self, on=on, nzi_joints=joints)
        if condition is WorldCondition.SLUGGISH_JOINT:
            if arg is None:
                return replace(self, on=on)
            joint, sep, lag = arg.partition(":")
            if not sep:
                raise ValueError(f"{arg!r} is not JOINT:LAG")
            return replace(self, on=on, sluggish=Sluggish(int(joint), float(lag)))
        if condition is WorldCondition.OBSTACLE:
            if arg is None:
                raise ValueError("needs an argument")
            parts = arg.split(":")
            if len(parts) != 3:
                raise ValueError(f"{arg!r} is not JOINT:LOWER:UPPER")
            lower = float(parts[1]) if parts[1] else None
            upper = float(parts[2]) if parts[2] else None
            return replace(self, on=on, obstacle=Obstacle(int(parts[0]), lower, upper))
        return replace(self, on=on)

    # ------------------------------------------------------------------------ where a session meets them
    @property
    def wrist_silent(self) -> bool:
        """The wrist computer does not answer."""
        return WorldCondition.WRIST_SILENT in self.on

    def place(self, arm: ArmSim) -> None:
        """Put the arm of a connection being made in these conditions (an obstacle, a lagging joint)."""
        if WorldCondition.OBSTACLE in self.on:
            arm.place_obstacle(self.obstacle)
        if WorldCondition.SLUGGISH_JOINT in self.on:
            arm.sluggish = self.sluggish

    def opened(self, arm: ArmSim, now: float) -> None:
        """The connection opened at ``now``: the panic button is pressed its delay later."""
        if WorldCondition.PANIC_BUTTON in self.on:
            arm.press_panic(at=now + self.panic_delay)

    def check(self, request: str) -> None:
        """Refuse a request the world makes fail (calibrate, violation no zero index): raise RequestError."""
        if WorldCondition.CALIBRATE_NZI in self.on and request == "calibrate":
            raise errors.nzi_error(self.nzi_joints)
