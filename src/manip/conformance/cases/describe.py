"""Describe self (E.1 Opcode 200): the multi-packet reply and its alist."""

from __future__ import annotations

from manip.codecs.lisp import LispValue
from manip.conformance.case import case
from manip.conformance.checks import (
    check_description_entries,
    check_reply,
    description_operations,
    multi_text,
    parse_description,
)
from manip.conformance.context import Answer, CaseContext, Probe
from manip.spec import SPEC


async def _describe(ctx: CaseContext, probe: Probe) -> Answer:
    answer = await probe.call("describe-self")
    ctx.check(check_reply(answer.request, answer.packets))
    return answer


async def _entries(ctx: CaseContext, probe: Probe | None = None) -> dict[str, LispValue]:
    probe = probe or await ctx.connect()
    answer = await _describe(ctx, probe)
    entries, findings = parse_description(multi_text(answer.packets))
    ctx.check(findings)
    assert entries is not None
    return entries


@case(
    "server.describe.reply-shape",
    clauses=[
        "describe.reply-shape",
        "multi.terminated-by-empty",
        "multi.same-request-number",
        "request.one-reply",
    ],
)
async def reply_shape(ctx: CaseContext) -> None:
    """Text packets with the request number, ended by an empty RESPONSE, and nothing more."""
    probe = await ctx.connect()
    answer = await _describe(ctx, probe)
    ctx.expect(
        answer.terminated,
        clause="multi.terminated-by-empty",
        expected="an empty RESPONSE ending the reply",
        actual=f"{len(answer.packets)} packet(s), no terminator",
        data=answer.packets[-1].data,
    )
    ctx.note(f"{len(answer.packets) - 1} text packet(s)")
    after = await probe.call("here")  # the next answer belongs to the next request
    ctx.expect(
        after.number == after.request.packet_no,
        clause="request.one-reply",
        expected=f"the reply to request #{after.request.packet_no} after the terminator",
        actual=str(after),
        data=after.data,
    )


@case(
    "server.describe.alist",
    clauses=["describe.alist-readable", "describe.alist-shape", "describe.numbers-octal"],
)
async def alist(ctx: CaseContext) -> None:
    """The concatenated text is one alist of keyword entries, numbers in octal."""
    entries = await _entries(ctx)
    ops = description_operations(entries)
    wrong = [o for o in ops if not 0o200 <= o <= 0o377]
    ctx.expect(
        not wrong,
        clause="describe.numbers-octal",
        expected=":operations opcodes in 200-377 read in octal",
        actual=f"{[oct(o) for o in wrong]} (written in decimal?)",
    )


@case("server.describe.protocol-version", clauses=["describe.protocol-version"])
async def protocol_version(ctx: CaseContext) -> None:
    """:protocol-version is 1."""
    entries = await _entries(ctx)
    ctx.check(f for f in check_description_entries(entries) if f.clause == "describe.protocol-version")


@case(
    "server.describe.keys",
    clauses=[
        "describe.brand-name",
        "describe.unique-name",
        "describe.degrees-of-freedom",
        "describe.operations",
        "describe.software-version",
    ],
)
async def keys(ctx: CaseContext) -> None:
    """:brand-name, :unique-name, :degrees-of-freedom, :operations, :software-version shaped as E.1 says."""
    entries = await _entries(ctx)
    ctx.check(f for f in check_description_entries(entries) if f.clause != "describe.protocol-version")


@case("server.describe.operations-served", clauses=["describe.operations"], deadline=10.0)
async def operations_served(ctx: CaseContext) -> None:
    """Every read-only opcode answered normally is listed under :operations."""
    probe = await ctx.connect()
    entries = await _entries(ctx, probe)
    listed = set(description_operations(entries))
    for op in SPEC.requests.values():
        if op.hazard != "read-only" or op.request.fields:
            continue
        answer = await probe.call(op.name)
        if answer.is_response:
            ctx.expect(
                op.opcode in listed,
                clause="describe.operations",
                expected=f"{op.name} ({op.opcode:o}) listed under :operations: it is answered",
                actual=f":operations {sorted(oct(o) for o in listed)}",
            )
