"""What the simulated hand touches: contact models that turn the tool pose into a wrench on the tool.

An :class:`Environment` is asked once per tick for the wrench the world applies to the tool, given the
tool frame (a :class:`~manip.arm.Transform` in world coordinates, mm).  It answers a :class:`Wrench`:
force in ounces and torque in ounce-inches about the tool point, both in world coordinates.  The
simulator adds gravity on the hand and payload itself, so environments model contact only.

* :class:`FreeSpace`: nothing to touch.
* :class:`Surface`: a rigid-ish plane (a table top); penetration times stiffness along its normal.
* :class:`Spring`: a spring from the tool point to an anchor (a compliant fixture, or a person's hand).
* :class:`Contacts`: several of the above at once; their wrenches add.
* :class:`HandLoad`: a steady wrench given in the tool's own axes (a push on the hand that turns with
  it; the reference server's world arranges one to trip a guard).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from manip.arm import Transform

__all__ = ["Contacts", "Environment", "FreeSpace", "HandLoad", "Spring", "Surface", "Wrench"]

Vector = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Wrench:
    """Force (oz) and torque (oz-in) the world applies to the tool, about the tool point, world axes."""

    force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    torque: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @classmethod
    def of(cls, force: Vector, torque: Vector | None = None) -> Wrench:
        f = (float(force[0]), float(force[1]), float(force[2]))
        if torque is None:
            return cls(f)
        return cls(f, (float(torque[0]), float(torque[1]), float(torque[2])))

    def __add__(self, other: Wrench) -> Wrench:
        # float64 sums, as numpy's add would make them
        f, g, t, u = self.force, other.force, self.torque, other.torque
        return Wrench(
            (float(f[0]) + float(g[0]), float(f[1]) + float(g[1]), float(f[2]) + float(g[2])),
            (float(t[0]) + float(u[0]), float(t[1]) + float(u[1]), float(t[2]) + float(u[2])),
        )


@runtime_checkable
class Environment(Protocol):
    """Anything that can say what wrench the world puts on the tool at a given tool pose."""

    def wrench(self, tool: Transform) -> Wrench: ...


def _vec3(v: Sequence[float], what: str) -> Vector:
    a = np.array(v, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{what} must be three finite numbers, got {v!r}")
    return a


@dataclass(frozen=True)
class FreeSpace:
    """No contact anywhere."""

    def wrench(self, tool: Transform) -> Wrench:
        return Wrench()


@dataclass(frozen=True)
class Surface:
    """The half-space behind a plane: ``point`` on it (mm), ``normal`` pointing out into free space.

    When the tool point is ``d`` mm inside, the surface pushes it out with ``stiffness``·d ounces along the
    normal (a one-sided spring: it never pulls).
    """

    point: Sequence[float] = (0.0, 0.0, 0.0)
    normal: Sequence[float] = (0.0, 0.0, 1.0)
    stiffness: float = 10.0
    """oz per mm of penetration."""
    # Worked out once (the simulator asks every tick): the point, the normal, its length and direction.
    _point: Vector = field(init=False, repr=False, compare=False)
    _normal: Vector = field(init=False, repr=False, compare=False)
    _length: np.float64 = field(init=False, repr=False, compare=False)
    _unit: Vector = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = _vec3(self.normal, "Surface.normal")
        length = np.linalg.norm(n)
        if float(length) == 0.0:
            raise ValueError("Surface.normal must not be zero")
        point = _vec3(self.point, "Surface.point")
        if not self.stiffness >= 0.0:
            raise ValueError("Surface.stiffness must be >= 0")
        for name, value in (("_point", point), ("_normal", n), ("_length", length), ("_unit", n / length)):
            object.__setattr__(self, name, value)

    def penetration(self, tool: Transform) -> float:
        """How far (mm) the tool point is inside the surface; 0 when outside."""
        depth = -float(np.dot(tool.p - self._point, self._unit))
        return max(depth, 0.0)

    def wrench(self, tool: Transform) -> Wrench:
        depth = self.penetration(tool)
        if depth == 0.0:
            return Wrench()
        return Wrench.of(self.stiffness * depth * self._normal / self._length)


@dataclass(frozen=True)
class Spring:
    """A linear spring between the tool point and ``anchor`` (mm) with ``rest_length`` (mm)."""

    anchor: Sequence[float] = (0.0, 0.0, 0.0)
    stiffness: float = 1.0
    """oz per mm of stretch."""
    rest_length: float = 0.0
    _anchor: Vector = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_anchor", _vec3(self.anchor, "Spring.anchor"))
        if not self.stiffness >= 0.0 or not self.rest_length >= 0.0:
            raise ValueError("Spring.stiffness and Spring.rest_length must be >= 0")

    def wrench(self, tool: Transform) -> Wrench:
        d = self._anchor - tool.p
        length = float(np.linalg.norm(d))
        if length == 0.0:
            return Wrench()
        return Wrench.of(self.stiffness * (length - self.rest_length) * d / length)


@dataclass(frozen=True)
class Contacts:
    """Several environments at once."""

    parts: tuple[Environment, ...]

    def wrench(self, tool: Transform) -> Wrench:
        total = Wrench()
        for part in self.parts:
            total = total + part.wrench(tool)
        return total


@dataclass(frozen=True)
class HandLoad:
    """A steady force (oz) and torque (oz-in, about the tool point) given in the tool's axes: whatever
    the pose, the hand feels the same push."""

    force: Sequence[float] = (0.0, 0.0, 0.0)
    torque: Sequence[float] = (0.0, 0.0, 0.0)
    _force: Vector = field(init=False, repr=False, compare=False)
    _torque: Vector = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_force", _vec3(self.force, "HandLoad.force"))
        object.__setattr__(self, "_torque", _vec3(self.torque, "HandLoad.torque"))

    def wrench(self, tool: Transform) -> Wrench:
        r = np.array(tool.rotation)
        return Wrench.of(r @ self._force, r @ self._torque)
