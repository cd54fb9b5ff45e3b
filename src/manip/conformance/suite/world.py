"""The target's world: conditions of the arm's surroundings that the protocol alone cannot provoke.

Some clauses are about what a server does when the world intervenes: a joint meets an obstacle, a
calibration finds no zero index, a joint lags its command, the wrist computer falls silent, someone
presses the panic button, a force on the wrist trips a guard.  A case that needs one asks the run's
:class:`World` for it, the same way whatever the target::

    async with ctx.arranged(Obstacle(joint=1, upper=12.5)):
        probe = await ctx.connect()
        ...

A world arranges the condition, answers when it holds, and clears it when the block ends.  There are
three kinds (:func:`open_world` picks one from ``--world``):

* the embedded target's, in-process (:class:`manip.conformance.suite.embedded.ServerEnvironment`);
* a world that speaks contract 2 (``docs/world-harness.md``), JSON Lines over a pipe to a command the
  suite starts, or over TCP (:class:`ContractWorld`): the reference server's
  (``manip-server --world tcp://127.0.0.1:0``), or anybody's;
* an operator at a terminal, asked to arrange each condition by hand (:class:`PromptWorld`).

Without a world a case that needs one ends ``not-judged`` (:class:`CaseNotJudged`), with what would judge
it.  A world that cannot arrange a condition says so (:class:`ConditionUnsupported`: the case is then
not judged either, with the world's reason); a world that misbehaves (garbage, silence past the time
limit, an early exit) raises :class:`WorldError`, whose message says what it did.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Protocol

__all__ = [
    "CONDITIONS",
    "WITHOUT_WORLD",
    "CalibrationFailure",
    "CaseNotJudged",
    "Condition",
    "ConditionUnsupported",
    "Obstacle",
    "PanicButton",
    "SilentWrist",
    "SluggishJoint",
    "World",
    "WorldError",
    "WristForce",
]

WITHOUT_WORLD: Final = (
    "run with --world CMD_OR_URL (a world of contract 2, docs/world-harness.md; the reference server's: "
    "manip-server --world tcp://127.0.0.1:0) or, at a real arm, --world prompt"
)
"""What judges a case that needs a world, for the message of a run without one."""


class CaseNotJudged(Exception):  # noqa: N818 - an outcome
    """The case cannot judge its clauses on this target; ``reason`` says why and what would judge them."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class ConditionUnsupported(Exception):  # noqa: N818 - an answer of the world
    """The world cannot arrange the condition (it said so, with ``reason``)."""

    def __init__(self, condition: Condition, reason: str) -> None:
        super().__init__(f"the world cannot arrange {condition.describe()}: {reason}")
        self.reason = reason


class WorldError(Exception):
    """The world failed or broke its contract; the message says what it did."""


def _joint(value: object, what: str = "joint") -> int:
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 6:
        raise ValueError(f"{what} must be a joint number 1..6, not {value!r}")
    return value


@dataclass(frozen=True)
class Condition:
    """A condition of the arm's world; each kind is a subclass with its contract name and arguments."""

    name: ClassVar[str]

    def args(self) -> dict[str, Any]:
        """The ``args`` object of the contract's ``arrange`` message."""
        return {}

    def describe(self) -> str:
        """What the condition is, in a few words."""
        raise NotImplementedError

    def how_to_clear(self) -> str:
        """What undoes it (for an operator)."""
        raise NotImplementedError


@dataclass(frozen=True)
class Obstacle(Condition):
    """Something in the way of one joint: the joint cannot go below ``lower`` or above ``upper``
    (degrees; None is no bound on that side)."""

    name: ClassVar[str] = "obstacle"
    joint: int
    lower: float | None = None
    upper: float | None = None

    def __post_init__(self) -> None:
        _joint(self.joint)
        if self.lower is None and self.upper is None:
            raise ValueError("an obstacle needs a lower or an upper bound")

    def args(self) -> dict[str, Any]:
        return {"joint": self.joint, "lower": self.lower, "upper": self.upper}

    def describe(self) -> str:
        sides = []
        if self.lower is not None:
            sides.append(f"below {self.lower:g} deg")
        if self.upper is not None:
            sides.append(f"above {self.upper:g} deg")
        return f"an obstacle that stops joint {self.joint} {' and '.join(sides)}"

    def how_to_clear(self) -> str:
        return f"take the obstacle out of joint {self.joint}'s way"


