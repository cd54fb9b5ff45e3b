"""The client's NCP and request matching: server packet numbers wrapping past 2^16, acknowledgements,
the server's window, pipelined requests, and (on CHUDP) duplicated and reordered packets."""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Final

from manip.codecs.error_string import ErrorMessage
from manip.codecs.lispm_text import encode_lispm
from manip.codecs.messages import encode_reply, response_layout
from manip.codecs.packet import Packet
from manip.conformance.cases.client._support import (
    close,
    connect,
    expect_error_parts,
    expect_reply,
    expect_wire,
    layout_values,
    request,
    spec_request,
)
from manip.conformance.cases.client.asyncs import expect_async
from manip.conformance.cases.client.describe import DESCRIPTION, chunks_at, expect_text, play_description
from manip.conformance.client.contract import Op
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import Mangle, ServerSide, plain_answer
from manip.conformance.client.wire import ack_violations, numbering_violations, window_violations
from manip.conformance.judge.violation import missing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.links import NcpConfig
from manip.spec import SPEC
from manip.spec.constants import ServerOp

PIPELINED = ("here", "joint-angles", "wrist-version", "read-forces", "read-raw-gauges", "here")


@case("client.ncp.packet-numbers-wrap", clauses=["ncp.packet-numbers", "client.multi-packet"])
async def numbers_wrap(base: CaseContext) -> None:
    """The server's packet numbers start just below 2^16 and wrap inside a 20-packet describe-self
    reply: the text arrives whole and in order."""
    ctx = client_context(base)
    raw = encode_lispm(DESCRIPTION)
    cuts = sorted(ctx.random.sample(range(1, len(raw)), 19))
    first = 0x10000 - ctx.random.randint(3, 12)
    play = await play_description(ctx, chunks_at(raw, cuts), ncp=NcpConfig(first_packet_no=first))
    expect_text(ctx, play, raw)
    expect_wire(ctx, numbering_violations(play.wire), clause="ncp.packet-numbers")


@case("client.ncp.acknowledge", clauses=["ncp.acknowledge", "client.multi-packet"])
async def acknowledge(base: CaseContext) -> None:
    """A describe-self reply of 40 packets, more than the client's window: it gets through only if
    the client acknowledges what it received, and every packet is acknowledged by the end."""
    ctx = client_context(base)
    raw = encode_lispm(DESCRIPTION)
    cuts = sorted(ctx.random.sample(range(1, len(raw)), 39))
    play = await play_description(ctx, chunks_at(raw, cuts))
    expect_wire(ctx, ack_violations(play.wire, settle=0.5), clause="ncp.acknowledge")
    expect_text(ctx, play, raw)


Answered = list[tuple[int, bytes]]
"""(request number, reply payload) of each request the judging server answered, in order."""
Throttle = Callable[[ServerSide, int], Awaitable[None]]
"""What the judging server does before it takes the request of index ``i`` (holds, delays, shrinks)."""


async def _no_throttle(_side: ServerSide, _i: int) -> None:
    return None


async def _pipelined(
    ctx: ClientContext,
    names: tuple[str, ...],
    ncp: NcpConfig | None = None,
    *,
    throttle: Throttle = _no_throttle,
    read_all_first: bool = False,
    slack: float = 0.0,
) -> tuple[Play, Answered]:
    """``names`` sent pipelined and answered in order, with values drawn from the seed; ``throttle``
    runs before each request is taken; ``read_all_first`` takes every request before answering any (so
    only STS packets acknowledge them); ``slack`` seconds are added to each request's timeout."""
    values = [layout_values(ctx.random, response_layout(spec_request(n))) for n in names]
    sent: Answered = []

    async def script(side: ServerSide) -> None:
        taken: list[Packet] = []
        for i in range(len(names)):
            await throttle(side, i)
            req = await side.next_request()
            if req is None:
                return
            taken.append(req)
            if not read_all_first:
                await _answer(side, req, values[i], sent)
        if read_all_first:
            for req, value in zip(taken, values, strict=True):
                await _answer(side, req, value, sent)
        while (req := await side.next_request(3.0)) is not None:
            await plain_answer(side, req)

    timeout = ctx.timeout + slack if slack else None
    ops: list[Op] = [connect(0)]
    ops += [request(i + 1, n, pipeline=True, timeout=timeout) for i, n in enumerate(names)]
    ops += [Op(len(names) + 1, "await-replies"), close(len(names) + 2)]
    play = await ctx.play(ops, script, ncp=ncp)
    return play, sent


