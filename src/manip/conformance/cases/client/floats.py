"""PDP-11 floats at their edges: the largest and smallest magnitudes and a clean zero read exactly, a
dirty zero reads as zero, and a reserved operand is an error, never a number."""

from __future__ import annotations

from typing import Final

from manip.codecs.messages import encode_reply
from manip.conformance.cases.client._support import (
    LARGEST,
    SMALLEST,
    close,
    connect,
    expect_reply,
    request,
    spec_request,
)
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

JOINTS = spec_request("joint-angles")
RESERVED: Final = b"\x00\x80\x00\x00"
"""Sign 1, exponent 0: the reserved operand, as wire bytes (sign/exponent word first, low byte first)."""
DIRTY_ZERO: Final = b"\x05\x00\x34\x12"
"""Exponent 0, sign 0, fraction not zero."""


async def _joints_reply(ctx: ClientContext, payload: bytes) -> tuple[Play, int]:
    numbers: list[int] = []

    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is not None:
            numbers.append(req.packet_no)
            await side.reply_payload(req, payload)
            await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "joint-angles"), close(2)], script)
    return play, numbers[0] if numbers else 0


@case(
    "client.float.edges", clauses=["float.range", "float.format", "client.reply-data"], technique="property"
)
async def edges(base: CaseContext) -> None:
    """The largest and smallest PDP-11 magnitudes, both signs, and a clean zero, in a seeded order, read
    exactly."""
    ctx = client_context(base)
    values = [LARGEST, -LARGEST, SMALLEST, -SMALLEST, 0.0, 1.0]
    ctx.random.shuffle(values)
    payload = encode_reply("joint-angles", 0, joints=values)[2:]
    play, number = await _joints_reply(ctx, payload)
    expect_reply(ctx, play, 1, JOINTS, payload, number, clause="float.range")


@case("client.float.reserved-operand", clauses=["float.reserved-operand"])
async def reserved_operand(base: CaseContext) -> None:
    """A reply with a reserved operand among its floats is reported as an error, never as a number."""
    ctx = client_context(base)
    where = ctx.random.randrange(6)
    floats = [
        encode_reply("joint-angles", 0, joints=[float(i + 1)] * 6)[2 + 4 * i : 6 + 4 * i] for i in range(6)
    ]
    floats[where] = RESERVED
    play, _ = await _joints_reply(ctx, b"".join(floats))
    answer = play.answer(1)
    ctx.expect_result(
        answer,
        "bad-data",
        clause="float.reserved-operand",
        expected=f"an error (bad-data): joint {where + 1} is a reserved operand",
    )


@case("client.float.dirty-zero", clauses=["float.dirty-zero"])
async def dirty_zero(base: CaseContext) -> None:
    """A dirty zero (exponent 0, fraction not zero) in a reply reads as 0.0."""
    ctx = client_context(base)
    where = ctx.random.randrange(6)
    floats = [encode_reply("joint-angles", 0, joints=[2.0] * 6)[2 + 4 * i : 6 + 4 * i] for i in range(6)]
    floats[where] = DIRTY_ZERO
    payload = b"".join(floats)
    play, number = await _joints_reply(ctx, payload)
    expect_reply(ctx, play, 1, JOINTS, payload, number, clause="float.dirty-zero")
