"""``manip-conform run --length-unit auto``: the unit of the target's lengths, learned before the cases.

The 1985 guide gives no length unit (erratum ``units``).  A PUMA 600 at its ready position (0, -90, 90,
0, 0, 0 degrees) holds its hand about 865 mm above the base, 86.5 cm, 34.1 inches: far enough apart that
one Solve backwards (0221, read-only: nothing moves) of those angles tells which unit the target speaks.
When the answer fits none (another arm, a refusal, a garbled reply) the run keeps millimetres and says why.
"""

from __future__ import annotations

import asyncio
from typing import Final

from manip.arm.kinematics import PUMA600, forward
from manip.arm.units import LengthUnit, unit_of
from manip.codecs.errors import CodecError
from manip.codecs.messages import decode_reply
from manip.conformance.suite.case import CaseFailure
from manip.conformance.suite.context import CaseContext, Connector, RunOptions
from manip.spec import SPEC

__all__ = ["FALLBACK", "learn_length_unit"]

FALLBACK: Final[LengthUnit] = "mm"
"""The unit kept when the target's ready pose tells none."""
_READY_HEIGHT_MM: Final = forward(PUMA600.ready, PUMA600.geometry).to_floats()[11]


async def learn_length_unit(options: RunOptions, connector: Connector) -> tuple[LengthUnit, str]:
    """The target's length unit from the height of its ready pose, and how it was learned (or why not)."""
    ctx = CaseContext(case_id="length-unit", level="INFO", seed=0, options=options, connector=connector)
    try:
        async with asyncio.timeout(options.connect_timeout + 2 * options.reply_timeout + 1.0):
            probe = await ctx.connect()
            answer = await probe.call("solve-backwards", joints=list(PUMA600.ready))
    except (CaseFailure, TimeoutError) as exc:
        return FALLBACK, f"kept {FALLBACK}: the ready pose could not be asked for ({exc})"
    finally:
        await ctx.close_all()
    if not answer.is_response:
        return FALLBACK, f"kept {FALLBACK}: solve backwards of the ready position was refused ({answer})"
    try:
        values = decode_reply(answer.data, SPEC.request("solve-backwards")).values["transform"]
    except (CodecError, KeyError) as exc:
        return FALLBACK, f"kept {FALLBACK}: the ready pose's transform does not decode ({exc})"
    assert isinstance(values, tuple)
    height = float(values[11])
    unit = unit_of(height, _READY_HEIGHT_MM)
    if unit is None:
        return FALLBACK, (
            f"kept {FALLBACK}: the ready pose's height, {height:g}, is a PUMA 600's "
            f"({_READY_HEIGHT_MM:.1f} mm) in no unit manip knows"
        )
    return (
        unit,
        f"learned {unit}: the ready pose's height is {height:g} (a PUMA 600's is {_READY_HEIGHT_MM:.1f} mm)",
    )
