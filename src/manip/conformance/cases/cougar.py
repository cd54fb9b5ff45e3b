"""Cougar target cases (``manip-conform run --cougar URL``): Table 1 and Appendix B over the DRV-11J.

Each case opens its own link (:func:`~manip.conformance.cougar_probe.cougar_probe`) and plays the Puma,
tick by tick.  A Cougar keeps its state across links (as the real one did across Puma sessions), so a
case never assumes a fresh one: it disarms every guard first (:func:`_clean`), sets the parameters it
relies on, lets the gauge filter settle when it reads forces, and puts back what it changed that a Puma
would not set again (gauge offsets, frame vector, version word).

What a case may rely on, so that it holds for any conforming Cougar and not just manip's simulator:

* Table 1 (codes, data lengths) and the seed's GUTS order: ADC8, conversion, GRAVITY, guards, COMINT,
  one GUTS per Puma tick; a response may come up to :data:`DEFAULT_WITHIN` ticks after its command.
* The errata: out-of-sync is response 2 carrying the bad word (``cougar-out-of-sync``); bit 15 of a
  guard's first word chooses its type (``guard-type-bit``); the memory map of ``cougar-memory-map``
  (its addresses are taken from :mod:`manip.cougar.memory`, the erratum's parameter, never retyped);
  ADC8's rounding (``cougar-filter-rounding``); the conversion and force sign (``cougar-units``); the
  compliance equation (``cougar-compliance-equation``), used only through properties that any linear
  spring/damper law has (zero gain gives zero, doubling a gain doubles its effect).
* Never the simulator's numbers: no expected force, gauge or Δθ value is hard-coded; each check compares
  Cougar with itself (before/after, split/unsplit) or with a formula of the spec applied to what Cougar
  reports.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any, Final

import numpy as np

from manip.arm import READY
from manip.codecs.cougar import encode
from manip.conformance.case import case
from manip.conformance.context import CaseContext
from manip.conformance.cougar_probe import (
    CougarProbe,
    WordReply,
    cougar_probe,
    floats_of,
    octal,
    words_bytes,
)
from manip.cougar.memory import MEMORY_BYTES, region
from manip.spec import SPEC, CougarMessage

GUARDS: Final = 16
STOP_BIT: Final = 0x8000
SETTLE_TICKS: Final = 40
"""Ticks for the gauge filter (pole 0.75 per tick) to settle after the arm moves: 0.75**40 < 1e-5."""
NEVER: Final = 1.0e30
"""A guard tolerance no dot product reaches (a guard that must not trip)."""
ALWAYS: Final = -1.0
"""With a zero dvec the dot product is 0 > -1: a guard that trips at the first check."""
POSE_B: Final = tuple(a + d for a, d in zip(READY, (15.0, 10.0, -10.0, 20.0, 30.0, 25.0), strict=True))

_GUARD_DVEC_ZERO: Final = (0.0,) * 6


# ------------------------------------------------------------------------------------------ helpers
async def _clean(probe: CougarProbe) -> None:
    """Disarm all 16 guards and drop whatever the previous user left in flight."""
    words: list[int] = []
    for index in range(GUARDS):
        words += (_code("GUARDC"), index)
    await probe.send_words(words)
    await probe.run(2)


def _code(name: str) -> int:
    return _command(name).code


def _command(name: str) -> CougarMessage:
    for msg in SPEC.cougar_commands.values():
        if msg.name == name:
            return msg
    raise KeyError(name)


def _response_code(name: str) -> int:
    for msg in SPEC.cougar_responses.values():
        if msg.name == name:
            return msg.code
    raise KeyError(name)


def _expect_reply(
    ctx: CaseContext, reply: WordReply, name: str, clause: str, *, after: str = ""
) -> WordReply:
    """``reply`` is a well-formed ``name`` response (code and data length of Table 1)."""
    code = _response_code(name)
    where = f" to {after}" if after else ""
    ctx.expect(
        not reply.problem,
        clause="cougar.response.layout",
        expected=f"a Table 1 response{where} ({name}, code {code})",
        actual=str(reply),
        data=words_bytes(reply.words),
    )
    ctx.expect(
        reply.name == name,
        clause=clause,
        expected=f"{name} (code {code}){where}",
        actual=str(reply),
        data=words_bytes(reply.words),
    )
    return reply


def _expect_none(ctx: CaseContext, replies: Sequence[WordReply], clause: str, why: str) -> None:
    ctx.expect(
        not replies,
        clause=clause,
        expected=f"no response ({why})",
        actual="; ".join(str(r) for r in replies),
        data=words_bytes([w for r in replies for w in r.words]),
    )


async def _quiet(ctx: CaseContext, probe: CougarProbe, clause: str, why: str, ticks: int = 2) -> None:
    """Nothing more comes in the next ``ticks`` ticks (no extra words after a response)."""
    _expect_none(ctx, await probe.run(ticks), clause, why)


async def _examine(ctx: CaseContext, probe: CougarProbe, address: int, count: int) -> tuple[int, ...]:
    """EXMN that must return ``count`` words (an address inside memory)."""
    reply = _expect_reply(
        ctx, await probe.examine(address, count), "EXMN-DATA", "cougar.exmn.reply", after="EXMN"
    )
    words = tuple(int(w) for w in reply.data_words[1:])
    ctx.expect(
        reply.data_words[:1] == (count,) and len(words) == count,
        clause="cougar.exmn.reply",
        expected=f"EXMN of {count} word(s) at {address:o}: count word {count}, then {count} words",
        actual=str(reply),
        data=words_bytes(reply.words),
    )
    return words


async def _examine_region(ctx: CaseContext, probe: CougarProbe, name: str) -> tuple[int, ...]:
    r = region(name)
    return await _examine(ctx, probe, r.address, r.words)


async def _region_floats(ctx: CaseContext, probe: CougarProbe, name: str) -> tuple[float, ...]:
    return floats_of(await _examine_region(ctx, probe, name))


async def _peek_region(ctx: CaseContext, probe: CougarProbe, name: str) -> tuple[int, ...]:
    """A region's words for a case that only needs them (to send them back unchanged): judges nothing,
    and skips the case when EXMN does not return them (``cougar.reply.exmn`` judges EXMN)."""
    r = region(name)
    reply = await probe.examine(r.address, r.words)
    if reply.problem or reply.name != "EXMN-DATA" or reply.data_words[:1] != (r.words,):
        ctx.skip(f"the case needs Cougar's {name} words, which EXMN did not return: {reply}")
    return tuple(int(w) for w in reply.data_words[1:])


def _int16(words: Iterable[int]) -> list[int]:
    return [w - 0x10000 if w & 0x8000 else w for w in words]


async def _settle(probe: CougarProbe, pose: Sequence[float] = READY) -> None:
    """Tell Cougar where the arm is and let the gauge filter settle there."""
    await probe.send("SEN", theta_sensed=tuple(pose))
    await probe.run(SETTLE_TICKS)


async def _forces(ctx: CaseContext, probe: CougarProbe) -> tuple[float, ...]:
    reply = _expect_reply(ctx, await probe.call("RFRC"), "FORCES", "cougar.rfrc.reply", after="RFRC")
    values = reply.floats()
    ctx.expect(
        len(values) == 6 and all(math.isfinite(v) for v in values),
        clause="cougar.rfrc.reply",
        expected="six finite floats",
        actual=str(values),
        data=words_bytes(reply.words),
    )
    return values


def _guard(index_word: int, dvec: Sequence[float] = _GUARD_DVEC_ZERO, tol: float = ALWAYS) -> list[int]:
    return encode("command", "GUARDS", type_index=index_word, dvec=tuple(dvec), tol=tol)


def _trips(replies: Iterable[WordReply]) -> list[tuple[str, int]]:
    """(response name, guard index) of every guard response."""
    out: list[tuple[str, int]] = []
    for r in replies:
        if r.name in ("GUARD-STOP", "GUARD-CONTINUE"):
            out.append((r.name, int(r.data_words[0]) if r.data_words else -1))
    return out


def _others(replies: Iterable[WordReply]) -> list[WordReply]:
    return [r for r in replies if r.name not in ("GUARD-STOP", "GUARD-CONTINUE")]


def _close(a: Sequence[float], b: Sequence[float], *, rel: float, floor: float) -> bool:
    """Element-wise closeness with a tolerance relative to the larger vector's size."""
    scale = max([abs(x) for x in (*a, *b)], default=0.0)
    tol = rel * scale + floor
    return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def _fmt(values: Iterable[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"


# ------------------------------------------------------------------------------------------ the link
@case(
    "cougar.link.drv11j-framing",
    clauses=["link.drv11j.framing", "cougar.word-link"],
    kind="cougar",
)
async def link_framing(ctx: CaseContext) -> None:
    """Cougar says HELLO (magic, version 1, role Cougar), answers every TICK with TICKED of the same
    number after the words that tick produced, and takes the next link once one ends."""
    for link in range(2):
        async with cougar_probe(ctx) as probe:
            for n in range(3):
                await probe.send("VERS", version=n)
                got = await probe.run(1)  # the probe checks each TICKED's number
                ctx.expect(
                    [r.name for r in got] == ["VERSION"],
                    clause="link.drv11j.framing",
                    expected=f"link {link + 1}, tick {probe.ticks - 1}: VERSION before its TICKED",
                    actual="; ".join(str(r) for r in got) or "nothing before TICKED",
                    data=words_bytes([w for r in got for w in r.words]),
                )


# ------------------------------------------------------------------------------------------ Table 1
_RESPONSE_CLAUSE: Final = {
    "NTD": "cougar.npr.reply",
    "EXMN-DATA": "cougar.exmn.reply",
    "VERSION": "cougar.vers.reply",
    "FORCES": "cougar.rfrc.reply",
    "RAW": "cougar.rraw.reply",
}


async def _valid_values(ctx: CaseContext, probe: CougarProbe, msg: CougarMessage) -> dict[str, Any]:
    """Values that are valid for any Cougar and leave it as it was where a Puma would not reset them."""
    values: dict[str, Any] = {}
    for f in msg.data:
        zero: Any = 0.0 if f.element == "float" else 0
        values[f.name] = zero if f.count == 1 else (zero,) * (f.count or 0)
    match msg.name:
        case "SEN" | "FINIT":
            values["theta_sensed"] = READY
        case "NPR":
            values.update(theta_sensed=READY, theta_commanded=READY)
        case "DPST":  # an odd address is no word: it changes nothing (erratum cougar-memory-map)
            values.update(address=region("version").address + 1, value=0)
        case "EXMN":
            values.update(address=region("version").address, count=1)
        case "VERS":
            values["version"] = 1
        case "GUARDS":
            values.update(type_index=GUARDS - 1, tol=NEVER)
        case "GUARDC":
            values["index"] = GUARDS - 1
        case "NFV":
            values["offset"] = floats_of(await _peek_region(ctx, probe, "fv"))
        case "NEWWC":
            weight, *cg = floats_of(await _peek_region(ctx, probe, "object"))
            values.update(weight=weight, cg=tuple(cg))
        case "WGOV":
            values["offsets"] = tuple(_int16(await _peek_region(ctx, probe, "gauge_offsets")))
    return values


async def _table1_exchange(
    ctx: CaseContext, probe: CougarProbe, msg: CougarMessage, immediate: str | None
) -> tuple[tuple[int, ...], list[WordReply]]:
    """Send ``msg`` with valid values, then NOP and VERS; the words sent and every response."""
    await _clean(probe)
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
    ctx.expect(
        [r.name for r in replies] == expected,
        clause="cougar.word-link",
        expected=f"{msg.name} ({octal(sent)}), NOP, VERS answered by {', '.join(expected)}: "
        "the command taken with its Table 1 data length, sync kept",
        actual="; ".join(str(r) for r in replies) or "nothing",
        data=words_bytes([w for r in replies for w in r.words]),
    )


def _make_table1_case(msg: CougarMessage) -> None:
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
                _expect_reply(ctx, replies[0], immediate, _RESPONSE_CLAUSE[immediate], after=msg.name)
            _expect_sync(ctx, msg, sent, replies, [immediate, "VERSION"])

    if immediate is not None:
        clauses += [_RESPONSE_CLAUSE[immediate], "cougar.response.layout"]
        table1 = table1_answered
    table1.__doc__ = (
        f"{msg.name} (code {msg.code}) with its {msg.data_words} data word(s) is accepted"
        + (f" and answered with {immediate}" if immediate else "")
        + "; a NOP and VERS after it still work (sync kept)."
    )
    case(
        f"cougar.table1.{msg.name.lower()}",
        clauses=clauses,
        kind="cougar",
        hazard="config",
    )(table1)


for _msg in SPEC.cougar_commands.values():
    _make_table1_case(_msg)


# ------------------------------------------------------------------------------------------ responses
@case(
    "cougar.reply.ntd",
    clauses=["cougar.npr.reply", "cougar.response.layout"],
    kind="cougar",
    hazard="config",
)
async def reply_ntd(ctx: CaseContext) -> None:
    """NPR is answered with NTD (code 1) carrying six finite floats, nothing more."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        target = tuple(a + 1.0 for a in READY)
        for rate in ((0.0,) * 6, (1.0, -1.0, 0.5, 0.0, 2.0, -2.0)):
            reply = await probe.call("NPR", theta_sensed=READY, theta_commanded=target, rate_difference=rate)
            _expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
            ctx.expect(
                len(reply.floats()) == 6 and all(math.isfinite(v) for v in reply.floats()),
                clause="cougar.npr.reply",
                expected="six finite floats of joint-rate change",
                actual=_fmt(reply.floats()),
                data=words_bytes(reply.words),
            )
            await _quiet(ctx, probe, "cougar.response.layout", "NPR has one response")


@case(
    "cougar.reply.version",
    clauses=["cougar.vers.reply", "cougar.response.layout"],
    kind="cougar",
)
async def reply_version(ctx: CaseContext) -> None:
    """VERS is answered with VERSION (code 8) and exactly one word, whatever the Puma's version word."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for puma_version in (0, 1, 0o105, 0xFFFF):
            reply = await probe.call("VERS", version=puma_version)
            _expect_reply(ctx, reply, "VERSION", "cougar.vers.reply", after=f"VERS {puma_version:o}")
            await _quiet(ctx, probe, "cougar.response.layout", "VERSION is one data word")


@case(
    "cougar.reply.forces",
    clauses=["cougar.rfrc.reply", "cougar.response.layout"],
    kind="cougar",
)
async def reply_forces(ctx: CaseContext) -> None:
    """RFRC is answered with FORCES (code 5) and six finite floats, on consecutive ticks."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for _ in range(3):
            await _forces(ctx, probe)
            await _quiet(ctx, probe, "cougar.response.layout", "FORCES is six floats", ticks=1)


@case(
    "cougar.reply.raw",
    clauses=["cougar.rraw.reply", "cougar.gauge-range", "cougar.response.layout"],
    kind="cougar",
)
async def reply_raw(ctx: CaseContext) -> None:
    """RRAW is answered with RAW (code 9) and eight words, each a 12-bit reading in -2048..2047."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for _ in range(3):
            reply = _expect_reply(ctx, await probe.call("RRAW"), "RAW", "cougar.rraw.reply", after="RRAW")
            gauges = _int16(reply.data_words)
            ctx.expect(
                len(gauges) == 8 and all(-2048 <= g <= 2047 for g in gauges),
                clause="cougar.gauge-range",
                expected="eight readings in -2048..2047",
                actual=str(gauges),
                data=words_bytes(reply.words),
            )
            await _quiet(ctx, probe, "cougar.response.layout", "RAW is eight words", ticks=1)


@case(
    "cougar.reply.exmn",
    clauses=["cougar.exmn.reply", "cougar.memory", "cougar.response.layout"],
    kind="cougar",
)
async def reply_exmn(ctx: CaseContext) -> None:
    """EXMN is answered with EXMN-DATA: the number of words asked for (0, 1, 2, 17, 200), then them."""
    base = region("version").address
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        first: tuple[int, ...] = ()
        for count in (0, 1, 2, 17, 200):
            words = await _examine(ctx, probe, base, count)
            await _quiet(ctx, probe, "cougar.response.layout", "EXMN-DATA carries its own count", ticks=1)
            if count == 1:
                first = words
            if count > 1 and first:
                ctx.expect(
                    words[:1] == first,
                    clause="cougar.memory",
                    expected=f"the word at {base:o} the same in every examine ({octal(first)})",
                    actual=octal(words[:1]),
                )


@case(
    "cougar.exmn.bad-address",
    clauses=["cougar.exmn.reply", "cougar.memory", "cougar.response.layout", "cougar.word-link"],
    kind="cougar",
)
async def exmn_bad_address(ctx: CaseContext) -> None:
    """EXMN at an odd address or past memory returns 0 words; one running off the end returns the
    words that exist, and says how many (erratum cougar-memory-map)."""
    cases = (
        (region("version").address + 1, 3, 0, "an odd address"),
        (MEMORY_BYTES, 2, 0, "the first address past memory"),
        (MEMORY_BYTES - 4, 5, 2, "two words before the end of memory"),
    )
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for address, count, returned, what in cases:
            reply = _expect_reply(
                ctx, await probe.examine(address, count), "EXMN-DATA", "cougar.exmn.reply", after="EXMN"
            )
            ctx.expect(
                reply.data_words[:1] == (returned,) and len(reply.data_words) == 1 + returned,
                clause="cougar.exmn.reply",
                expected=f"EXMN of {count} at {address:o} ({what}): count word {returned}, {returned} words",
                actual=str(reply),
                data=words_bytes(reply.words),
            )
        ctx.expect(
            (await probe.call("VERS", version=1)).name == "VERSION",
            clause="cougar.word-link",
            expected="VERSION after the bad addresses (Cougar still in sync)",
            actual="another response",
        )


# ------------------------------------------------------------------------------------------ COMINT
@case(
    "cougar.comint.in-order",
    clauses=["cougar.comint.partial-waits", "cougar.word-link"],
    kind="cougar",
)
async def comint_in_order(ctx: CaseContext) -> None:
    """Several complete commands sent together are all executed, in the order sent."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.send("VERS", version=1)
        await probe.send("EXMN", address=region("version").address, count=1)
        await probe.send("RFRC")
        await probe.send("NOP")
        await probe.send("RRAW")
        await probe.send("VERS", version=2)
        expected = ["VERSION", "EXMN-DATA", "FORCES", "RAW", "VERSION"]
        replies: list[WordReply] = []
        for _ in range(4):
            replies += await probe.run(1)
            if len(replies) >= len(expected):
                break
        replies += await probe.run(1)
        ctx.expect(
            [r.name for r in replies] == expected,
            clause="cougar.comint.partial-waits",
            expected=" then ".join(expected),
            actual="; ".join(str(r) for r in replies) or "nothing",
            data=words_bytes([w for r in replies for w in r.words]),
        )


@case(
    "cougar.comint.partial-waits",
    clauses=[
        "cougar.comint.partial-waits",
        "cougar.word-link",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    kind="cougar",
    hazard="config",
)
async def comint_partial_waits(ctx: CaseContext) -> None:
    """A command split over several ticks waits for its last word and then gives the same result as
    the same command sent whole (EXMN split in three; NPR split in four, one part only the code)."""
    address = region("version").address
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        whole = _expect_reply(ctx, await probe.examine(address, 3), "EXMN-DATA", "cougar.exmn.reply")
        await _quiet(ctx, probe, "cougar.word-link", "nothing was sent")
        words = [_code("EXMN"), address, 3]
        for i, part in enumerate(([words[0]], [words[1]], [words[2]])):
            await probe.send_words(part)
            got = await probe.run(1)
            if i < 2:
                _expect_none(ctx, got, "cougar.comint.partial-waits", f"EXMN has {i + 1} of 3 words")
            else:
                got += await probe.run(1) if not got else []
                ctx.expect(
                    [r.words for r in got] == [whole.words],
                    clause="cougar.comint.partial-waits",
                    expected=f"the split EXMN answered as the whole one: {octal(whole.words)}",
                    actual="; ".join(str(r) for r in got) or "nothing",
                    data=words_bytes([w for r in got for w in r.words]),
                )
        npr = encode("command", "NPR", theta_sensed=READY, theta_commanded=READY, rate_difference=(0.0,) * 6)
        cuts = (1, 6, 30, len(npr))
        start = 0
        for n, cut in enumerate(cuts):
            await probe.send_words(npr[start:cut])
            start = cut
            got = await probe.run(1)
            if n < len(cuts) - 1:
                _expect_none(ctx, got, "cougar.comint.partial-waits", f"NPR has {cut} of {len(npr)} words")
            else:
                got += await probe.run(1) if not got else []
                ctx.expect(
                    [r.name for r in got] == ["NTD"],
                    clause="cougar.comint.partial-waits",
                    expected="one NTD once the last word of the split NPR arrived",
                    actual="; ".join(str(r) for r in got) or "nothing",
                    data=words_bytes([w for r in got for w in r.words]),
                )
        _expect_reply(ctx, await probe.call("VERS", version=1), "VERSION", "cougar.word-link")


def _unknown_codes() -> tuple[int, ...]:
    known = set(SPEC.cougar_commands)
    return (max(known) + 1, 0o100000 | _code("VERS"), 0xFFFF)


@case(
    "cougar.comint.unknown-code",
    clauses=["cougar.comint.unknown-code", "cougar.word-link", "cougar.response.layout"],
    kind="cougar",
)
async def comint_unknown_code(ctx: CaseContext) -> None:
    """An unknown code dumps the input buffer (a VERS after it is not answered) and sends OUT-OF-SYNC
    (code 2) carrying the bad word; the next valid command works."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for bad in _unknown_codes():
            await probe.send_words([bad, _code("VERS"), 1])
            got = await probe.run(2)
            ctx.expect(
                len(got) == 1 and got[0].name == "OUT-OF-SYNC",
                clause="cougar.comint.unknown-code",
                expected=f"one OUT-OF-SYNC (code 2) for the unknown code {bad:o}, "
                "and the VERS after it dumped with the buffer",
                actual="; ".join(str(r) for r in got) or "nothing",
                data=words_bytes([w for r in got for w in r.words]),
            )
            ctx.expect(
                got[0].data_words == (bad,),
                clause="cougar.comint.unknown-code",
                expected=f"OUT-OF-SYNC carrying the bad word {bad:o} (erratum cougar-out-of-sync)",
                actual=str(got[0]),
                data=words_bytes(got[0].words),
            )
            reply = await probe.call("VERS", version=1)
            _expect_reply(ctx, reply, "VERSION", "cougar.comint.unknown-code", after="the next VERS")
            await _quiet(ctx, probe, "cougar.comint.unknown-code", "the buffer was dumped")


# ------------------------------------------------------------------------------------------ guards
@case(
    "cougar.guard.trips-once",
    clauses=["cougar.guards", "cougar.guard-trips-once"],
    kind="cougar",
    hazard="config",
)
async def guard_trips_once(ctx: CaseContext) -> None:
    """A guard whose condition always holds trips exactly once: response 6 with its index when bit 15
    is set, 7 when clear (bits 4-14 ignored); a guard that cannot trip stays silent; re-armed, it trips
    once more."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.send_words(_guard(STOP_BIT | 0x0070 | 3))
        await probe.send_words(_guard(0x0FF0 | 12))
        await probe.send_words(_guard(7, tol=NEVER))
        got = await probe.run(8)
        trips = sorted(_trips(got))
        ctx.expect(
            trips == [("GUARD-CONTINUE", 12), ("GUARD-STOP", 3)],
            clause="cougar.guard-trips-once",
            expected="exactly one GUARD-STOP (6) for guard 3 and one GUARD-CONTINUE (7) for guard 12 "
            "in 8 ticks, none for guard 7 (tolerance never reached)",
            actual="; ".join(str(r) for r in got) or "nothing",
            data=words_bytes([w for r in got for w in r.words]),
        )
        _expect_none(ctx, _others(got), "cougar.guards", "only guard responses")
        await probe.send_words(_guard(STOP_BIT | 3))
        got = await probe.run(6)
        ctx.expect(
            _trips(got) == [("GUARD-STOP", 3)],
            clause="cougar.guard-trips-once",
            expected="guard 3, armed again, trips once more (one GUARD-STOP 3)",
            actual="; ".join(str(r) for r in got) or "nothing",
            data=words_bytes([w for r in got for w in r.words]),
        )
        await probe.send("GUARDC", index=7)
        await probe.run(1)


@case(
    "cougar.guard.clear",
    clauses=["cougar.guardc", "cougar.guards"],
    kind="cougar",
    hazard="config",
)
async def guard_clear(ctx: CaseContext) -> None:
    """GUARDC disarms a guard before it trips; the guard armed with it and not cleared still trips."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.send_words(_guard(5))
        await probe.send_words(_guard(9))
        await probe.send("GUARDC", index=5)
        got = await probe.run(8)
        ctx.expect(
            _trips(got) == [("GUARD-CONTINUE", 9)],
            clause="cougar.guardc",
            expected="guard 5 cleared in the same tick it was armed never trips; guard 9 trips once",
            actual="; ".join(str(r) for r in got) or "nothing",
            data=words_bytes([w for r in got for w in r.words]),
        )


@case(
    "cougar.guard.condition",
    clauses=["cougar.guards", "cougar.response.layout", "cougar.rfrc.reply"],
    kind="cougar",
    hazard="config",
)
async def guard_condition(ctx: CaseContext) -> None:
    """A guard trips when the dot product of the force with its dvec exceeds tol, not otherwise (both
    signs of dvec, tolerances just below and above the force Cougar reports)."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await _settle(probe)
        force = await _forces(ctx, probe)
        axis = max(range(3), key=lambda i: abs(force[i]))
        f = force[axis]
        margin = max(2.0, 0.05 * abs(f))
        unit = tuple(1.0 if i == axis else 0.0 for i in range(6))
        minus = tuple(-x for x in unit)
        guards = {  # index: (dvec, tol, trips)
            1: (unit, f - margin, True),
            2: (unit, f + margin, False),
            3: (minus, -f - margin, True),
            4: (minus, -f + margin, False),
        }
        for index, (dvec, tol, _) in guards.items():
            await probe.send_words(_guard(index, dvec, tol))
        got = await probe.run(6)
        expected = [("GUARD-CONTINUE", i) for i, (_, _, trips) in guards.items() if trips]
        ctx.expect(
            sorted(_trips(got)) == sorted(expected),
            clause="cougar.guards",
            expected=f"with force[{axis}] = {f:.4g}: guards 1 and 3 trip (dot > tol), 2 and 4 do not",
            actual="; ".join(str(r) for r in got) or "nothing",
            data=words_bytes([w for r in got for w in r.words]),
        )
        await _clean(probe)


# ------------------------------------------------------------------------------------------ memory
@case(
    "cougar.memory.deposit-examine",
    clauses=["cougar.memory", "cougar.exmn.reply", "cougar.vers.reply", "cougar.response.layout"],
    kind="cougar",
    hazard="config",
)
async def memory_deposit_examine(ctx: CaseContext) -> None:
    """DPST then EXMN reads the word back, and the deposit changes what Cougar does: a new version
    word is what VERS reports (the old one is put back)."""
    address = region("version").address
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        (old,) = await _examine(ctx, probe, address, 1)
        new = old ^ 0o52525
        try:
            await probe.send("DPST", address=address, value=new)
            (seen,) = await _examine(ctx, probe, address, 1)
            ctx.expect(
                seen == new,
                clause="cougar.memory",
                expected=f"EXMN after DPST {new:o} at {address:o} reads {new:o}",
                actual=f"{seen:o}",
            )
            reply = _expect_reply(ctx, await probe.call("VERS", version=1), "VERSION", "cougar.vers.reply")
            ctx.expect(
                reply.data_words == (new,),
                clause="cougar.memory",
                expected=f"VERS reports the deposited version word {new:o}",
                actual=str(reply),
                data=words_bytes(reply.words),
            )
        finally:
            await probe.send("DPST", address=address, value=old)
            await probe.run(1)


@case(
    "cougar.memory.parameters",
    clauses=["cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    kind="cougar",
    hazard="config",
)
async def memory_parameters(ctx: CaseContext) -> None:
    """The data of NK, NB, NBJI and NFC are in memory where the map puts them, exactly as sent."""
    values: dict[str, tuple[str, dict[str, tuple[float, ...]]]] = {
        "NK": ("k", {"k": (1.5, -2.25, 3.0, 0.125, 1024.0, -0.5)}),
        "NB": ("b", {"b": tuple(float(i) / 8.0 - 2.0 for i in range(36))}),
        "NBJI": ("bji", {"bji": (0.01, 0.02, 0.03, 0.5, 0.25, 0.125)}),
        "NFC": ("fc", {"force": (-3.0, 0.0, 7.5, 1.0, -1.0, 2.0)}),
    }
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        for name, (where, data) in values.items():
            words = encode("command", name, **data)
            await probe.send_words(words)
            await probe.run(1)
            stored = await _examine_region(ctx, probe, where)
            ctx.expect(
                stored == tuple(words[1:]),
                clause="cougar.memory",
                expected=f"{name}'s data words at {region(where).address:o} ({where}): {octal(words[1:])}",
                actual=octal(stored),
                data=words_bytes(stored),
            )
        zero = {"NK": "k", "NB": "b", "NBJI": "bji", "NFC": "force"}
        for name, field in zero.items():
            count = _command(name).data[0].count or 0
            await probe.send(name, **{field: (0.0,) * count})
        await probe.run(1)


# ------------------------------------------------------------------------------------------ ADC8, forces
@case(
    "cougar.adc8.integer-filter",
    clauses=[
        "cougar.adc8-filter",
        "cougar.memory",
        "cougar.comint.partial-waits",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    kind="cougar",
    hazard="config",
)
async def adc8_integer_filter(ctx: CaseContext) -> None:
    """Each tick's filtered gauge reading is (u_k + u_k-1 + 6 Y_k-1) >> 3 exactly, also while it
    recovers from a deposited disturbance of 100 counts (erratum cougar-filter-rounding)."""
    raw, filtered = region("gauge_raw"), region("gauge_filtered")

    async def sample() -> tuple[list[int], list[int]]:
        """u_k and Y_k of one tick: both EXMNs run in the same COMINT, after that tick's ADC8."""
        await probe.send("EXMN", address=raw.address, count=raw.words)
        await probe.send("EXMN", address=filtered.address, count=filtered.words)
        got = [await probe.reply("EXMN of gauge_raw"), await probe.reply("EXMN of gauge_filtered")]
        for reply, r in zip(got, (raw, filtered), strict=True):
            _expect_reply(ctx, reply, "EXMN-DATA", "cougar.exmn.reply", after="EXMN")
            ctx.expect(
                reply.data_words[:1] == (r.words,),
                clause="cougar.exmn.reply",
                expected=f"{r.words} words of {r.name}",
                actual=str(reply),
                data=words_bytes(reply.words),
            )
        ctx.expect(
            got[0].tick == got[1].tick,
            clause="cougar.comint.partial-waits",
            expected="two EXMNs sent together answered in the same tick",
            actual=f"ticks {got[0].tick} and {got[1].tick}",
        )
        return _int16(got[0].data_words[1:]), _int16(got[1].data_words[1:])

    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await _settle(probe)
        _, y0 = await sample()
        for i, reading in enumerate(y0):
            await probe.send("DPST", address=filtered.at(i), value=(reading - 100) & 0xFFFF)
        u_prev, y_prev = await sample()
        ctx.expect(
            y_prev == [y - 100 for y in y0],
            clause="cougar.memory",
            expected=f"the deposited filter state {[y - 100 for y in y0]}",
            actual=str(y_prev),
        )
        for k in range(12):
            u, y = await sample()  # the next tick
            want = [(u[i] + u_prev[i] + 6 * y_prev[i]) >> 3 for i in range(8)]
            ctx.expect(
                y == want,
                clause="cougar.adc8-filter",
                expected=f"tick {k + 1} after the disturbance: Y = (u + u_prev + 6 Y_prev) >> 3 = {want} "
                f"(u = {u}, u_prev = {u_prev}, Y_prev = {y_prev})",
                actual=f"Y = {y}",
            )
            u_prev, y_prev = u, y


def _expected_voltmat(calmat: Sequence[float], fv_mm: Sequence[float]) -> np.ndarray[Any, Any]:
    """The clause's conversion: -(10/2048) * calmat, torque rows taken about the compliance centre
    (tau - r x f, r in inches: erratum cougar-units)."""
    cal = np.array(calmat, dtype=np.float64).reshape(6, 8)
    r = np.array(fv_mm, dtype=np.float64) / 25.4
    torque = cal[3:] - np.cross(r, cal[:3].T).T
    out: np.ndarray[Any, Any] = -(10.0 / 2048.0) * np.vstack([cal[:3], torque])
    return out


@case(
    "cougar.forces.conversion",
    clauses=[
        "cougar.nfv-conversion",
        "cougar.rfrc.reply",
        "cougar.memory",
        "cougar.comint.partial-waits",
        "cougar.exmn.reply",
        "cougar.response.layout",
        "cougar.rraw.reply",
    ],
    kind="cougar",
    hazard="config",
    deadline=8.0,
)
async def forces_conversion(ctx: CaseContext) -> None:
    """The conversion matrix is -(10/2048) x calibration with the compliance-centre transform; NFV
    changes only its torque rows; and raising one gauge offset by d changes the force Cougar reports
    by -voltmat[:, g] * d (the -1: forces are what the robot applies)."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        fv0 = await _region_floats(ctx, probe, "fv")
        offsets0 = tuple(_int16(await _examine_region(ctx, probe, "gauge_offsets")))
        try:
            calmat = await _region_floats(ctx, probe, "calmat")
            for fv in ((0.0, 0.0, 0.0), (30.0, -20.0, 100.0)):
                await probe.send("NFV", offset=fv)
                await probe.run(2)
                vm = np.array(await _region_floats(ctx, probe, "voltmat")).reshape(6, 8)
                want = _expected_voltmat(calmat, fv)
                scale = float(np.abs(want).max()) or 1.0
                ctx.expect(
                    bool(np.allclose(vm, want, rtol=1e-5, atol=1e-6 * scale)),
                    clause="cougar.nfv-conversion",
                    expected=f"voltmat = -(10/2048) calmat with the torque rows about fv = {fv} mm: "
                    f"{_fmt(want.reshape(-1)[:8])}...",
                    actual=f"{_fmt(vm.reshape(-1)[:8])}... (largest difference "
                    f"{float(np.abs(vm - want).max()):.3g})",
                )
                if fv == (0.0, 0.0, 0.0):
                    force_rows = vm[:3].copy()
                else:
                    ctx.expect(
                        bool(np.array_equal(vm[:3], force_rows)),
                        clause="cougar.nfv-conversion",
                        expected="NFV leaves the force rows of voltmat unchanged",
                        actual=f"largest change {float(np.abs(vm[:3] - force_rows).max()):.3g}",
                    )
            await _settle(probe)
            gauge = int(np.argmax(np.abs(vm).sum(axis=0)))
            delta = 100
            before = await _raw_and_forces(ctx, probe)
            shifted = list(offsets0)
            shifted[gauge] += delta
            await probe.send("WGOV", offsets=tuple(shifted))
            await probe.run(2)
            after = await _raw_and_forces(ctx, probe)
            offsets_delta = np.zeros(8)
            offsets_delta[gauge] = delta
            want_change = vm @ (np.array(after[0]) - np.array(before[0]) - offsets_delta)
            change = np.array(after[1]) - np.array(before[1])
            ctx.expect(
                _close(list(change), list(want_change), rel=0.02, floor=0.05),
                clause="cougar.nfv-conversion",
                expected=f"gauge {gauge} offset +{delta} changes the force by voltmat (dY - d_offset) = "
                f"{_fmt(want_change)}",
                actual=f"{_fmt(change)}",
            )
        finally:
            await probe.send("WGOV", offsets=offsets0)
            await probe.send("NFV", offset=fv0)
            await probe.run(1)


async def _raw_and_forces(ctx: CaseContext, probe: CougarProbe) -> tuple[list[int], tuple[float, ...]]:
    """RRAW and RFRC answered in the same tick: the filtered readings and the force made from them."""
    await probe.send("RRAW")
    await probe.send("RFRC")
    raw = _expect_reply(ctx, await probe.reply("RRAW"), "RAW", "cougar.rraw.reply", after="RRAW")
    forces = _expect_reply(ctx, await probe.reply("RFRC"), "FORCES", "cougar.rfrc.reply", after="RFRC")
    ctx.expect(
        raw.tick == forces.tick,
        clause="cougar.comint.partial-waits",
        expected="RRAW and RFRC sent together answered in the same tick",
        actual=f"ticks {raw.tick} and {forces.tick}",
    )
    return _int16(raw.data_words), forces.floats()


# ------------------------------------------------------------------------------------------ NPR, RST
_THETA_ERROR: Final = (1.0, -1.0, 1.0, 2.0, -2.0, 2.0)
GAIN: Final = 5.0
"""K (oz/mm) and B (oz s/mm) steps: with the position error and rate difference used, their force
terms are ~100 oz, so gauge noise of a fraction of an ounce stays far inside the 2 % tolerance."""


async def _ntd(
    ctx: CaseContext,
    probe: CougarProbe,
    *,
    k: float,
    b: float,
    bji: float,
    rate: float,
) -> tuple[float, ...]:
    """NTD for diagonal gains (K = k, B = b I, BJI = bji) at READY with a fixed position error,
    after RST (so the output filter starts from rest whatever its constants)."""
    await probe.send("NK", k=(k,) * 6)
    await probe.send("NB", b=tuple(b if i % 7 == 0 else 0.0 for i in range(36)))
    await probe.send("NBJI", bji=(bji,) * 6)
    await probe.send("NFC", force=(0.0,) * 6)
    await probe.send("RST")
    _expect_none(ctx, await probe.run(3), "cougar.word-link", "parameter commands have no response")
    commanded = tuple(a + e for a, e in zip(READY, _THETA_ERROR, strict=True))
    reply = await probe.call(
        "NPR", theta_sensed=READY, theta_commanded=commanded, rate_difference=(rate,) * 6
    )
    _expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
    values = reply.floats()
    ctx.expect(
        len(values) == 6 and all(math.isfinite(v) for v in values),
        clause="cougar.npr.reply",
        expected="six finite floats",
        actual=_fmt(values),
        data=words_bytes(reply.words),
    )
    return values


@case(
    "cougar.npr.gains",
    clauses=["cougar.npr.reply", "cougar.response.layout", "cougar.word-link"],
    kind="cougar",
    hazard="config",
    deadline=8.0,
)
async def npr_gains(ctx: CaseContext) -> None:
    """NTD answers the gains NK, NB and NBJI set: zero joint damping inverse gives zero; the part due
    to K (position error) and to B (rate difference) is non-zero and doubles when the gain doubles;
    doubling BJI doubles the whole answer (erratum cougar-compliance-equation)."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await _settle(probe)
        try:
            zero = await _ntd(ctx, probe, k=5.0, b=1.0, bji=0.0, rate=3.0)
            ctx.expect(
                all(abs(v) <= 1e-6 for v in zero),
                clause="cougar.npr.reply",
                expected="NTD all zero with BJI = 0",
                actual=_fmt(zero),
            )
            bji = 0.01
            base = await _ntd(ctx, probe, k=0.0, b=0.0, bji=bji, rate=0.0)
            for gain, kw in (("K", "k"), ("B", "b")):
                rate = 3.0 if kw == "b" else 0.0
                one = await _ntd(ctx, probe, **{"k": 0.0, "b": 0.0, kw: GAIN}, bji=bji, rate=rate)
                two = await _ntd(ctx, probe, **{"k": 0.0, "b": 0.0, kw: 2 * GAIN}, bji=bji, rate=rate)
                rest = base if kw == "k" else await _ntd(ctx, probe, k=0.0, b=0.0, bji=bji, rate=rate)
                d1 = [x - y for x, y in zip(one, rest, strict=True)]
                d2 = [x - y for x, y in zip(two, rest, strict=True)]
                ctx.expect(
                    max(abs(v) for v in d1) > 1e-4,
                    clause="cougar.npr.reply",
                    expected=f"NTD to change when {gain} goes from 0 to {GAIN:g} (with a "
                    f"{'position error' if kw == 'k' else 'rate difference'})",
                    actual=f"{_fmt(rest)} -> {_fmt(one)}",
                )
                ctx.expect(
                    _close(d2, [2 * v for v in d1], rel=0.02, floor=1e-6),
                    clause="cougar.npr.reply",
                    expected=f"doubling {gain} doubles its part of NTD: {_fmt(2 * v for v in d1)}",
                    actual=_fmt(d2),
                )
            one = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=bji, rate=0.0)
            two = await _ntd(ctx, probe, k=GAIN, b=0.0, bji=2 * bji, rate=0.0)
            ctx.expect(
                _close(two, [2 * v for v in one], rel=0.02, floor=1e-6),
                clause="cougar.npr.reply",
                expected=f"doubling BJI doubles NTD: {_fmt(2 * v for v in one)}",
                actual=_fmt(two),
            )
        finally:
            await probe.send("NBJI", bji=(0.0,) * 6)
            await probe.send("RST")
            await probe.run(1)


@case(
    "cougar.rst.zeroes-velocities",
    clauses=[
        "cougar.rst",
        "cougar.memory",
        "cougar.exmn.reply",
        "cougar.npr.reply",
        "cougar.response.layout",
    ],
    kind="cougar",
    hazard="config",
)
async def rst_zeroes_velocities(ctx: CaseContext) -> None:
    """After NPR with a rate difference, RST sets the rate difference, the filter state and the last
    NTD in memory to zero."""
    names = ("rate_difference", "dtheta_previous", "dtheta_filtered", "dtheta_out")
    rate = (1.0, 2.0, 3.0, -1.0, -2.0, -3.0)
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.send("NK", k=(1.0,) * 6)
        await probe.send("NBJI", bji=(0.01,) * 6)
        await probe.run(2)
        commanded = tuple(a + e for a, e in zip(READY, _THETA_ERROR, strict=True))
        reply = await probe.call("NPR", theta_sensed=READY, theta_commanded=commanded, rate_difference=rate)
        _expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
        stored = await _region_floats(ctx, probe, "rate_difference")
        ctx.expect(
            _close(stored, rate, rel=1e-6, floor=0.0),
            clause="cougar.memory",
            expected=f"NPR's rate difference in memory before RST: {_fmt(rate)}",
            actual=_fmt(stored),
        )
        await probe.send("RST")
        await probe.run(1)
        for name in names:
            words = await _examine_region(ctx, probe, name)
            values = floats_of(words)
            ctx.expect(
                all(v == 0.0 for v in values),
                clause="cougar.rst",
                expected=f"{name} zero after RST",
                actual=_fmt(values),
                data=words_bytes(words),
            )
        await probe.send("NBJI", bji=(0.0,) * 6)
        await probe.run(1)


# ------------------------------------------------------------------------------------------ JACOB, GUTS
@case(
    "cougar.jacob.front-buffer-complete",
    clauses=["cougar.jacob-double-buffer", "cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    kind="cougar",
    hazard="config",
)
async def jacob_front_buffer(ctx: CaseContext) -> None:
    """After the arm moves, every tick's front Jacobian buffer is the old Jacobian or the new one,
    never a mixture; the new one arrives within a few ticks."""
    front, buffers = region("jacob_front"), (region("jbuf0"), region("jbuf1"))
    j_words = 2 * 36

    async def front_j() -> tuple[int, ...]:
        (which,) = await _examine(ctx, probe, front.address, 1)
        both = [await _examine(ctx, probe, b.address, j_words) for b in buffers]
        return both[which & 1]

    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.send("SEN", theta_sensed=READY)
        await probe.run(5)
        old = await front_j()
        await probe.send("SEN", theta_sensed=POSE_B)
        seen = []
        for _ in range(12):
            seen.append(await front_j())
            await probe.run(1)
        new = seen[-1]
        ctx.expect(
            new != old and seen[-3:] == [new] * 3,
            clause="cougar.jacob-double-buffer",
            expected="a new, steady Jacobian in the front buffer within 9 ticks of SEN to a new pose",
            actual="unchanged" if new == old else "still changing after 9 ticks",
        )
        mixed = [i for i, j in enumerate(seen) if j not in (old, new)]
        ctx.expect(
            not mixed,
            clause="cougar.jacob-double-buffer",
            expected="the front buffer always the old or the new Jacobian",
            actual=f"another one at tick(s) {mixed} after the move",
            data=words_bytes(seen[mixed[0]]) if mixed else b"",
        )
        await probe.send("SEN", theta_sensed=READY)
        await probe.run(1)


REENTRY_GAP_S: Final = 1e-6
"""A tick this soon after the previous one (the TICK frame's resolution) finds any GUTS still running."""


@case("cougar.guts.no-nesting", clauses=["cougar.guts-reentry"], kind="cougar")
async def guts_no_nesting(ctx: CaseContext) -> None:
    """A tick one microsecond after the previous one finds GUTS still running, however fast Cougar is:
    it sends no words, and a command sent before it runs at the next tick."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.run(1)
        await probe.send("VERS", version=1)
        nested = await probe.run(1, gap=REENTRY_GAP_S)
        ctx.expect(
            not nested,
            clause="cougar.guts-reentry",
            expected=f"no words from a tick {REENTRY_GAP_S * 1e6:g} us after the previous one",
            actual="; ".join(str(r) for r in nested),
        )
        late = await probe.run(1)
        ctx.expect(
            [r.name for r in late] == ["VERSION"],
            clause="cougar.guts-reentry",
            expected="the VERS waiting in the buffer answered at the next full tick",
            actual="; ".join(str(r) for r in late) or "nothing",
        )


@case(
    "cougar.guts.reentry",
    clauses=["cougar.guts-cost-model"],
    kind="cougar",
)
async def guts_reentry(ctx: CaseContext) -> None:
    """A tick 0.5 ms after the previous one finds GUTS still running (erratum cougar-guts-reentry's
    cost model): it returns at once, and a command sent before it runs at the next tick instead.

    It checks clause cougar.guts-cost-model (SHOULD), not the MUST of cougar.guts-reentry (that is
    cougar.guts.no-nesting's): it relies on the erratum's GUTS time, and a Cougar whose GUTS finishes in
    under 0.5 ms breaks no MUST by running the command early."""
    async with cougar_probe(ctx) as probe:
        await _clean(probe)
        await probe.run(1)
        await probe.send("VERS", version=1)
        early = await probe.run(1, gap=0.0005)
        ctx.expect(
            not early,
            clause="cougar.guts-cost-model",
            expected="no words from a tick that re-entered GUTS",
            actual="; ".join(str(r) for r in early),
        )
        late = await probe.run(1) if not early else []
        ctx.expect(
            [r.name for r in late] == ["VERSION"] or bool(early),
            clause="cougar.guts-cost-model",
            expected="the VERS waiting in the buffer answered at the next full tick",
            actual="; ".join(str(r) for r in late) or "nothing",
        )
