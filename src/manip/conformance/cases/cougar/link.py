"""The DRV-11J link and COMINT, Cougar's command interpreter: framing, order, partial commands,
unknown codes."""

from __future__ import annotations

from manip.arm import READY
from manip.codecs.cougar import encode
from manip.conformance.cases.cougar._support import (
    any_address,
    clean,
    expect_names,
    expect_none,
    expect_quiet,
    expect_reply,
)
from manip.conformance.cougar.probe import (
    WordReply,
    cougar_probe,
    words_bytes,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC
from manip.spec.constants import CougarCommand
from manip.spec.notation import octal, octal_words


# ------------------------------------------------------------------------------------------ the link
@case(
    "cougar.link.drv11j-framing",
    clauses=["link.drv11j.framing", "cougar.word-link"],
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
                    seen=showing(
                        words_bytes([w for r in got for w in r.words]),
                        "; ".join(str(r) for r in got) or "nothing before TICKED",
                    ),
                )


# ------------------------------------------------------------------------------------------ COMINT
@case(
    "cougar.comint.in-order",
    clauses=["cougar.comint.partial-waits", "cougar.word-link"],
)
async def comint_in_order(ctx: CaseContext) -> None:
    """Several complete commands sent together are all executed, in the order sent."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        await probe.send("VERS", version=1)
        await probe.send("EXMN", address=any_address(ctx), count=1)
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
        expect_names(
            ctx, replies, expected, clause="cougar.comint.partial-waits", expected=" then ".join(expected)
        )


@case(
    "cougar.comint.partial-waits",
    clauses=[
        "cougar.comint.partial-waits",
        "cougar.word-link",
        "cougar.exmn.reply",
        "cougar.response.layout",
    ],
    hazard="config",
)
async def comint_partial_waits(ctx: CaseContext) -> None:
    """A command split over several ticks waits for its last word and then gives the same result as
    the same command sent whole (EXMN split in three; NPR split in four, one part only the code)."""
    address = any_address(ctx)
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        whole = expect_reply(ctx, await probe.examine(address, 3), "EXMN-DATA", "cougar.exmn.reply")
        await expect_quiet(ctx, probe, "cougar.word-link", "nothing was sent")
        words = [CougarCommand.EXMN, address, 3]
        for i, part in enumerate(([words[0]], [words[1]], [words[2]])):
            await probe.send_words(part)
            got = await probe.run(1)
            if i < 2:
                expect_none(ctx, got, "cougar.comint.partial-waits", f"EXMN has {i + 1} of 3 words")
            else:
                got += await probe.run(1) if not got else []
                ctx.expect(
                    [r.words for r in got] == [whole.words],
                    clause="cougar.comint.partial-waits",
                    expected=f"the split EXMN answered as the whole one: {octal_words(whole.words)}",
                    seen=got,
                )
        npr = encode("command", "NPR", theta_sensed=READY, theta_commanded=READY, rate_difference=(0.0,) * 6)
        cuts = (1, 6, 30, len(npr))
        start = 0
        for n, cut in enumerate(cuts):
            await probe.send_words(npr[start:cut])
            start = cut
            got = await probe.run(1)
            if n < len(cuts) - 1:
                expect_none(ctx, got, "cougar.comint.partial-waits", f"NPR has {cut} of {len(npr)} words")
            else:
                got += await probe.run(1) if not got else []
                expect_names(
                    ctx,
                    got,
                    ["NTD"],
                    clause="cougar.comint.partial-waits",
                    expected="one NTD once the last word of the split NPR arrived",
                )
        expect_reply(ctx, await probe.call("VERS", version=1), "VERSION", "cougar.word-link")


def _unknown_codes() -> tuple[int, ...]:
    known = set(SPEC.cougar_commands)
    return (max(known) + 1, 0o100000 | CougarCommand.VERS, 0xFFFF)


@case(
    "cougar.comint.unknown-code",
    clauses=["cougar.comint.unknown-code", "cougar.word-link", "cougar.response.layout"],
)
async def comint_unknown_code(ctx: CaseContext) -> None:
    """An unknown code dumps the input buffer (a VERS after it is not answered) and sends OUT-OF-SYNC:
    code 2, alone or with the bad word (B.7 gives no layout; erratum cougar-out-of-sync); the next valid
    command works."""
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for bad in _unknown_codes():
            await probe.send_words([bad, CougarCommand.VERS, 1])
            got = await probe.run(2)
            ctx.expect(
                [r.name for r in got][:1] == ["OUT-OF-SYNC"],
                clause="cougar.comint.unknown-code",
                expected=f"an OUT-OF-SYNC (code 2, alone or with the word {octal(bad)}) for the unknown code "
                f"{octal(bad)}",
                seen=got,
            )
            ctx.expect(
                all(r.name == "OUT-OF-SYNC" for r in got),
                clause="cougar.comint.unknown-code",
                expected="the VERS after the unknown code dumped with the buffer (no VERSION)",
                seen=got,
            )
            ctx.expect(
                len(got) <= 1,
                clause="cougar.comint.unknown-code",
                expected="one out-of-sync message for one unknown code",
                seen=got,
            )
            ctx.expect(
                not got or got[0].data_words in ((), (bad,)),
                clause="cougar.comint.unknown-code",
                expected=f"OUT-OF-SYNC as code 2 alone or code 2 then the bad word {octal(bad)}",
                seen=got[0] if got else got,
            )
            reply = await probe.call("VERS", version=1)
            expect_reply(ctx, reply, "VERSION", "cougar.comint.unknown-code", after="the next VERS")
            await expect_quiet(ctx, probe, "cougar.comint.unknown-code", "the buffer was dumped")
