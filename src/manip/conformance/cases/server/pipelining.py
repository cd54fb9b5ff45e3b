"""Requests pipelined behind a multi-packet reply: a client sends describe self and, without waiting, more
requests; the server must end describe self's reply with its empty terminator before it answers them.

Part I §3 of the 1985 guide: each request gets one reply, and the last packet of a multi-packet reply must
be detectable.  A client pairs replies with its requests in order (erratum ``capture-pairing``), so a
reply that overtakes the terminator is read as part of describe self's text, and every answer after it
belongs to the wrong request.  A server whose request loop re-enters itself does exactly that, and only
when requests arrive while it is still sending; a case that waits for each answer never shows it.
"""

from __future__ import annotations

from typing import Final

from manip.conformance.judge.checks import ANSWER_OPCODES, WirePacket, describe, word
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.spec import RequestName
from manip.spec.constants import ServerOp

BEHIND: Final[tuple[RequestName, ...]] = ("here", "joint-angles")
"""The read-only requests sent behind describe self, before its reply."""
MAX_PACKETS: Final = 256
"""The most answer packets the case reads (describe self's text takes a few)."""


async def _answers(ctx: CaseContext, probe: Probe, first: int, later: list[int]) -> list[WirePacket]:
    """The answer packets, in arrival order, up to the replies to every request sent (or a silence of the
    reply timeout, the end of the connection, :data:`MAX_PACKETS`)."""
    got: list[WirePacket] = []
    waiting = set(later)
    terminated = False
    while (waiting or not terminated) and len(got) < MAX_PACKETS:
        packet = await probe.next_packet(ctx.options.reply_timeout)
        if packet is None:
            break
        if packet.opcode not in ANSWER_OPCODES:
            continue  # asynchronous packets: not answers
        got.append(packet)
        number = word(packet.data)
        if number == first:
            terminated |= packet.opcode == ServerOp.RESPONSE and len(packet.data) <= 2
        else:
            waiting.discard(number)
    return got


@case("server.describe.pipelined", clauses=["request.one-reply", "multi.terminated-by-empty"])
async def describe_pipelined(ctx: CaseContext) -> None:
    """Requests sent behind describe self, before its reply: its empty terminator comes before theirs."""
    probe = await ctx.connect()
    first = await probe.send("describe-self")
    later = [await probe.send(name) for name in BEHIND]
    got = await _answers(ctx, probe, first, later)
    ends = [
        i
        for i, p in enumerate(got)
        if word(p.data) == first and p.opcode == ServerOp.RESPONSE and len(p.data) <= 2
    ]
    ctx.require(
        ends,
        clause="multi.terminated-by-empty",
        expected=f"describe self (#{first}) ended by an empty RESPONSE echoing #{first}",
        seen=showing(got[-1] if got else None, f"{len(got)} answer packet(s), none of them its terminator"),
    )
    end = ends[0]
    early = [p for p in got[:end] if word(p.data) in later]
    ctx.expect(
        not early,
        clause="request.one-reply",
        expected=f"describe self's terminator (#{first}) before the replies to "
        + ", ".join(f"#{n}" for n in later)
        + ", sent behind it",
        seen=showing(
            early[0],
            f"{describe(early[0])} came as answer packet {got.index(early[0]) + 1}, before the terminator "
            f"(answer packet {end + 1})",
        )
        if early
        else None,
    )
    order = [word(p.data) for p in got if word(p.data) in later]
    ctx.expect(
        order == later,
        clause="request.one-reply",
        expected="one reply to each request sent behind it, in order: " + ", ".join(f"#{n}" for n in later),
        seen="replies to " + (", ".join(f"#{n}" for n in order) or "none"),
    )
    ctx.note(f"{len(got)} answer packets; describe self's terminator was answer packet {end + 1}")
