"""Timeouts: a reply that comes late but within the request's timeout is delivered; a request without a
reply fails with a timeout, neither early nor much later."""

from __future__ import annotations

import asyncio
from typing import Final

from manip.conformance.cases.client._support import close, connect, request
from manip.conformance.client.runner import client_context
from manip.conformance.client.server import ServerSide
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext

TIMEOUT: Final = 2.0
LATE_SLACK: Final = 1.5
"""How long after its timeout a request may be reported timed out (a busy machine, a slow harness)."""


@case("client.timing.reply-near-timeout", clauses=["client.reply-wait"])
async def reply_near_timeout(base: CaseContext) -> None:
    """A reply sent at 60-70 % of the request's timeout is delivered, not given up (the rest is margin
    for a loaded machine; a client that gives up at half its timeout fails)."""
    ctx = client_context(base)
    delay = TIMEOUT * ctx.random.uniform(0.6, 0.7)
    values = [float(ctx.random.randint(-180, 180)) for _ in range(6)]

    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is not None:
            await asyncio.sleep(delay)
            await side.reply(req, joints=values)
            await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "joint-angles", timeout=TIMEOUT), close(2)], script)
    answer = play.answer(1)
    delivered = f"the reply sent {delay:.2f} s after the request (timeout {TIMEOUT:g} s) delivered"
    ctx.expect_result(answer, values={"joints": values}, clause="client.reply-wait", expected=delivered)


@case("client.timing.no-reply", clauses=["client.reply-wait"])
async def no_reply(base: CaseContext) -> None:
    """A request the server never answers fails with a timeout once its timeout has passed."""
    ctx = client_context(base)

    async def script(side: ServerSide) -> None:
        await side.next_request()  # taken, never answered
        await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "here", timeout=TIMEOUT), close(2)], script)
    answer = play.answer(1)
    ctx.expect_result(answer, "timeout", clause="client.reply-wait", expected="op 1 failed with a timeout")
    assert answer is not None
    sent = [r.t for r in play.requests()]
    reported = play.time_of(answer)
    if sent and reported is not None:
        waited = reported - sent[0]
        ctx.expect(
            TIMEOUT * 0.95 <= waited <= TIMEOUT + LATE_SLACK,
            clause="client.reply-wait",
            expected=f"the timeout reported {TIMEOUT:g} to {TIMEOUT + LATE_SLACK:g} s after the request",
            seen=f"{waited:.2f} s after it",
        )
