"""Cougar memory through DPST and EXMN (erratum cougar-memory-map): deposit/examine, the parameters."""

from __future__ import annotations

from manip.codecs.cougar import encode
from manip.conformance.cases.cougar._support import (
    clean,
    examine_region,
    expect_examine,
    expect_reply,
    mapped,
)
from manip.conformance.cougar.probe import (
    cougar_probe,
    words_bytes,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC
from manip.spec.constants import CougarCommand
from manip.spec.notation import octal, octal_words


# ------------------------------------------------------------------------------------------ memory
@case(
    "cougar.memory.deposit-examine",
    clauses=["cougar.memory", "cougar.exmn.reply", "cougar.vers.reply", "cougar.response.layout"],
    hazard="config",
)
async def memory_deposit_examine(ctx: CaseContext) -> None:
    """DPST then EXMN reads the word back, and the deposit changes what Cougar does: a new version
    word is what VERS reports (the old one is put back)."""
    (version,) = mapped(ctx, "version")
    address = version.address
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        (old,) = await expect_examine(ctx, probe, address, 1)
        new = old ^ 0o52525
        try:
            await probe.send("DPST", address=address, value=new)
            (seen,) = await expect_examine(ctx, probe, address, 1)
            ctx.expect(
                seen == new,
                clause="cougar.memory",
                expected=f"EXMN after DPST {octal(new)} at {octal(address)} reads {octal(new)}",
                seen=octal(seen),
            )
            reply = expect_reply(ctx, await probe.call("VERS", version=1), "VERSION", "cougar.vers.reply")
            ctx.expect(
                reply.data_words == (new,),
                clause="cougar.memory",
                expected=f"VERS reports the deposited version word {octal(new)}",
                seen=reply,
            )
        finally:
            await probe.send("DPST", address=address, value=old)
            await probe.run(1)


@case(
    "cougar.memory.parameters",
    clauses=["cougar.memory", "cougar.exmn.reply", "cougar.response.layout"],
    hazard="config",
)
async def memory_parameters(ctx: CaseContext) -> None:
    """The data of NK, NB, NBJI and NFC are in memory where the map puts them, exactly as sent (each
    command its own check)."""
    values: dict[str, tuple[str, dict[str, tuple[float, ...]]]] = {
        "NK": ("k", {"k": (1.5, -2.25, 3.0, 0.125, 1024.0, -0.5)}),
        "NB": ("b", {"b": tuple(float(i) / 8.0 - 2.0 for i in range(36))}),
        "NBJI": ("bji", {"bji": (0.01, 0.02, 0.03, 0.5, 0.25, 0.125)}),
        "NFC": ("fc", {"force": (-3.0, 0.0, 7.5, 1.0, -1.0, 2.0)}),
    }
    objects = dict(zip(("k", "b", "bji", "fc"), mapped(ctx, "k", "b", "bji", "fc"), strict=True))
    async with cougar_probe(ctx) as probe:
        await clean(probe)
        for name, (where, data) in values.items():
            words = encode("command", name, **data)
            await probe.send_words(words)
            await probe.run(1)
            stored = await examine_region(ctx, probe, objects[where])
            ctx.expect(
                stored == tuple(words[1:]),
                clause="cougar.memory",
                expected=f"{name}'s data words at {octal(objects[where].address)} ({where}): "
                f"{octal_words(words[1:])}",
                seen=showing(words_bytes(stored), octal_words(stored)),
            )
        zero = {
            CougarCommand.NK: "k",
            CougarCommand.NB: "b",
            CougarCommand.NBJI: "bji",
            CougarCommand.NFC: "force",
        }
        for command, field in zero.items():
            count = SPEC.cougar_commands[command].data[0].count or 0
            await probe.send(command.name, **{field: (0.0,) * count})
        await probe.run(1)
