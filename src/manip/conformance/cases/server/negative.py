"""Malformed and unexpected requests: the server answers as the spec says and stays alive.

Every case here is of kind ``negative``, so the runner sends a liveness probe after each.  The wrong
lengths and reserved-operand floats are generated from the spec's layouts, for every opcode; the cases
are split by hazard so that on hardware the motion and power opcodes are not sent malformed either.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from typing import Final

from manip.codecs.chaos import chaos_checksum, data_words, header_words
from manip.codecs.messages import encode_request
from manip.codecs.packet import Packet
from manip.conformance.cases._support import (
    UNASSIGNED_OPCODES,
    expect_error_numbers,
    expect_here_served,
    expect_refusal,
    refused,
    valid_values,
)
from manip.conformance.judge.checks import check_reply, word
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.links.address import parse_address
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import ServerOp
from manip.spec.model import Hazard
from manip.spec.notation import octal

RESERVED_OPERAND: Final = struct.pack("<HH", 0x8000, 0)
"""Sign 1, exponent 0: the PDP-11 reserved operand (sign/exponent word first, low byte first)."""
SAFE: Final[tuple[Hazard, ...]] = ("read-only", "config")
UNSAFE: Final[tuple[Hazard, ...]] = ("motion", "power")


def _ops(hazards: Iterable[str]) -> list[RequestOpcode]:
    wanted = set(hazards)
    return [op for op in SPEC.requests.values() if op.hazard in wanted]


def _accepted_sizes(op: RequestOpcode) -> set[int]:
    """The data lengths the layout accepts (a ``small`` field also accepts one byte less)."""
    size = op.request.fixed_size
    if size is None:
        return set()
    return {size} | ({size - 1} if any(f.type.element == "small" for f in op.request.fields) else set())


def _bdl_numbers(op: RequestOpcode, received: int) -> list[tuple[int, int]]:
    """BDL's numbers for ``received`` bytes: an accepted size and the count received, in either order."""
    return [pair for size in _accepted_sizes(op) for pair in ((size, received), (received, size))]


def _wrong_sizes(op: RequestOpcode) -> list[int]:
    """Two data lengths the layout does not accept."""
    size = op.request.fixed_size
    if size is None:
        return []
    accepted = _accepted_sizes(op)
    candidates = [size + 2, size + 1, size - 2, size - 3, 0, 4]
    out: list[int] = []
    for n in candidates:
        if n >= 0 and n not in accepted and n not in out:
            out.append(n)
    return out[:2]


def _float_offsets(op: RequestOpcode) -> list[int]:
    offsets, pos = [], 0
    for f in op.request.fields:
        ft = f.type
        if ft.element == "float" and ft.count:
            offsets += [pos + 4 * i for i in range(ft.count)]
        pos += ft.fixed_size or 0
    return offsets


@case(
    "server.negative.unknown-opcodes",
    clauses=["request.unknown-opcode", "error-string.arg-values"],
    technique="negative",
    deadline=10.0,
)
async def unknown_opcodes(ctx: CaseContext) -> None:
    """Every data opcode the spec does not define is answered by a non-fatal error of severity C."""
    probe = await ctx.connect()
    for opcode in UNASSIGNED_OPCODES:
        answer = await probe.call_raw(opcode, b"")
        ctx.check(check_reply(answer.request, answer.packets))
        what = f"unknown opcode {octal(opcode)}"
        error = expect_refusal(ctx, answer, clause="request.unknown-opcode", what=what)
        expect_error_numbers(ctx, answer, error, [(opcode,)], what=what)
    answer = await probe.call("here")
    ctx.expect_response(
        answer, clause="request.unknown-opcode", expected="the connection still serving after unknown opcodes"
    )


_HAZARD_GROUPS: Final[tuple[tuple[str, tuple[Hazard, ...]], ...]] = (("safe", SAFE), ("motion", UNSAFE))
"""The negative cases come in two: opcodes safe on hardware, and motion/power ones (id suffix)."""


@case.each(_HAZARD_GROUPS)
def _length_case(row: tuple[str, tuple[Hazard, ...]]) -> None:
    suffix, hazards = row

    async def data_length(ctx: CaseContext) -> None:
        probe = await ctx.connect()
        for op in _ops(hazards):
            for size in _wrong_sizes(op):
                data = bytes(ctx.random.randrange(1, 256) & 0x3F for _ in range(size))
                answer = await probe.call_raw(op.opcode, data)
                ctx.check(check_reply(answer.request, answer.packets))
                what = f"{op.name} with {size} data bytes (layout: {op.request.fixed_size})"
                error = expect_refusal(ctx, answer, clause="request.data-length", what=what)
                if error is not None and error.error.code == "BDL":
                    expect_error_numbers(ctx, answer, error, _bdl_numbers(op, size), what=what)

    case(
        f"server.negative.data-length.{suffix}",
        summary=f"Wrong data lengths for every {'/'.join(hazards)} opcode draw a C error.",
        clauses=["request.data-length", "error-string.arg-values"],
        technique="negative",
        hazard=hazards[-1],
        deadline=10.0,
    )(data_length)


