"""Error strings: ~ and $ numbers with and without the alignment pad, every severity, non-fatal errors
as replies, asynchronous errors and warnings between a request and its reply, fatal errors."""

from __future__ import annotations

from typing import Final

from manip.codecs.error_string import ErrorMessage
from manip.conformance.cases.client._support import close, connect, expect_error_parts, request
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide, plain_answer
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec.constants import ServerOp
from manip.spec.notation import octal_words


def _message(ctx: ClientContext, *, even: bool) -> ErrorMessage:
    """A JOR-like message with a ~ and a $, its text length even (the numbers need a pad) or odd."""
    joints = ctx.random.randint(1, 63)
    tries = ctx.random.randint(0, 0xFFFF)
    text = "Joints $ out of range after ~ tries"
    where = "PUMA"
    full = f"{where}: E JOR {text}"
    if (len(full) % 2 == 0) != even:
        text += "."
    return ErrorMessage(where, "E", "JOR", text, (joints, tries))


async def _one_error(
    ctx: ClientContext, error: ErrorMessage, *, align: bool = True, opcode: int = ServerOp.NON_FATAL_ERROR
) -> Play:
    async def script(side: ServerSide) -> None:
        req = await side.next_request()
        if req is not None:
            await side.error(opcode, req.packet_no, error, align=align)
            await side.serve_plainly()

    return await ctx.play([connect(0), request(1, "here"), request(2, "joint-angles"), close(3)], script)


ARG_LAYOUTS: Final = (
    ("padded", True, True, "the NUL ends at an odd offset: one zero pad byte, then the numbers"),
    ("aligned", False, True, "the NUL ends at an even offset: the numbers right after it"),
)


@case.each(ARG_LAYOUTS)
def _arg_case(row: tuple[str, bool, bool, str]) -> None:
    name, even, align, how = row

    async def args_case(base: CaseContext) -> None:
        ctx = client_context(base)
        error = _message(ctx, even=even)
        play = await _one_error(ctx, error, align=align)
        expect_error_parts(
            ctx,
            play.answer(1),
            error,
            "non-fatal-error",
            clause="error-string.substitution",
            play=play,
            ops=(1,),
        )
        later = play.answer(2)
        normally = "the next request answered normally: a non-fatal error fails its own request only"
        ctx.expect_result(later, clause="client.error-report", expected=normally)

    case(
        f"client.error.args-{name}",
        clauses=["error-string.substitution", "client.error-report"],
        summary=f"A non-fatal error with ~ and $ numbers ({how}) is reported with its parts and rendered",
    )(args_case)


@case("client.error.args-unpadded", clauses=["client.error-args-layout"])
async def args_unpadded(base: CaseContext) -> None:
    """A non-fatal error whose numbers follow an odd NUL without the pad byte is still read."""
    ctx = client_context(base)
    error = _message(ctx, even=True)
    play = await _one_error(ctx, error, align=False)
    expect_error_parts(
        ctx, play.answer(1), error, "non-fatal-error", clause="client.error-args-layout", play=play, ops=(1,)
    )


@case("client.error.severities", clauses=["client.error-report"])
async def severities(base: CaseContext) -> None:
    """Non-fatal errors of severity E, C and BE (no NUL, so ~ and $ are plain) are each reported as the
    reply to their own request."""
    ctx = client_context(base)
    errors = [
        ErrorMessage("PUMA", "E", "NAP", "No arm power"),
        ErrorMessage("PUMA", "C", "BVA", "Value ~ not in $ range"),
        ErrorMessage("PUMA", "BE", "BUG", "Inconsistent queue"),
    ]

    async def script(side: ServerSide) -> None:
        for error in errors:
            req = await side.next_request()
            if req is None:
                return
            await side.error(ServerOp.NON_FATAL_ERROR, req.packet_no, error)
        await side.serve_plainly()

    ops = [connect(0), *(request(i + 1, "here") for i in range(3)), close(4)]
    play = await ctx.play(ops, script)
    for i, error in enumerate(errors):
        expect_error_parts(
            ctx,
            play.answer(i + 1),
            error,
            "non-fatal-error",
            clause="client.error-report",
            play=play,
            ops=(i + 1,),
        )


