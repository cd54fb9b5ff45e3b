"""Error strings (E.2) and the error packets that carry them (E.3 Opcodes 201, 202)."""

from __future__ import annotations

import asyncio
from typing import Final, NoReturn

from manip.conformance.cases._support import UNASSIGNED_OPCODES, error_of
from manip.conformance.judge.checks import check_error_packet
from manip.conformance.judge.violation import missing, showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.conformance.suite.world import CalibrationFailure
from manip.links import ChaosError, ConnectionClosed
from manip.spec import SPEC
from manip.spec.constants import ServerOp

EOF_POLL_S: Final = 0.01
"""How often the case looks whether the CLS has followed the server's EOF (seconds)."""


async def _command_error(ctx: CaseContext, probe: Probe, clause: str | None = None) -> Answer:
    """Provoke a non-fatal error: an opcode the spec does not define.  A target that does not refuse
    it breaks ``clause`` when the case declares the refusal; otherwise the case has no error string to
    judge and is not judged (``server.negative.unknown-opcodes`` fails the target)."""
    answer = await probe.call_raw(UNASSIGNED_OPCODES[-1 - ctx.random.randrange(8)])
    if clause is not None:
        ctx.expect_opcode(
            answer,
            ServerOp.NON_FATAL_ERROR,
            clause=clause,
            expected="a non-fatal error (0202) for an unknown opcode",
        )
    elif answer.opcode != ServerOp.NON_FATAL_ERROR:
        ctx.not_judged(
            f"no non-fatal error to judge: an unknown opcode was answered with {answer} "
            "(server.negative.unknown-opcodes judges that answer)"
        )
    return answer


@case(
    "server.error.string-format",
    clauses=[
        "error-string.format",
        "error-string.where-no-colon",
        "error-string.severity",
        "error-string.code",
        "error-string.args",
        "error-string.substitution",
    ],
)
async def string_format(ctx: CaseContext) -> None:
    """'where: severity code message', a known severity, a three-letter code, ~/$ matched by numbers."""
    probe = await ctx.connect()
    answer = await _command_error(ctx, probe)
    ctx.check(f for f in check_error_packet(answer.first) if f.clause != "error-string.arg-layout")
    error = error_of(answer)
    if error is not None:
        ctx.note(f"error string: {error.error.render()!r}")


@case("server.error.arg-alignment", clauses=["error-string.arg-layout"])
async def arg_alignment(ctx: CaseContext) -> None:
    """Numbers after the NUL follow it directly or after one zero pad byte to an even offset (erratum
    error-arg-layout: both conform).  Two errors are provoked, an unknown opcode and a bad length, so that
    both parities of the NUL's offset are seen with the reference server's messages."""
    probe = await ctx.connect()
    answers = [await _command_error(ctx, probe)]
    bad_length = await probe.call_raw(SPEC.request("here").opcode, b"\x01")
    if bad_length.is_error:
        answers.append(bad_length)
    numbered = 0
    for answer in answers:
        data = answer.data
        nul = data.find(0, 2)
        if nul < 0 or nul + 1 >= len(data):
            continue
        numbered += 1
        ctx.check(f for f in check_error_packet(answer.first) if f.clause == "error-string.arg-layout")
    if not numbered:
        ctx.not_judged(
            "no error string carried numbers: C UOP carries the opcode and C BDL the byte counts "
            "(server.negative.unknown-opcodes and server.negative.data-length judge them)"
        )


@case(
    "server.error.severity-matches-opcode",
    clauses=["error.severity-matches-opcode", "request.unknown-opcode"],
)
async def severity_matches(ctx: CaseContext) -> None:
    """A non-fatal error (202) carries E, C or BE; a command error C."""
    probe = await ctx.connect()
    answer = await _command_error(ctx, probe, "request.unknown-opcode")
    ctx.check(f for f in check_error_packet(answer.first) if f.clause == "error.severity-matches-opcode")
    decoded = error_of(answer)
    if decoded is None:
        return  # the format case says what is wrong with the string
    error = decoded.error
    ctx.expect(
        error.severity == "C",
        clause="request.unknown-opcode",
        expected="severity C for an unknown opcode",
        seen=showing(answer, repr(error.render())),
    )


@case("server.error.non-fatal-is-reply", clauses=["error.non-fatal-is-reply", "request.one-reply"])
async def non_fatal_is_reply(ctx: CaseContext) -> None:
    """Nothing else answers a request after its non-fatal error."""
    probe = await ctx.connect()
    await _command_error(ctx, probe)
    extra = [p for p in await probe.drain(0.2) if p.opcode in (ServerOp.RESPONSE, ServerOp.NON_FATAL_ERROR)]
    ctx.expect(
        not extra,
        clause="error.non-fatal-is-reply",
        expected="no other reply after the non-fatal error",
        seen=showing(extra[:1], f"{len(extra)} more packet(s)"),
    )
    after = await probe.call("here")
    ctx.expect_echo(after, clause="request.one-reply", expected="the next reply answers the next request")


