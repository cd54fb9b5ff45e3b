"""The connection: the initial RESPONSE, the close, a server that closes or drops it mid-request, a
refusal as busy."""

from __future__ import annotations

import asyncio

from manip.conformance.cases.client._support import close, connect, expect_wire, request
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide
from manip.conformance.client.wire import initial_response_violations
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.notation import octal_words

INITIAL_DELAY = 0.3


@case("client.connect.initial-response", clauses=["client.initial-response", "client.reply-matching"])
async def initial_response(base: CaseContext) -> None:
    """The initial RESPONSE comes late: no request goes out before it, and it is not taken as a reply."""
    ctx = client_context(base)
    values = [float(ctx.random.randint(-500, 500)) for _ in range(12)]

    async def script(side: ServerSide) -> None:
        early = await side.next_request(INITIAL_DELAY)
        await side.send(ServerOp.RESPONSE, side.rfc_number.to_bytes(2, "little"))
        req = early or await side.next_request()
        if req is not None:
            await side.reply(req, transform=values)
            await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "here"), close(2)], script, initial=False)
    expect_wire(ctx, initial_response_violations(play.wire), clause="client.initial-response")
    answer = play.answer(1)
    after = f"here answered with the transform sent after the initial RESPONSE ({values})"
    ctx.expect_result(answer, values={"transform": values}, clause="client.reply-matching", expected=after)


@case("client.close.sequence", clauses=["client.close"])
async def close_sequence(base: CaseContext) -> None:
    """After its requests are answered the client closes with a CLS (an EOF first, optionally), and the
    harness reports the connection closed."""
    ctx = client_context(base)

    async def script(side: ServerSide) -> None:
        await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "joint-angles"), close(2)], script)
    ends = [
        r.packet.opcode for r in play.wire if r.dir == "c2s" and r.packet.opcode in (ChaosOp.EOF, ChaosOp.CLS)
    ]
    ctx.expect(
        ChaosOp.CLS in ends,
        clause="client.close",
        expected="a CLS from the client after close",
        seen=f"client control packets: {octal_words(ends)}",
    )
    ctx.expect(
        play.one("state", 2) is not None and play.one("state", 2).get("state") == "closed",  # type: ignore[union-attr]
        clause="client.close",
        expected="state closed reported for the close op",
        seen=play.describe(),
    )


def _lost(ctx: ClientContext, play: Play, reason_part: str | None) -> None:
    lost = [r for r in play.of("state", any_op=True) if r.get("state") == "lost"]
    ctx.expect(
        bool(lost), clause="client.connection-lost", expected="state lost reported", seen=play.describe()
    )
    if reason_part is not None:
        ctx.expect(
            reason_part in str(lost[0].get("reason", "")),
            clause="client.connection-lost",
            expected=f"the reason naming the server's text {reason_part!r}",
            seen=str(lost[0]),
        )
    for op in (1, 2):
        answer = play.answer(op)
        ctx.expect_result(
            answer,
            "not-connected",
            clause="client.connection-lost",
            expected=f"op {op} failed as not-connected (in flight when the connection went, or after)",
        )


@case("client.conn.cls-mid-request", clauses=["client.connection-lost"])
async def cls_mid_request(base: CaseContext) -> None:
    """The server closes the connection (CLS with a reason) while a request waits for its reply."""
    ctx = client_context(base)
    reason = f"Puma going away {ctx.random.randint(100, 999)}"

    async def script(side: ServerSide) -> None:
        if await side.next_request() is not None:
            await asyncio.sleep(0.05)
            side.close_now(reason)

    play = await ctx.play([connect(0), request(1, "here"), request(2, "here"), close(3)], script)
    _lost(ctx, play, reason)


@case("client.conn.los-mid-request", clauses=["client.connection-lost"])
async def los_mid_request(base: CaseContext) -> None:
    """The server's NCP sends a LOS (with a reason) while a request waits for its reply."""
    ctx = client_context(base)
    reason = f"Connection lost by the Puma {ctx.random.randint(100, 999)}"

    async def script(side: ServerSide) -> None:
        if await side.next_request() is not None:
            await asyncio.sleep(0.05)
            side.send_los(reason)

    play = await ctx.play([connect(0), request(1, "here"), request(2, "here"), close(3)], script)
    _lost(ctx, play, reason)


@case("client.conn.lost-mid-request", clauses=["client.connection-lost"])
async def lost_mid_request(base: CaseContext) -> None:
    """The link under the connection drops (no CLS) while a request waits for its reply."""
    ctx = client_context(base)
    if ctx.link == "chudp":
        ctx.skip("a dropped link shows on a stream link (tcp, chaosd); on CHUDP it is silence for 90 s")

    async def script(side: ServerSide) -> None:
        if await side.next_request() is not None:
            await asyncio.sleep(0.05)
            side.drop_link()

    play = await ctx.play([connect(0), request(1, "here"), request(2, "here"), close(3)], script)
    _lost(ctx, play, None)


@case("client.conn.busy", clauses=["client.connection-lost"])
async def busy(base: CaseContext) -> None:
    """The server refuses the connection as busy (CLS answering the RFC): reported refused with the
    server's reason, and nothing sent."""
    ctx = client_context(base)
    reason = "Busy: the robot already has a client"

    async def script(side: ServerSide) -> None:
        return

    play = await ctx.play([connect(0), request(1, "here"), close(2)], script, refuse=reason)
    state = play.one("state", 0)
    ctx.expect(
        state is not None and state.get("state") == "refused" and "Busy" in str(state.get("reason")),
        clause="client.connection-lost",
        expected=f"state refused with the reason {reason!r}",
        seen=str(state) if state is not None else play.describe(),
    )
    answer = play.answer(1)
    ctx.expect_result(
        answer,
        "not-connected",
        clause="client.connection-lost",
        expected="the request after the refusal failed as not-connected",
    )
