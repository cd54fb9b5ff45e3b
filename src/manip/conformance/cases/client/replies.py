"""Replies read exactly: every request with a data reply, its values drawn from the seed, and every
request's data as the client builds them."""

from __future__ import annotations

from typing import Any

from manip.codecs.messages import encode_reply, encode_request, response_layout
from manip.conformance.cases.client._support import (
    close,
    connect,
    expect_reply,
    layout_values,
    request,
)
from manip.conformance.client.runner import client_context
from manip.conformance.client.server import ServerSide, plain_answer
from manip.conformance.judge.violation import missing, showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from manip.spec.model import RequestOpcode
from manip.spec.notation import a_or_an, octal

DATA_REPLIES = [op for op in SPEC.requests.values() if op.response.form == "data"]
WITH_ARGS = [op for op in SPEC.requests.values() if op.request.fields]
_MOVES = ("move", "straight-move")


@case.each(DATA_REPLIES)
def _reply_case(op: RequestOpcode) -> None:
    has_floats = any(f.type.element == "float" for f in response_layout(op).fields)
    clauses = ["client.reply-data", "client.reply-matching"] + (["float.format"] if has_floats else [])

    async def reply_values(base: CaseContext) -> None:
        ctx = client_context(base)
        rng = ctx.random
        args = layout_values(rng, op.request) if op.request.fields else None
        if op.name == "examine-wrist" and args is not None:
            args["count"] = rng.randint(1, 6)
        values = layout_values(rng, response_layout(op))
        if op.name == "examine-wrist" and args is not None:
            values["words"] = [rng.randint(0, 0xFFFF) for _ in range(args["count"])]
        sent: dict[str, Any] = {}

        async def script(side: ServerSide) -> None:
            req = await side.next_request()
            if req is None:
                return
            sent["number"] = req.packet_no
            sent["payload"] = encode_reply(op.opcode, req.packet_no, **values)[2:]
            await side.reply(req, **values)
            await side.serve_plainly()

        play = await ctx.play([connect(0), request(1, op.name, args), close(2)], script)
        ctx.expect(
            "number" in sent,
            clause="client.reply-matching",
            expected=f"{a_or_an(op.name)} request",
            seen=missing("no request reached the judging server"),
        )
        reply = expect_reply(ctx, play, 1, op, sent["payload"], sent["number"], clause="client.reply-data")
        ctx.expect(
            reply.get("request_number") in (None, sent["number"]),
            clause="client.reply-matching",
            expected=f"the reply reported for request #{sent['number']}",
            seen=str(reply),
        )

    case(
        f"client.reply.{op.name}",
        clauses=clauses,
        technique="property",
        hazard=op.hazard,
        summary=f"{op.title}: a reply with values drawn from the seed is reported exactly, floats to the bit",
    )(reply_values)


def _data_clause(op: RequestOpcode) -> str:
    """The clause a request's data are judged under: the opcode's own (``hand.data``...) when the spec
    has one binding the client, else the general one."""
    if op.name in _MOVES:
        return "move.transform-data"
    own = SPEC.clauses.get(f"{op.name}.data")
    return own.id if own is not None and own.party in ("client", "both") else "request-data.types"


@case.each(WITH_ARGS)
def _request_case(op: RequestOpcode) -> None:
    clauses = ["request.opcode-range", _data_clause(op)]

    async def request_data(base: CaseContext) -> None:
        ctx = client_context(base)
        args = layout_values(ctx.random, op.request)
        got: list[Any] = []

        async def script(side: ServerSide) -> None:
            req = await side.next_request()
            if req is None:
                return
            got.append(req)
            await plain_answer(side, req)
            await side.serve_plainly()

        play = await ctx.play([connect(0), request(1, op.name, args), close(2)], script)
        ctx.expect(
            bool(got),
            clause="request.opcode-range",
            expected=f"{a_or_an(op.name)} request",
            seen=missing(f"no request reached the judging server:\n{play.describe()}"),
        )
        req = got[0]
        ctx.expect(
            req.opcode == op.opcode,
            clause="request.opcode-range",
            expected=f"opcode {octal(op.opcode)}",
            seen=f"opcode {octal(req.opcode)}",
        )
        want = encode_request(op.opcode, **args)
        ctx.expect(
            req.data == want,
            clause=clauses[1],
            expected=f"{op.name} data {want.hex()} ({len(want)} bytes) for {args}",
            seen=showing(req, f"{req.data.hex()} ({len(req.data)} bytes)"),
        )

    case(
        f"client.request.{op.name}",
        clauses=clauses,
        technique="property",
        hazard=op.hazard,
        summary=f"{op.title}: arguments drawn from the seed go out in the opcode's layout, to the byte",
    )(request_data)


@case(
    "client.reply.out-of-sequence",
    clauses=["client.out-of-sequence"],
    technique="scripted",
    hazard="read-only",
    summary="a RESPONSE numbered for no request is signalled as out of sequence and fails no request",
)
async def out_of_sequence(base: CaseContext) -> None:
    """Before a here request's reply, the judge sends a RESPONSE whose number no request of the client's
    has; the client reports it (an ``error`` of kind ``out-of-sequence``) and still reads the reply."""
    ctx = client_context(base)
    values = layout_values(ctx.random, response_layout(SPEC.request("here")))
    sent: dict[str, Any] = {}

    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is None:
            return
        stray = (req.packet_no + 0x4000) & 0xFFFF  # far from any number the client has used or will use
        sent.update(number=req.packet_no, stray=stray)
        sent["payload"] = encode_reply(SPEC.request("here").opcode, req.packet_no, **values)[2:]
        await side.send(ServerOp.RESPONSE, stray.to_bytes(2, "little"))
        await side.reply(req, **values)
        await side.serve_plainly()

    play = await ctx.play([connect(0), request(1, "here"), close(2)], script)
    if "number" not in sent:
        ctx.expect(
            False, clause="client.out-of-sequence", expected="a here request", seen=missing("none came")
        )
        return
    # the stray packet fails no other request: the here request still gets its own reply
    expect_reply(
        ctx, play, 1, SPEC.request("here"), sent["payload"], sent["number"], clause="client.out-of-sequence"
    )
    signalled = [
        r
        for r in play.of("error", any_op=True)
        if r.get("kind") == "out-of-sequence" and r.get("request_number") == sent["stray"] and r.op is None
    ]
    ctx.expect(
        bool(signalled),
        clause="client.out-of-sequence",
        expected=f"an error of kind out-of-sequence, op null, request_number {sent['stray']}: the request "
        "number the stray RESPONSE carries in its first data word, not its Chaos packet number",
        seen="; ".join(str(r) for r in play.of("error", any_op=True)) or "no error reported",
    )