@case(
    "server.error.fatal-then-close",
    clauses=[
        "error.fatal-then-close",
        "error.fatal-request-number",
        "error.severity-matches-opcode",
        "calibrate.nzi",
        "calibrate.nzi-mask",
        "calibrate.done",
    ],
    hazard="motion",
    deadline=8.0,
)
async def fatal_then_close(ctx: CaseContext) -> None:
    """Calibrate while the world fails it (no zero index on two joints the seed picks): a fatal error
    quoting the packet last received, of severity F, an NZI mask naming those joints, then CLS.

    The target's world arranges the calibration failure (the embedded server's always; another target's
    with ``--world``); without a world the case is not judged."""
    failure = CalibrationFailure(tuple(sorted(ctx.random.sample(range(1, 7), 2))))
    async with ctx.arranged(failure):
        probe = await ctx.connect()
        answer = await probe.call("enable-power")
        answer = await probe.call("calibrate", timeout=5.0)
        if answer.opcode != ServerOp.FATAL_ERROR:
            _not_fatal(ctx, answer, failure)
        await _judge_fatal(ctx, probe, answer, failure.joints)


def _not_fatal(ctx: CaseContext, answer: Answer, failure: CalibrationFailure) -> NoReturn:
    """Calibrate, under an arranged calibration failure, answered other than with a fatal error: done, or
    NZI as a non-fatal error, is a wrong answer (the 1985 guide's table: F NZI); a refusal for another
    reason leaves no calibration to judge, and server.reply.calibrate judges that answer."""
    expected = f"F NZI naming joints {list(failure.joints)}, as the world arranged {failure.describe()}"
    if answer.is_response:
        ctx.expect(len(answer.data) == 2, clause="calibrate.done", expected="an empty done", seen=answer)
        ctx.fail(
            "calibrate succeeded although it could not",
            clause="calibrate.nzi",
            expected=expected,
            seen=answer,
        )
    error = error_of(answer)
    if error is not None and error.error.code == "NZI":
        ctx.fail("NZI came as a non-fatal error", clause="calibrate.nzi", expected=expected, seen=answer)
    ctx.not_judged(
        f"calibrate was refused with a non-fatal error, not failed: {answer} (server.reply.calibrate "
        "judges that answer)"
    )


async def _judge_fatal(ctx: CaseContext, probe: Probe, answer: Answer, failed: tuple[int, ...]) -> None:
    """A fatal error: its request number, its severity, its NZI form, then CLS (a dropped link or a LOS
    is not the CLS the clause asks for)."""
    ctx.check(check_error_packet(answer.first))
    ctx.expect_echo(
        answer,
        clause="error.fatal-request-number",
        expected=f"request number {answer.request.packet_no}, the packet last received",
    )
    error = error_of(answer)
    ctx.expect(
        error is not None and error.error.severity in ("F", "BF"),
        clause="error.severity-matches-opcode",
        expected="severity F (or BF) in a fatal error",
        seen=answer,
    )
    if error is not None and error.error.code == "NZI":
        ctx.expect(
            error.error.has_nul and len(error.error.args) == 1 and "$" in error.error.message,
            clause="calibrate.nzi",
            expected="NZI with the joints as one $ mask argument",
            seen=showing(answer, repr(error.error.render())),
        )
        _judge_mask(ctx, answer, error.error.args, failed)
    closed = await probe.wait_closed(ctx.options.reply_timeout)
    ctx.expect(
        closed,
        clause="error.fatal-then-close",
        expected=f"CLS within {ctx.options.reply_timeout:g} s of the fatal error",
        seen=missing("the connection still open", after=answer),
    )
    end = probe.end_reason
    if isinstance(end, ConnectionClosed) and end.reason == "EOF":
        end = await _after_eof(ctx, probe)
    ctx.expect(
        isinstance(end, ConnectionClosed) and end.by_peer and end.reason != "EOF",
        clause="error.fatal-then-close",
        expected="the server to end the connection with CLS after the fatal error (EOF first or not)",
        seen=showing(answer, f"the connection ended otherwise: {end or 'EOF, and no CLS followed it'}"),
    )


def _judge_mask(ctx: CaseContext, answer: Answer, args: tuple[int, ...], failed: tuple[int, ...]) -> None:
    """The NZI mask names exactly the joints the world made fail (joint n is bit n-1: E.2's example)."""
    wanted = sum(1 << (joint - 1) for joint in failed)
    named = [j for j in range(1, 17) if args and args[0] >> (j - 1) & 1]
    ctx.expect(
        bool(args) and args[0] == wanted,
        clause="calibrate.nzi-mask",
        expected=f"mask {wanted} (joints {', '.join(map(str, failed))}, whose zero index the world hid)",
        seen=showing(answer, f"mask {args[0] if args else None} (joints {named})"),
    )


async def _after_eof(ctx: CaseContext, probe: Probe) -> ChaosError | None:
    """How the connection ended after the server's EOF: the CLS that should follow (the EOF read is
    acknowledged, which lets the server close), a LOS, a broken link, or None when nothing came within
    the reply timeout.  An EOF alone is a half-close, not the CLS the clause asks for."""
    conn = probe.conn
    deadline = ctx.clock() + ctx.options.reply_timeout
    while not conn.ended and ctx.clock() < deadline:
        await asyncio.sleep(EOF_POLL_S)
    return conn.end_reason