async def _answer(side: ServerSide, req: Packet, values: dict[str, Any], sent: Answered) -> None:
    payload = encode_reply(req.opcode, req.packet_no, **values)[2:]
    sent.append((req.packet_no, payload))
    await side.reply_payload(req, payload)


@case("client.pipeline.replies-matched", clauses=["client.reply-matching", "client.reply-data"])
async def pipeline(base: CaseContext) -> None:
    """Six requests sent without waiting for replies, answered in order with values drawn from the seed:
    each reply reaches its own request."""
    ctx = client_context(base)
    play, sent = await _pipelined(ctx, PIPELINED)
    ctx.expect(
        len(sent) == len(PIPELINED),
        clause="client.reply-matching",
        expected=f"{len(PIPELINED)} requests",
        seen=missing(f"{len(sent)} reached the judging server"),
    )
    for i, (name, (number, payload)) in enumerate(zip(PIPELINED, sent, strict=True)):
        expect_reply(ctx, play, i + 1, spec_request(name), payload, number, clause="client.reply-matching")


INTERLEAVED: Final = ("here", "joint-angles", "set-joint-angles", "here", "joint-angles", "set-joint-angles")
"""The pipelined requests of ``client.pipeline.interleaved`` (one of them answered by an error): three
reply layouts, each twice, and only requests every client has (no wrist extension)."""
WARNING: Final = ErrorMessage("PUMA", "W", "AWA", "Guard ~ stopped ~ segments", (3, 2))
REFUSAL: Final = ErrorMessage("PUMA", "E", "NAP", "No arm power")


@dataclass
class _Interleaving:
    """What the judging server sent in ``client.pipeline.interleaved``, for the judgement."""

    answers: dict[int, tuple[int, bytes]] = field(default_factory=dict)
    """Op id -> (request number, reply payload) of each request answered by a reply."""
    refused: int = 0
    """The op id answered by a non-fatal error."""
    asyncs: list[tuple[int, int, int]] = field(default_factory=list)
    order: list[int] = field(default_factory=list)
    """Op ids in the order their answers went out."""


def _answer_order(rng: random.Random, count: int) -> list[int]:
    """A seed-drawn order of ``count`` answers that is never the order of the requests."""
    order = list(range(count))
    while order == sorted(order):
        rng.shuffle(order)
    return order


async def _interleave(side: ServerSide, rng: random.Random, seen: _Interleaving) -> None:
    req = await side.next_request()  # request-notifications, answered at once
    if req is None:
        return
    await side.reply_payload(req, b"")
    taken: list[Packet] = []
    for _ in INTERLEAVED:
        if (req := await side.next_request()) is None:
            return
        taken.append(req)
    seen.refused = 2 + rng.randrange(len(INTERLEAVED))
    extras = [
        (ServerOp.ASYNCHRONOUS_RESPONSE, (2, 0, rng.randint(1, 0xFFF0))),
        (ServerOp.ASYNCHRONOUS_RESPONSE, (1, rng.randint(1, 2), rng.randrange(16))),
        (ServerOp.ASYNCHRONOUS_WARNING, None),
    ]
    slots = sorted(rng.sample(range(len(INTERLEAVED)), len(extras)))
    for position, index in enumerate(_answer_order(rng, len(INTERLEAVED))):
        if position in slots:
            opcode, words = extras[slots.index(position)]
            if words is None:
                await side.error(opcode, side.last_number, WARNING)
            else:
                await side.async_response(*words, number=taken[index].packet_no)
                seen.asyncs.append(words)
        op_id, req = 2 + index, taken[index]
        seen.order.append(op_id)
        if op_id == seen.refused:
            await side.error(ServerOp.NON_FATAL_ERROR, req.packet_no, REFUSAL)
            continue
        if req.opcode == SPEC.request("set-joint-angles").opcode:
            side.segment = rng.randint(1, 0xFFF0)
            payload = side.segment.to_bytes(2, "little")
        else:
            values = layout_values(rng, response_layout(spec_request(INTERLEAVED[index])))
            payload = encode_reply(req.opcode, req.packet_no, **values)[2:]
        seen.answers[op_id] = (req.packet_no, payload)
        await side.reply_payload(req, payload)
    await side.serve_plainly()


