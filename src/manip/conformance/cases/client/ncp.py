"""The client's NCP and request matching: server packet numbers wrapping past 2^16, acknowledgements,
the server's window, pipelined requests, and (on CHUDP) duplicated and reordered packets."""

from __future__ import annotations

from typing import Any

from manip.codecs.lispm_text import encode_lispm
from manip.codecs.messages import encode_reply, response_layout
from manip.conformance.cases.client._support import (
    close,
    connect,
    expect_reply,
    layout_values,
    request,
    spec_request,
)
from manip.conformance.cases.client.describe import DESCRIPTION, chunks_at, expect_text, play_description
from manip.conformance.client.contract import Op
from manip.conformance.client.runner import client_context
from manip.conformance.client.server import Mangle, ServerSide, plain_answer
from manip.conformance.client.wire import ack_findings, numbering_findings, window_findings
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.links import NcpConfig

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
    for finding in numbering_findings(play.wire):
        ctx.expect(False, clause="ncp.packet-numbers", expected=finding.expected, actual=finding.actual)


@case("client.ncp.acknowledge", clauses=["ncp.acknowledge", "client.multi-packet"])
async def acknowledge(base: CaseContext) -> None:
    """A describe-self reply of 40 packets, more than the client's window: it gets through only if
    the client acknowledges what it received, and every packet is acknowledged by the end."""
    ctx = client_context(base)
    raw = encode_lispm(DESCRIPTION)
    cuts = sorted(ctx.random.sample(range(1, len(raw)), 39))
    play = await play_description(ctx, chunks_at(raw, cuts))
    for finding in ack_findings(play.wire, settle=0.5):
        ctx.expect(False, clause="ncp.acknowledge", expected=finding.expected, actual=finding.actual)
    expect_text(ctx, play, raw)


async def _pipelined(ctx: Any, names: tuple[str, ...], ncp: NcpConfig | None = None) -> Any:
    values = [layout_values(ctx.random, response_layout(spec_request(n))) for n in names]
    sent: list[tuple[int, bytes]] = []

    async def script(side: ServerSide) -> None:
        for i in range(len(names)):
            req = await side.next_request()
            if req is None:
                return
            payload = encode_reply(req.opcode, req.packet_no, **values[i])[2:]
            sent.append((req.packet_no, payload))
            await side.reply_payload(req, payload)
        while (req := await side.next_request(3.0)) is not None:
            await plain_answer(side, req)

    ops: list[Op] = [connect(0)]
    ops += [request(i + 1, n, pipeline=True) for i, n in enumerate(names)]
    ops += [Op(len(names) + 1, "await-replies"), close(len(names) + 2)]
    play = await ctx.play(ops, script, ncp=ncp)
    return play, sent


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
        actual=f"{len(sent)} reached the judging server",
    )
    for i, (name, (number, payload)) in enumerate(zip(PIPELINED, sent, strict=True)):
        expect_reply(ctx, play, i + 1, spec_request(name), payload, number, clause="client.reply-matching")


@case("client.ncp.window", clauses=["ncp.window", "client.reply-matching"])
async def window(base: CaseContext) -> None:
    """The judging server offers a window of 2: six pipelined requests never have more than 2
    unacknowledged, and all are answered."""
    ctx = client_context(base)
    names = ("here",) * 6
    play, sent = await _pipelined(ctx, names, NcpConfig(window=2))
    for finding in window_findings(play.wire, 2):
        ctx.expect(False, clause="ncp.window", expected=finding.expected, actual=finding.actual)
    ctx.expect(
        len(sent) == len(names),
        clause="client.reply-matching",
        expected=f"{len(names)} requests answered",
        actual=f"{len(sent)}",
    )
    for i, (number, payload) in enumerate(sent):
        expect_reply(ctx, play, i + 1, spec_request("here"), payload, number, clause="client.reply-matching")


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