@case.each(_HAZARD_GROUPS)
def _float_case(row: tuple[str, tuple[Hazard, ...]]) -> None:
    suffix, hazards = row

    async def reserved_float(ctx: CaseContext) -> None:
        probe = await ctx.connect()
        for op in _ops(hazards):
            offsets = _float_offsets(op)
            if not offsets:
                continue
            values = await valid_values(ctx, probe, op)
            data = bytearray(encode_request(op.name, **values))
            at = ctx.random.choice(offsets)
            data[at : at + 4] = RESERVED_OPERAND
            answer = await probe.call_raw(op.opcode, bytes(data))
            ctx.check(check_reply(answer.request, answer.packets))
            expect_refusal(
                ctx,
                answer,
                clause="request.reserved-float",
                what=f"{op.name} with a reserved-operand float at data byte {at}",
            )

    case(
        f"server.negative.reserved-float.{suffix}",
        summary=f"A reserved-operand float in any {'/'.join(hazards)} request draws a C error.",
        clauses=["request.reserved-float", "float.reserved-operand"],
        technique="negative",
        hazard=hazards[-1],
        deadline=10.0,
    )(reserved_float)


@case(
    "server.negative.set-configuration-sizes",
    clauses=["set-configuration.data", "request.data-length"],
    technique="negative",
    hazard="config",
)
async def set_configuration_sizes(ctx: CaseContext) -> None:
    """Set configuration accepts one byte or one word; three bytes are a command error."""
    probe = await ctx.connect()
    for data in (b"\x01", b"\x00\x00"):
        answer = await probe.call_raw(SPEC.request("set-configuration").opcode, data)
        ctx.expect_done(
            answer, clause="set-configuration.data", expected=f"done for configuration data {data.hex()}"
        )
    answer = await probe.call_raw(SPEC.request("set-configuration").opcode, b"\x01\x00\x00")
    expect_refusal(ctx, answer, clause="request.data-length", what="set configuration with 3 data bytes")


@case(
    "server.negative.during-free-joint",
    clauses=["free-joint.awaits-next-packet", "free-joint.replies"],
    technique="negative",
    hazard="motion",
)
async def during_free_joint(ctx: CaseContext) -> None:
    """While free joint waits, even an unknown opcode is discarded with an empty done."""
    probe = await ctx.connect()
    answer = await probe.call("enable-power")
    answer = await probe.call("free-joint", joint=2)
    if not answer.is_response:
        refused(ctx, answer, "the case needs free joint of joint 2")
    discarded = await probe.call_raw(UNASSIGNED_OPCODES[0], b"\x01\x02\x03")
    ctx.expect_done(
        discarded,
        clause="free-joint.replies",
        expected="an empty done for the packet after free joint, whatever it is",
    )
    # its echo is the transcript invariant's (response.echoes-request-number)
    await expect_here_served(ctx, probe, "Here served normally afterwards")


OVERSIZE_EXTRA: Final = 4
"""Data bytes beyond the 488 a packet may carry, in the oversize frame."""


def _oversize_frame(packet: Packet, extra: int) -> bytes:
    """A TCP-link frame of ``packet`` with ``extra`` zero data bytes beyond its data, counted in nbytes and
    summed in the checksum: sound but for its size (the codec refuses to encode it)."""
    data = packet.data + bytes(extra)
    words = [*header_words(packet), *data_words(data)]
    words[1] = packet.fc << 12 | len(data)
    dest, source = packet.dest_host, packet.src_host
    words += [dest, source, chaos_checksum([*words, dest, source])]
    body = struct.pack(f">{len(words)}H", *words)
    return len(body).to_bytes(2, "big") + body


@case("server.negative.oversize-frame", clauses=["chaos.data.max-488"], technique="negative", deadline=8.0)
async def oversize_frame(ctx: CaseContext) -> None:
    """A frame claiming more than 488 data bytes is not served; the server survives it."""
    if parse_address(ctx.options.address).framing != "tcp":
        ctx.skip("the oversize frame is written on the TCP link only")
    ctx.auto_check = False
    probe = await ctx.connect()
    node = probe.conn.node
    link = node.links[0]
    transport = getattr(link, "_transport", None)
    if transport is None:
        ctx.skip("no raw transport to write an oversize frame on")
    host, index = probe.conn.peer
    info = probe.conn.info()
    assert info is not None
    packet = Packet(
        ServerOp.RESPONSE,
        host,
        index,
        node.address,
        probe.conn.conn_id,
        (info.last_sent + 1) & 0xFFFF,
        info.last_received,
        bytes(488),
    )
    transport.write(_oversize_frame(packet, OVERSIZE_EXTRA))
    first = await probe.next_packet(ctx.options.reply_timeout)
    served = first is not None and (
        (first.opcode == ServerOp.RESPONSE and len(first.data) > 2) or word(first.data) == packet.packet_no
    )
    if served:
        ctx.fail(
            "the oversize packet was served",
            clause="chaos.data.max-488",
            expected="the frame refused (LOS, or the link closed)",
            seen=first,
        )
    fresh = await ctx.connect()
    answer = await fresh.call("here")
    ctx.expect_response(
        answer, clause="chaos.data.max-488", expected="the server serving a new connection after it"
    )