@case(
    "client.pipeline.interleaved",
    clauses=["client.reply-matching", "client.async-routing", "client.error-report"],
    hazard="motion",
)
async def interleaved(base: CaseContext) -> None:
    """Six pipelined requests answered in an order drawn from the seed (never the order they were
    sent), one of them by a non-fatal error, with asynchronous responses and a warning between the
    answers: each answer reaches its own request by the number it carries (a client that matches by
    arrival order is seen doing it), and the asynchronous packets answer none."""
    ctx = client_context(base)
    seen = _Interleaving()
    rng = ctx.random
    joints = {"joints": [float(rng.randint(-90, 90)) for _ in range(6)]}
    ops: list[Op] = [connect(0), request(1, "request-notifications", {"mask": 3})]
    for i, name in enumerate(INTERLEAVED):
        ops.append(request(i + 2, name, joints if name == "set-joint-angles" else None, pipeline=True))
    ops += [Op(len(ops), "await-replies"), close(len(ops) + 1)]
    play = await ctx.play(ops, lambda side: _interleave(side, rng, seen))
    ctx.note(f"answers went out for ops {seen.order}")
    for op_id, (number, payload) in seen.answers.items():
        name = INTERLEAVED[op_id - 2]
        expect_reply(ctx, play, op_id, spec_request(name), payload, number, clause="client.reply-matching")
    if seen.refused:
        expect_error_parts(
            ctx,
            play.answer(seen.refused),
            REFUSAL,
            "non-fatal-error",
            clause="client.error-report",
            play=play,
            ops=(seen.refused,),
        )
    for warning in [r for r in play.of("error", any_op=True) if r.get("origin") == "asynchronous-warning"]:
        expect_error_parts(
            ctx,
            warning,
            WARNING,
            "asynchronous-warning",
            clause="client.async-routing",
            play=play,
            ops=(None,),
        )
    for code, word2, word3 in seen.asyncs:
        handler = "guard-hit" if code == 1 else "segment-completed"
        expect_async(ctx, play, code, word2, word3, handler)
    warnings = [r for r in play.of("error", any_op=True) if r.get("origin") == "asynchronous-warning"]
    ctx.expect(
        len(warnings) == 1 and warnings[0].op is None,
        clause="client.async-routing",
        expected="one asynchronous-warning result, tied to no op",
        seen="; ".join(str(r) for r in warnings) or play.describe(),
    )


def _expect_window(ctx: ClientContext, play: Play, window: int, sent: Answered, count: int) -> None:
    """The window held on the wire (as offered at each moment), and every request answered and matched."""
    expect_wire(ctx, window_violations(play.wire, window), clause="ncp.window")
    ctx.expect(
        len(sent) == count,
        clause="client.reply-matching",
        expected=f"{count} requests answered",
        seen=f"{len(sent)}",
    )
    for i, (number, payload) in enumerate(sent):
        expect_reply(ctx, play, i + 1, spec_request("here"), payload, number, clause="client.reply-matching")


def _hold_time(ctx: ClientContext) -> float:
    """How long the judging server holds its acknowledgements: long enough for a client that ignores
    the window to send past it, short against the reply timeout (drawn from the seed)."""
    return round(min(0.25 * ctx.timeout, ctx.random.uniform(0.2, 0.4)), 3)


@case("client.ncp.window", clauses=["ncp.window", "client.reply-matching"])
async def window(base: CaseContext) -> None:
    """The judging server offers a window of 2 and holds its acknowledgements and replies before it
    takes each pair of requests: six pipelined requests never have more than 2 unacknowledged (a client
    that sends past the window is seen doing it), and all are answered."""
    ctx = client_context(base)
    names = ("here",) * 6
    hold = _hold_time(ctx)

    async def throttle(side: ServerSide, i: int) -> None:
        if i % 2 == 0:
            await side.hold(hold)

    play, sent = await _pipelined(ctx, names, NcpConfig(window=2), throttle=throttle, slack=3 * hold)
    _expect_window(ctx, play, 2, sent, len(names))


@case("client.ncp.window-opens-late", clauses=["ncp.window", "client.reply-matching"])
async def window_opens_late(base: CaseContext) -> None:
    """The judging server (window 2) takes each request at once but answers none until all six are in,
    so only its STS packets open the window, and it holds each STS a while: the client waits for the
    late STS before it sends past the window."""
    ctx = client_context(base)
    names = ("here",) * 6
    hold = _hold_time(ctx)

    async def throttle(side: ServerSide, i: int) -> None:
        if i % 2 == 0 and await side.arrived():  # the STS of the pair that fills the window is held
            side.delay_status(hold)

    play, sent = await _pipelined(
        ctx, names, NcpConfig(window=2), throttle=throttle, read_all_first=True, slack=4 * hold
    )
    _expect_window(ctx, play, 2, sent, len(names))


