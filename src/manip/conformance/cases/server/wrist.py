"""A Cougar that does not answer (Part II §6.3; erratum wrist-timeout): the main process gives up and
answers a non-fatal error, and goes on serving.

The target's world silences the Cougar (condition ``silent-wrist``: the embedded server's world always,
another target's with ``--world``); without a world the case is not judged, nor on a target that serves
no wrist (the wrist opcodes are Puma extensions)."""

from __future__ import annotations

from typing import Final

from manip.conformance.cases._support import error_of, no_wrist
from manip.conformance.judge.checks import WirePacket, word
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.conformance.suite.world import SilentWrist
from manip.spec.constants import ServerOp

GIVE_UP_S: Final = 5.0
"""How long the case waits for the answers: the erratum's wrist timeout is 0.5 s, and the 1985 guide's
'reasonable amount of time' is taken to be well within ten times that."""
_ANSWERS: Final = frozenset({ServerOp.RESPONSE, ServerOp.FATAL_ERROR, ServerOp.NON_FATAL_ERROR})


@case(
    "server.wrist.no-answer",
    clauses=["wrist.no-answer"],
    hazard="read-only",
    deadline=15.0,
    extensions=["wrist-version", "read-forces"],
)
async def no_answer(ctx: CaseContext) -> None:
    """Read forces while Cougar is silent is answered with a non-fatal error within a few seconds, and
    the Joint angles request sent right after it is answered after it."""
    probe = await ctx.connect()
    version = await probe.call("wrist-version")
    served = version.is_response
    await probe.close()
    if not served:
        ctx.not_judged(no_wrist(version))
    async with ctx.arranged(SilentWrist()):
        probe = await ctx.connect()
        await _judge_silence(ctx, probe)


async def _judge_silence(ctx: CaseContext, probe: Probe) -> None:
    """Read forces, then joint angles, while Cougar is silent: a non-fatal E error, then the answer."""
    forces = await probe.send("read-forces")
    angles = await probe.send("joint-angles")
    answers: list[WirePacket] = []
    deadline = ctx.clock() + GIVE_UP_S
    while len(answers) < 2 and (left := deadline - ctx.clock()) > 0:
        packet = await probe.next_packet(left)
        if packet is None:
            break
        if packet.opcode in _ANSWERS:
            answers.append(packet)
    numbers = [word(p.data, 0) for p in answers]
    seen = ", ".join(f"0{p.opcode:o} for #{n}" for p, n in zip(answers, numbers, strict=True)) or "nothing"
    ctx.expect(
        bool(answers) and answers[0].opcode == ServerOp.NON_FATAL_ERROR and numbers[0] == forces,
        clause="wrist.no-answer",
        expected=f"read forces (#{forces}) answered with a non-fatal error (202) within {GIVE_UP_S:g} s "
        "while Cougar is silent",
        actual=seen,
    )
    error = error_of(answers[0])
    ctx.expect(
        error is not None and error.error.severity in ("E", "BE"),
        clause="wrist.no-answer",
        expected="a non-fatal error of severity E (the connection goes on)",
        seen=answers[0],
    )
    ctx.expect(
        len(answers) == 2 and numbers[1] == angles and answers[1].opcode == ServerOp.RESPONSE,
        clause="wrist.no-answer",
        expected=f"joint angles (#{angles}), sent after it, answered after it",
        actual=seen,
    )
