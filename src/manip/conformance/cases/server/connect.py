"""The opening of a connection (E introduction): the initial RESPONSE, one server per robot."""

from __future__ import annotations

from typing import Final

from manip.conformance.cases._support import error_of, power_on, read_floats, require_response, settle
from manip.conformance.judge.checks import check_initial_response
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.links import ConnectionRefused
from manip.spec.constants import ServerOp
from manip.spec.notation import octal

ABORT_SWING_DEG: Final = 20.0
"""How far joint 1 is sent before arm power is cut under it (long enough to be moving then)."""
MOVING_S: Final = 0.2
"""Seconds the case lets the servo run after it cut arm power under the move."""


@case(
    "server.connect.initial-response",
    clauses=["connect.initial-response", "connect.initial-response-number"],
)
async def initial_response(ctx: CaseContext) -> None:
    """The first packet after the open is a RESPONSE carrying the RFC's packet number."""
    probe = await ctx.connect(initial=False)
    first = await probe.next_packet(ctx.options.reply_timeout)
    ctx.check(check_initial_response(first, probe.rfc_packet_no))
    if first is not None:
        probe.initial = first
    # A second RESPONSE after the initial one would be taken as Here's answer: the transcript invariant
    # then finds its number wrong (response.echoes-request-number is not this case's clause).
    await probe.call("here")


@case("server.connect.one-server-per-robot", clauses=["connect.one-server-per-robot"])
async def one_server_per_robot(ctx: CaseContext) -> None:
    """A second connection while one is open is refused (CLS)."""
    first = await ctx.connect()
    try:
        second = await ctx.connect(initial=False, retry_busy=False)
    except Exception as exc:  # the probe turns link errors into a CaseFailure
        cause = exc.__cause__
        if isinstance(cause, ConnectionRefused):
            ctx.exercised("connect.one-server-per-robot")
            ctx.note(f"second connection refused: {cause.reason}")
            return
        raise
    # The server opened it: wait for its first packet, so the transcript judged holds what it sent.
    opened = await second.next_packet(ctx.options.reply_timeout)
    if opened is not None:
        second.push_back(opened)
    ctx.expect(
        False,
        clause="connect.one-server-per-robot",
        expected="the second RFC refused with CLS while a client is connected",
        seen=f"a second connection opened (peer index {octal(second.conn.peer[1])})",
    )
    ctx.note(f"first connection {octal(first.conn.peer[1])} still open")


@case(
    "server.connect.abort-not-carried",
    clauses=["connect.per-connection-state"],
    hazard="power",
    deadline=15.0,
)
async def abort_not_carried(ctx: CaseContext) -> None:
    """A connection that closes while an abort stands (arm power cut under a move: erratum
    abort-on-power-loss) leaves no abort to the next: the next connection's first move is done, or NAP
    when it starts without power, never AWA (Part II §5: the abort condition is the main process's, set up
    afresh per connection)."""
    first = await ctx.connect()
    await power_on(ctx, first)
    start = await read_floats(ctx, first, "joint-angles")
    await _abort_standing(ctx, first, start)
    await first.close()
    probe = await ctx.connect()
    answer = await probe.call("set-joint-angles", joints=list(start))
    error = error_of(answer)
    ctx.expect(
        answer.is_response or (error is not None and error.error.code != "AWA"),
        clause="connect.per-connection-state",
        expected="the new connection's first move done (or NAP, without power): no abort carried over",
        seen=answer,
    )
    await power_on(ctx, probe)
    await probe.call("set-joint-angles", joints=list(start))
    await settle(ctx, probe, start, within=5.0)


async def _abort_standing(ctx: CaseContext, probe: Probe, start: tuple[float, ...]) -> None:
    """Cut arm power under a move of joint 1, so an abort stands; not judged when the target then does
    not refuse motion with AWA (server.motion.abort judges that)."""
    goal = list(start)
    goal[0] += ABORT_SWING_DEG if start[0] <= 0 else -ABORT_SWING_DEG
    require_response(ctx, await probe.call("set-joint-angles", joints=goal), "a move of joint 1")
    require_response(ctx, await probe.call("kill-power"), "kill power")
    await probe.drain(MOVING_S)
    refused = await probe.call("set-joint-angles", joints=list(start))
    error = error_of(refused)
    if error is None or error.error.code != "AWA" or refused.opcode != ServerOp.NON_FATAL_ERROR:
        said = repr(error.error.render()) if error is not None else str(refused)
        ctx.not_judged(
            f"no abort stood after arm power was cut under a move (a move was answered {said}): a "
            "target that aborts on power loss (erratum abort-on-power-loss) would judge it"
        )