@case(
    "client.ncp.window-shrinks",
    clauses=["ncp.window", "client.reply-matching"],
    summary="an STS acknowledging nothing new shrinks the window to 1: 1 request unacknowledged at most",
)
async def window_shrinks(base: CaseContext) -> None:
    """The judging server offers a window of 4, holds its acknowledgements until the client has filled
    it, then shrinks the window to 1 (an STS that acknowledges nothing new) and takes the requests one
    by one, holding its acknowledgements and replies before every other one: from the shrink on, the
    client never has more than one request unacknowledged when it sends (a client that keeps the wider
    window, or reads an STS's window only when it acknowledges something new, sends during a hold)."""
    ctx = client_context(base)
    names = ("here",) * 8
    hold = _hold_time(ctx)

    async def throttle(side: ServerSide, i: int) -> None:
        if i == 0:
            await side.hold(hold)
            side.offer_window(1)
        elif i % 2 == 1:
            await side.hold(hold)

    play, sent = await _pipelined(ctx, names, NcpConfig(window=4), throttle=throttle, slack=6 * hold)
    _expect_window(ctx, play, 4, sent, len(names))


OPENED: Final = 4
"""The window ``client.ncp.window-opens-by-status`` opens to."""


@case(
    "client.ncp.window-opens-by-status",
    clauses=["ncp.window", "client.reply-matching"],
    summary="an STS acknowledging nothing new opens the window from 1 to 4: the client sends into it",
)
async def window_opens_by_status(base: CaseContext) -> None:
    """The judging server offers a window of 1 and takes nothing; once the client's first request is in,
    it opens the window to 4 by an STS that acknowledges nothing new: the client sends three more
    requests into it before anything is acknowledged (a client that reads an STS's window only when
    it acknowledges something new waits for an acknowledgement that does not come), and all four are
    answered."""
    ctx = client_context(base)
    names = ("here",) * OPENED
    hold = _hold_time(ctx)
    wait_for = max(1.0, ctx.timeout / 2)
    values = [layout_values(ctx.random, response_layout(spec_request(n))) for n in names]
    sent: Answered = []
    filled: list[bool] = []

    async def script(side: ServerSide) -> None:
        if not await side.arrived():
            return
        await side.hold(hold)
        side.offer_window(OPENED)
        filled.append(await side.arrived(wait_for, count=OPENED))
        for value in values:
            if (req := await side.next_request()) is None:
                return
            await _answer(side, req, value, sent)
        await side.serve_plainly()

    timeout = ctx.timeout + hold + wait_for
    ops: list[Op] = [connect(0)]
    ops += [request(i + 1, n, pipeline=True, timeout=timeout) for i, n in enumerate(names)]
    ops += [Op(len(names) + 1, "await-replies"), close(len(names) + 2)]
    play = await ctx.play(ops, script, ncp=NcpConfig(window=OPENED), offer=1)
    ctx.expect(
        bool(filled) and filled[0],
        clause="ncp.window",
        expected=f"{OPENED} requests sent once an STS acknowledging nothing new opened the window to "
        f"{OPENED} (every STS sets the window)",
        seen=f"fewer than {OPENED} had arrived {wait_for:g} s after the STS" if filled else "no request came",
    )
    _expect_window(ctx, play, 1, sent, len(names))


@case("client.chudp.duplicate-reorder", clauses=["ncp.retransmission", "client.multi-packet"])
async def duplicate_reorder(base: CaseContext) -> None:
    """On CHUDP the judging server duplicates and reorders the packets of a 12-packet describe-self
    reply: the client's NCP delivers each once and in order."""
    ctx = client_context(base)
    if ctx.link != "chudp":
        ctx.skip("needs the CHUDP link (--link chudp): TCP neither duplicates nor reorders")
    raw = encode_lispm(DESCRIPTION)
    cuts = sorted(ctx.random.sample(range(1, len(raw)), 11))
    mangle = Mangle(duplicate=0.3, reorder=0.3, rng=ctx.random)
    play = await play_description(ctx, chunks_at(raw, cuts), mangle=mangle)
    expect_text(ctx, play, raw, clause="ncp.retransmission")
