"""Table 1: every command with its data length is taken and keeps the word link in sync (one case per
command)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

from manip.arm import READY
from manip.conformance.cases.cougar._support import (
    GUARDS,
    NEVER,
    any_address,
    clean,
    expect_names,
    expect_reply,
    int16,
    peek_region,
    peek_words,
)
from manip.conformance.cougar.probe import (
    CougarProbe,
    WordReply,
    cougar_probe,
    floats_of,
)
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC, CougarMessage
from manip.spec.notation import octal_words

# ------------------------------------------------------------------------------------------ Table 1
_RESPONSE_CLAUSE: Final = {
    "NTD": "cougar.npr.reply",
    "EXMN-DATA": "cougar.exmn.reply",
    "VERSION": "cougar.vers.reply",
    "FORCES": "cougar.rfrc.reply",
    "RAW": "cougar.rraw.reply",
}


async def _current(ctx: CaseContext, probe: CougarProbe, name: str, words: int) -> tuple[int, ...]:
    """The words of object ``name`` where the run's memory map puts it; zeros without a map, or when the
    map does not name it (the values a Cougar starts with, as manip's does)."""
    memory_map = ctx.options.cougar_map
    obj = memory_map.get(name) if memory_map is not None else None
    return await peek_region(ctx, probe, obj) if obj is not None else (0,) * words


async def _valid_values(ctx: CaseContext, probe: CougarProbe, msg: CougarMessage) -> dict[str, Any]:
    """Values that are valid for any Cougar and leave it as it was where a Puma would not reset them
    (with a memory map; without one NFV, NEWWC and WGOV send zeros, and DPST writes the word at address
    0 back unchanged)."""
    values: dict[str, Any] = {}
    for f in msg.data:
        zero: Any = 0.0 if f.element == "float" else 0
        values[f.name] = zero if f.count == 1 else (zero,) * (f.count or 0)
    match msg.name:
        case "SEN" | "FINIT":
            values["theta_sensed"] = READY
        case "NPR":
            values.update(theta_sensed=READY, theta_commanded=READY)
        case "DPST":  # a word written back as it was
            address = any_address(ctx)
            (value,) = await peek_words(ctx, probe, address, 1, "DPST's")
            values.update(address=address, value=value)
        case "EXMN":
            values.update(address=any_address(ctx), count=1)
        case "VERS":
            values["version"] = 1
        case "GUARDS":
            values.update(type_index=GUARDS - 1, tol=NEVER)
        case "GUARDC":
            values["index"] = GUARDS - 1
        case "NFV":
            values["offset"] = floats_of(await _current(ctx, probe, "fv", 6))
        case "NEWWC":
            weight, *cg = floats_of(await _current(ctx, probe, "object", 8))
            values.update(weight=weight, cg=tuple(cg))
        case "WGOV":
            values["offsets"] = tuple(int16(await _current(ctx, probe, "gauge_offsets", 8)))
    return values


async def _table1_exchange(
    ctx: CaseContext, probe: CougarProbe, msg: CougarMessage, immediate: str | None
) -> tuple[tuple[int, ...], list[WordReply]]:
    """Send ``msg`` with valid values, then NOP and VERS; the words sent and every response."""
    await clean(probe)
    values = await _valid_values(ctx, probe, msg)
    sent = await probe.send(msg.name, **values)
    await probe.send("NOP")
    await probe.send("VERS", version=1)
    replies: list[WordReply] = []
    for _ in range(4):
        replies += await probe.run(1)
        if any(r.name == "VERSION" for r in replies) and len(replies) >= (2 if immediate else 1):
            break
    if msg.name == "GUARDS":
        await probe.send("GUARDC", index=GUARDS - 1)
    replies += await probe.run(2)
    return sent, replies


def _expect_sync(
    ctx: CaseContext,
    msg: CougarMessage,
    sent: Sequence[int],
    replies: Sequence[WordReply],
    expected: list[str],
) -> None:
    answered = f"{msg.name} ({octal_words(sent)}), NOP, VERS answered by {', '.join(expected)}"
    why = "the command taken with its Table 1 data length, sync kept"
    expect_names(ctx, replies, expected, clause="cougar.word-link", expected=f"{answered}: {why}")


@case.each(SPEC.cougar_commands.values())
def _table1_case(msg: CougarMessage) -> None:
    immediate = msg.response if msg.response and "|" not in msg.response else None
    clauses = ["cougar.word-link", "cougar.comint.partial-waits"]

    # Two bodies, so that a command without an immediate response has no code judging one.
    async def table1(ctx: CaseContext) -> None:
        async with cougar_probe(ctx) as probe:
            sent, replies = await _table1_exchange(ctx, probe, msg, None)
            _expect_sync(ctx, msg, sent, replies, ["VERSION"])

    async def table1_answered(ctx: CaseContext) -> None:
        assert immediate is not None
        async with cougar_probe(ctx) as probe:
            sent, replies = await _table1_exchange(ctx, probe, msg, immediate)
            if replies:
                expect_reply(ctx, replies[0], immediate, _RESPONSE_CLAUSE[immediate], after=msg.name)
            _expect_sync(ctx, msg, sent, replies, [immediate, "VERSION"])

    if immediate is not None:
        clauses += [_RESPONSE_CLAUSE[immediate], "cougar.response.layout"]
        table1 = table1_answered
    case(
        f"cougar.table1.{msg.name.lower()}",
        clauses=clauses,
        summary=f"{msg.name} (code {msg.code}) with its {msg.data_words} data word(s) is accepted"
        + (f" and answered with {immediate}" if immediate else "")
        + "; a NOP and VERS after it still work (sync kept).",
        hazard="config",
    )(table1)
