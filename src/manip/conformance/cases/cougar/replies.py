"""The responses of Table 1: NTD, VERSION, FORCES, RAW, EXMN-DATA and EXMN's refusal of a bad address."""

from __future__ import annotations

from manip.arm import READY
from manip.conformance.cases.cougar._support import (
    answer_words,
    any_address,
    clean,
    expect_examine,
    expect_names,
    expect_quiet,
    expect_reply,
    fmt,
    int16,
    read_forces,
)
from manip.conformance.cougar.probe import (
    cougar_probe,
    words_bytes,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec.constants import CougarResponse
from manip.spec.notation import octal, octal_words


# ------------------------------------------------------------------------------------------ responses
@case(
    "cougar.reply.ntd",
    clauses=["cougar.npr.reply", "cougar.response.layout"],
    hazard="config",
)
async def reply_ntd(ctx: CaseContext) -> None:
    """NPR is answered with NTD (code 1) carrying six finite floats, nothing more."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        target = tuple(a + 1.0 for a in READY)
        for rate in ((0.0,) * 6, (1.0, -1.0, 0.5, 0.0, 2.0, -2.0)):
            reply = await probe.call("NPR", theta_sensed=READY, theta_commanded=target, rate_difference=rate)
            expect_reply(ctx, reply, "NTD", "cougar.npr.reply", after="NPR")
            floats = reply.floats()
            ctx.expect_finite(
                floats,
                6,
                clause="cougar.npr.reply",
                expected="six finite floats of joint-rate change",
                seen=showing(reply, fmt(floats)),
            )
            await expect_quiet(ctx, probe, "cougar.response.layout", "NPR has one response")


@case(
    "cougar.reply.version",
    clauses=["cougar.vers.reply", "cougar.response.layout"],
)
async def reply_version(ctx: CaseContext) -> None:
    """VERS is answered with VERSION (code 8) and exactly one word, whatever the Puma's version word."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for puma_version in (0, 1, 0o105, 0xFFFF):
            reply = await probe.call("VERS", version=puma_version)
            expect_reply(ctx, reply, "VERSION", "cougar.vers.reply", after=f"VERS {octal(puma_version)}")
            await expect_quiet(ctx, probe, "cougar.response.layout", "VERSION is one data word")


@case(
    "cougar.reply.forces",
    clauses=["cougar.rfrc.reply", "cougar.response.layout"],
)
async def reply_forces(ctx: CaseContext) -> None:
    """RFRC is answered with FORCES (code 5) and six finite floats, on consecutive ticks."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for _ in range(3):
            await read_forces(ctx, probe)
            await expect_quiet(ctx, probe, "cougar.response.layout", "FORCES is six floats", ticks=1)


@case(
    "cougar.reply.raw",
    clauses=["cougar.rraw.reply", "cougar.gauge-range", "cougar.response.layout"],
)
async def reply_raw(ctx: CaseContext) -> None:
    """RRAW is answered with RAW (code 9) and eight words, each a 12-bit reading in -2048..2047: the
    words Cougar sends for it are those nine, whatever the probe makes of them."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for _ in range(3):
            replies, words = await answer_words(probe, "RRAW")
            seen = showing(words_bytes(words), octal_words(words) or "nothing")
            ctx.expect(
                words[:1] != (CougarResponse.RAW,) or len(words) == 9,
                clause="cougar.response.layout",
                expected=f"code {int(CougarResponse.RAW)} then the eight data words Table 1 gives it",
                seen=seen,
            )
            ctx.require(
                words[:1] == (CougarResponse.RAW,) and len(words) == 9,
                clause="cougar.rraw.reply",
                expected=f"code {int(CougarResponse.RAW)} and eight words, all Cougar sends for RRAW",
                seen=seen,
            )
            reply = expect_reply(ctx, replies[0], "RAW", "cougar.rraw.reply", after="RRAW")
            gauges = int16(reply.data_words)
            ctx.expect(
                len(gauges) == 8 and all(-2048 <= g <= 2047 for g in gauges),
                clause="cougar.gauge-range",
                expected="eight readings in -2048..2047",
                seen=showing(reply, str(gauges)),
            )
            await expect_quiet(ctx, probe, "cougar.response.layout", "RAW is eight words", ticks=1)


@case(
    "cougar.reply.exmn",
    clauses=["cougar.exmn.reply", "cougar.memory", "cougar.response.layout"],
)
async def reply_exmn(ctx: CaseContext) -> None:
    """EXMN is answered with EXMN-DATA: the number of words asked for (0, 1, 2, 17, 200), then them."""
    base = any_address(ctx)
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        first: tuple[int, ...] = ()
        for count in (0, 1, 2, 17, 200):
            words = await expect_examine(ctx, probe, base, count)
            await expect_quiet(
                ctx, probe, "cougar.response.layout", "EXMN-DATA carries its own count", ticks=1
            )
            if count == 1:
                first = words
            if count > 1 and first:
                ctx.expect(
                    words[:1] == first,
                    clause="cougar.memory",
                    expected=f"the word at {octal(base)} the same in every examine ({octal_words(first)})",
                    seen=octal_words(words[:1]),
                )


LAST_WORD = 0o177776
"""The last word a 16-bit address reaches (on a PDP-11, in the I/O page)."""


@case(
    "cougar.exmn.bad-address",
    clauses=["cougar.exmn.reply", "cougar.response.layout", "cougar.word-link"],
)
async def exmn_bad_address(ctx: CaseContext) -> None:
    """EXMN at an odd address, or running past the 16-bit address space, is answered with EXMN-DATA: a
    count word no larger than the count asked, then that many words (the 1985 guide does not say how
    many; manip's Cougar retrieves none: erratum cougar-memory-map), and Cougar stays in sync."""
    cases = (
        (any_address(ctx) + 1, 3, "an odd address"),
        (LAST_WORD, 2, "the last word of the address space and one past it"),
    )
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for address, count, what in cases:
            reply = expect_reply(
                ctx, await probe.examine(address, count), "EXMN-DATA", "cougar.exmn.reply", after="EXMN"
            )
            retrieved = reply.data_words[:1]
            ctx.expect(
                bool(retrieved) and retrieved[0] <= count,
                clause="cougar.exmn.reply",
                expected=f"EXMN of {count} at {octal(address)} ({what}): a count word of at most {count}",
                seen=reply,
            )
            ctx.expect(
                bool(retrieved) and len(reply.data_words) == 1 + retrieved[0],
                clause="cougar.exmn.reply",
                expected=f"EXMN of {count} at {octal(address)} ({what}): as many words as its count "
                "word says",
                seen=reply,
            )
        reply = await probe.call("VERS", version=1)
        expect_names(
            ctx,
            [reply],
            ["VERSION"],
            clause="cougar.word-link",
            expected="VERSION after the bad addresses (Cougar still in sync)",
        )