ASYNC_ERRORS: Final = (
    (
        "async-error",
        ServerOp.ASYNCHRONOUS_ERROR,
        ErrorMessage("PUMA", "E", "COL", "Collision on $", (4,)),
        "asynchronous-error",
    ),
    (
        "warning",
        ServerOp.ASYNCHRONOUS_WARNING,
        ErrorMessage("PUMA", "W", "AWA", "Guard ~ stopped ~ segments", (3, 2)),
        "asynchronous-warning",
    ),
)


@case.each(ASYNC_ERRORS)
def _async_error_case(row: tuple[str, int, ErrorMessage, str]) -> None:
    name, opcode, error, origin = row

    async def between(base: CaseContext) -> None:
        ctx = client_context(base)
        values = [float(ctx.random.randint(-180, 180)) for _ in range(6)]

        async def script(side: ServerSide) -> None:
            req = await side.next_request()
            if req is None:
                return
            await side.error(opcode, req.packet_no, error)
            await side.reply(req, joints=values)
            await side.serve_plainly()

        play = await ctx.play([connect(0), request(1, "joint-angles"), close(2)], script)
        found = [r for r in play.of("error", any_op=True) if r.get("origin") == origin]
        ctx.expect(
            bool(found),
            clause="client.async-routing",
            expected=f"an error result of origin {origin}",
            seen=play.describe(),
        )
        expect_error_parts(ctx, found[0], error, origin, clause="client.error-report", play=play, ops=(None,))
        ctx.expect(
            found[0].op is None,
            clause="client.async-routing",
            expected="an asynchronous error tied to no op",
            seen=str(found[0]),
        )
        answer = play.answer(1)
        after = f"the reply that came after it, joints {values}"
        ctx.expect_result(answer, values={"joints": values}, clause="client.async-routing", expected=after)

    case(
        f"client.error.{name}-between",
        clauses=["client.async-routing", "client.error-report"],
        summary=f"An {origin} between a request and its reply is reported apart; the reply still answers",
    )(between)


FATALS: Final = (("f", "F"), ("bf", "BF"))


@case.each(FATALS)
def _fatal_case(row: tuple[str, str]) -> None:
    name, severity = row

    async def fatal(base: CaseContext) -> None:
        ctx = client_context(base)
        error = ErrorMessage(
            "PUMA", severity, "NZI", "No zero index on joint $", (ctx.random.randint(1, 63),)
        )
        after: list[int] = []

        async def script(side: ServerSide) -> None:
            req = await side.next_request()
            if req is None:
                return
            await side.error(ServerOp.FATAL_ERROR, req.packet_no, error)
            more = await side.next_request(0.5)  # a conformant client sends nothing more
            if more is not None:
                after.append(more.opcode)
                await plain_answer(side, more)
            side.close_now("fatal error")

        ops = [connect(0), request(1, "calibrate"), request(2, "here"), close(3)]
        play = await ctx.play(ops, script)
        fatal_results = [r for r in play.of("error", any_op=True) if r.get("origin") == "fatal-error"]
        ctx.expect(
            bool(fatal_results),
            clause="client.fatal-ends",
            expected="an error result of origin fatal-error",
            seen=play.describe(),
        )
        expect_error_parts(
            ctx,
            fatal_results[0],
            error,
            "fatal-error",
            clause="client.error-report",
            play=play,
            ops=(1, None),
        )
        ctx.expect(
            not after,
            clause="client.fatal-ends",
            expected="no request after the fatal error",
            seen=f"request opcode(s) {octal_words(after)} sent after it",
        )
        ctx.expect(
            "lost" in play.states(),
            clause="client.fatal-ends",
            expected="the connection reported lost after the fatal error",
            seen=f"states {play.states()}",
        )
        later = play.answer(2)
        refused = "the request after the fatal error refused as not-connected"
        ctx.expect_result(later, "not-connected", clause="client.fatal-ends", expected=refused)

    case(
        f"client.fatal.severity-{name}",
        clauses=["client.fatal-ends", "client.error-report"],
        hazard="motion",
        summary=f"A fatal error ({severity}) ends the connection: reported, and no request follows it",
    )(fatal)
