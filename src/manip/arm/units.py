"""Length units a server may speak on the wire, and the one place a server converts them.

The 1985 guide states no length unit (erratum ``units``): manip's arm model works in millimetres, and a
server that speaks another unit converts at its boundary, the position column of a transform (Here,
Move, Straight-line move, Solve forwards and backwards) and the dX dY dZ of an incremental move.
Angles are degrees whatever the length unit.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Final, Literal

__all__ = ["LENGTH_UNITS", "MM_PER_UNIT", "LengthUnit", "WireLengths", "unit_of"]

LengthUnit = Literal["mm", "cm", "inch"]
MM_PER_UNIT: Final[Mapping[LengthUnit, float]] = {"mm": 1.0, "cm": 10.0, "inch": 25.4}
"""Millimetres in one of each unit."""
LENGTH_UNITS: Final[tuple[LengthUnit, ...]] = tuple(MM_PER_UNIT)

_POSITION: Final = slice(9, 12)
"""P x y z in a transform's 12 floats (column-major N O A P)."""
_DISPLACEMENT: Final = slice(0, 3)
"""dX dY dZ in an incremental move's 6 floats."""


@dataclass(frozen=True, slots=True)
class WireLengths:
    """Lengths on the wire in ``unit``, millimetres inside."""

    unit: LengthUnit = "mm"

    @property
    def mm_per_unit(self) -> float:
        return MM_PER_UNIT[self.unit]

    def transform_in(self, floats: Sequence[float]) -> tuple[float, ...]:
        """A transform from the wire, its position in millimetres."""
        return self._scaled(floats, _POSITION, self.mm_per_unit)

    def transform_out(self, floats: Sequence[float]) -> tuple[float, ...]:
        """A transform for the wire, its position in the wire's unit."""
        return self._scaled(floats, _POSITION, 1.0 / self.mm_per_unit)

    def increment_in(self, delta: Sequence[float]) -> tuple[float, ...]:
        """An incremental move's dX dY dZ dO dA dT from the wire, dX dY dZ in millimetres."""
        return self._scaled(delta, _DISPLACEMENT, self.mm_per_unit)

    def _scaled(self, floats: Sequence[float], part: slice, factor: float) -> tuple[float, ...]:
        values = [float(x) for x in floats]
        if self.unit != "mm":
            values[part] = [x * factor for x in values[part]]
        return tuple(values)


LEARN_TOLERANCE: Final = 1.25
"""How far (as a factor) a measured length may be from the expected one in a unit for that unit to be
learned from it."""


def unit_of(measured: float, expected_mm: float) -> LengthUnit | None:
    """The unit in which a length the model puts at ``expected_mm`` millimetres reads ``measured``: the
    unit whose size makes them agree within :data:`LEARN_TOLERANCE`, or None when none does."""
    if not (measured > 0.0 and expected_mm > 0.0):
        return None
    ratio = expected_mm / measured
    for unit, size in MM_PER_UNIT.items():
        if 1.0 / LEARN_TOLERANCE <= ratio / size <= LEARN_TOLERANCE:
            return unit
    return None
