"""What a server run can see of the link and the NCP: well-formed frames, consecutive packet numbers,
and asynchronous warnings in the error format when the arm produces any."""

from __future__ import annotations

from itertools import pairwise
from typing import Final

from manip.conformance.cases._support import UNASSIGNED_OPCODES
from manip.conformance.judge.checks import check_error_packet
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.links.address import parse_address
from manip.spec.constants import ServerOp

_FRAME_CLAUSES = (
    "chaos.header.layout",
    "chaos.header.unused-byte-zero",
    "chaos.header.nbytes",
    "chaos.data.byte-order",
    "chaos.opcode.legal",
)


async def _exchange(probe: Probe) -> None:
    """Traffic of every server packet shape: multi-packet text, data, done, error."""
    await probe.call("describe-self")
    await probe.call("here")
    await probe.call("set-speed", factor=1.0)
    await probe.call_raw(UNASSIGNED_OPCODES[0])


_LINK_FRAMES: Final[tuple[tuple[str, tuple[str, ...]], ...]] = (
    ("tcp", ("link.tcp.framing",)),
    ("chudp", ("chudp.header", "chudp.length", "chudp.word-order", "chudp.trailer", "chudp.checksum")),
    ("chaosd", ("link.chaosd.framing",)),
)
"""Each link framing a server may be reached on, and the clauses of its frames."""


@case.each(_LINK_FRAMES)
def _frames_case(row: tuple[str, tuple[str, ...]]) -> None:
    scheme, clauses = row

    async def frames(ctx: CaseContext) -> None:
        if parse_address(ctx.options.address).framing != scheme:
            ctx.skip(f"the target is not on a {scheme} link")
        probe = await ctx.connect()
        await _exchange(probe)
        stats = probe.conn.node.link_stats()
        ctx.expect(
            stats.bad_total == 0,
            clause=clauses[0],
            expected=f"every {scheme} frame from the server well formed",
            actual=f"{stats.bad_total} bad frame(s): {dict(stats.bad)}",
        )

    case(
        f"server.link.{scheme}-frames",
        clauses=[*clauses, *_FRAME_CLAUSES],
        summary=f"Every frame the server sends on a {scheme} link decodes (header, length, checksum).",
    )(frames)


@case("server.link.packet-numbers", clauses=["ncp.packet-numbers"])
async def packet_numbers(ctx: CaseContext) -> None:
    """The server's data packets are numbered consecutively (modulo 2^16)."""
    probe = await ctx.connect()
    await _exchange(probe)
    numbers = [p.packet_no for p in probe.packets if p.direction == "s2c" and not p.is_close]
    bad = [(a, b) for a, b in pairwise(numbers) if b != (a + 1) & 0xFFFF]
    ctx.expect(
        not bad,
        clause="ncp.packet-numbers",
        expected="consecutive packet numbers",
        actual=f"jumps {bad[:5]} in {numbers[:20]}",
    )


@case(
    "server.async.warning-format",
    clauses=["async-warning.format", "async-error.request-number"],
    hazard="motion",
    deadline=8.0,
)
async def warning_format(ctx: CaseContext) -> None:
    """Asynchronous warnings and errors seen during fast moves have the error format (W for 205).

    Skipped when the target produces none (the reference arm warns only when a joint lags)."""
    probe = await ctx.connect()
    await probe.call("enable-power")
    await probe.drain(0.3)
    seen = [
        p
        for p in probe.packets
        if p.direction == "s2c" and p.opcode in (ServerOp.ASYNCHRONOUS_WARNING, ServerOp.ASYNCHRONOUS_ERROR)
    ]
    if not seen:
        ctx.skip("no asynchronous warning or error was produced")
    for packet in seen:
        ctx.check(check_error_packet(packet))
