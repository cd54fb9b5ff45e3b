"""Asynchronous responses: segment completions and guard hits between a request and its reply, for
segments queued earlier, delivered apart from the replies."""

from __future__ import annotations

from manip.codecs.messages import encode_async
from manip.conformance.cases.client._support import close, connect, request, wait
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec.constants import ServerOp

NOTIFY_ALL = {"mask": 3}


def _joints(ctx: ClientContext) -> dict[str, list[float]]:
    return {"joints": [float(ctx.random.randint(-90, 90)) for _ in range(6)]}


def expect_async(ctx: ClientContext, play: Play, code: int, word2: int, word3: int, handler: str) -> None:
    found = [
        r
        for r in play.of("async", any_op=True)
        if (r.get("code"), r.get("word2"), r.get("word3")) == (code, word2, word3)
    ]
    ctx.expect(
        bool(found),
        clause="client.async-routing",
        expected=f"an async result code {code} words {word2} {word3}",
        seen=play.describe(),
    )
    ctx.expect(
        found[0].get("handler") == handler,
        clause="client.async-routing",
        expected=f"handled as {handler}",
        seen=str(found[0]),
    )
    numbers = {
        int.from_bytes(r.packet.data[:2], "little")
        for r in play.wire
        if r.dir == "s2c"
        and r.packet.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
        and r.packet.data[2:8] == encode_async(0, code, word2, word3)[2:8]
    }
    ctx.expect(
        found[0].op is None and found[0].get("request_number") in numbers,
        clause="client.async-routing",
        expected=f"op null and request_number {' or '.join(str(n) for n in sorted(numbers))} (the async "
        "packet's first word): an asynchronous response belongs to no op",
        seen=str(found[0]),
    )


def expect_segment(ctx: ClientContext, play: Play, op: int, segment: int) -> None:
    answer = play.answer(op)
    shown = str(answer) if answer is not None else play.describe()
    expected = f"op {op} answered with segment {segment}"
    ctx.expect_result(
        answer, values={"segment": segment}, clause="client.async-routing", expected=expected, seen=shown
    )


@case("client.async.segment-interleaved", clauses=["client.async-routing"], hazard="motion")
async def segment_interleaved(base: CaseContext) -> None:
    """A segment completion for an earlier segment arrives between set-joint-angles and its reply; both
    are delivered, each where it belongs."""
    ctx = client_context(base)
    first = ctx.random.randint(1, 0xFFF0)

    async def script(side: ServerSide) -> None:
        req = await side.next_request()  # request-notifications
        if req is None:
            return
        await side.reply_payload(req, b"")
        req = await side.next_request()
        if req is None:
            return
        await side.async_response(2, 0, first, number=req.packet_no)
        await side.reply_payload(req, (first + 1).to_bytes(2, "little"))
        await side.async_response(2, 0, first + 1)
        await side.serve_plainly()

    ops = [
        connect(0),
        request(1, "request-notifications", NOTIFY_ALL),
        request(2, "set-joint-angles", _joints(ctx)),
        wait(3, 0.5),
        close(4),
    ]
    play = await ctx.play(ops, script)
    expect_segment(ctx, play, 2, first + 1)
    expect_async(ctx, play, 2, 0, first, "segment-completed")
    expect_async(ctx, play, 2, 0, first + 1, "segment-completed")


@case("client.async.guard-hits", clauses=["client.async-routing"], hazard="motion")
async def guard_hits(base: CaseContext) -> None:
    """Guard hits (one that lets the motion continue, one that stops it) and segment completions for
    queued segments, some between a request and its reply, are each delivered with their words."""
    ctx = client_context(base)
    guard_a, guard_b = ctx.random.sample(range(16), 2)

    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is None:
            return
        await side.reply_payload(req, b"")
        for segment in (1, 2):
            req = await side.next_request()
            if req is None:
                return
            await side.reply_payload(req, segment.to_bytes(2, "little"))
        req = await side.next_request()  # here: interleave before its reply
        if req is None:
            return
        await side.async_response(1, 2, guard_a)
        await side.async_response(2, 0, 1)
        await side.async_response(1, 1, guard_b)
        await side.reply(req, transform=[0.0] * 12)
        await side.serve_plainly()

    ops = [
        connect(0),
        request(1, "request-notifications", NOTIFY_ALL),
        request(2, "set-joint-angles", _joints(ctx)),
        request(3, "set-joint-angles", _joints(ctx)),
        request(4, "here"),
        wait(5, 0.2),
        close(6),
    ]
    play = await ctx.play(ops, script)
    expect_segment(ctx, play, 2, 1)
    expect_segment(ctx, play, 3, 2)
    expect_async(ctx, play, 1, 2, guard_a, "guard-hit")
    expect_async(ctx, play, 2, 0, 1, "segment-completed")
    expect_async(ctx, play, 1, 1, guard_b, "guard-hit")
    answer = play.answer(4)
    own = "here answered by its own reply, not by an asynchronous response"
    ctx.expect_result(answer, values={"transform": [0.0] * 12}, clause="client.async-routing", expected=own)