@dataclass(frozen=True)
class CalibrationFailure(Condition):
    """Calibration finds no zero index on ``joints``."""

    name: ClassVar[str] = "calibration-failure"
    joints: tuple[int, ...] = (2, 3)

    def __post_init__(self) -> None:
        if not self.joints:
            raise ValueError("a calibration failure needs at least one joint")
        for joint in self.joints:
            _joint(joint)

    def args(self) -> dict[str, Any]:
        return {"joints": list(self.joints)}

    def describe(self) -> str:
        joints = ", ".join(str(j) for j in self.joints)
        return f"a calibration that finds no zero index on joint(s) {joints}"

    def how_to_clear(self) -> str:
        return "let calibration find every zero index again"


@dataclass(frozen=True)
class SluggishJoint(Condition):
    """``joint`` trails its command by ``lag`` degrees while it moves."""

    name: ClassVar[str] = "sluggish-joint"
    joint: int = 2
    lag: float = 0.35

    def __post_init__(self) -> None:
        _joint(self.joint)
        if not self.lag > 0.0:
            raise ValueError(f"the lag must be positive, not {self.lag!r}")

    def args(self) -> dict[str, Any]:
        return {"joint": self.joint, "lag": self.lag}

    def describe(self) -> str:
        return f"joint {self.joint} trailing its command by {self.lag:g} deg while it moves"

    def how_to_clear(self) -> str:
        return f"let joint {self.joint} follow its command again"


@dataclass(frozen=True)
class SilentWrist(Condition):
    """The wrist computer stops answering (hung, or its link cut)."""

    name: ClassVar[str] = "silent-wrist"

    def describe(self) -> str:
        return "a wrist computer that does not answer"

    def how_to_clear(self) -> str:
        return "let the wrist computer answer again"


@dataclass(frozen=True)
class PanicButton(Condition):
    """The panic button is pressed now: arm power off, motion aborted; cleared, it is released."""

    name: ClassVar[str] = "panic-button"

    def describe(self) -> str:
        return "the panic button pressed (arm power off, motion aborted)"

    def how_to_clear(self) -> str:
        return "release the panic button"


@dataclass(frozen=True)
class WristForce(Condition):
    """A steady force (oz) and torque (oz-in) on the hand, in the hand's axes, at the wrist sensor."""

    name: ClassVar[str] = "wrist-force"
    force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    torque: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if len(self.force) != 3 or len(self.torque) != 3:
            raise ValueError("a wrench is three force and three torque components")

    def args(self) -> dict[str, Any]:
        return {"force": list(self.force), "torque": list(self.torque)}

    def describe(self) -> str:
        force = ", ".join(f"{f:g}" for f in self.force)
        torque = ", ".join(f"{t:g}" for t in self.torque)
        return f"a force of ({force}) oz and a torque of ({torque}) oz-in on the hand, in hand axes"

    def how_to_clear(self) -> str:
        return "take the force off the hand"


CONDITIONS: Final[dict[str, type[Condition]]] = {
    kind.name: kind
    for kind in (Obstacle, CalibrationFailure, SluggishJoint, SilentWrist, PanicButton, WristForce)
}
"""Every condition of contract 2, by its name."""


class World(Protocol):
    """What the suite needs of a target's world."""

    @property
    def description(self) -> str:
        """Whose world it is, for messages (``the embedded server's world``, ``world tcp://...``)."""
        ...

    def arranged(self, condition: Condition) -> contextlib.AbstractAsyncContextManager[None]:
        """Arrange ``condition`` for the block and clear it after; raises :class:`ConditionUnsupported`
        when the world cannot, :class:`WorldError` when it fails."""
        ...


@contextlib.asynccontextmanager
async def no_world(condition: Condition) -> AsyncIterator[None]:
    """What ``ctx.arranged`` is without a world: the case is not judged, and the message says what
    would judge it."""
    raise CaseNotJudged(f"needs {condition.describe()}, which only a world can arrange: {WITHOUT_WORLD}")
    yield  # pragma: no cover - never reached
