"""The opening of a connection (E introduction): the initial RESPONSE, one server per robot."""

from __future__ import annotations

from manip.conformance.judge.checks import check_initial_response
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.links import ConnectionRefused
from manip.spec.notation import octal


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
    ctx.expect(
        False,
        clause="connect.one-server-per-robot",
        expected="the second RFC refused with CLS while a client is connected",
        actual=f"a second connection opened (peer index {octal(second.conn.peer[1])})",
    )
    ctx.note(f"first connection {octal(first.conn.peer[1])} still open")
