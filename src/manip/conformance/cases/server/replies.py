"""Every request opcode of the spec: a well-formed request gets one reply of the shape the spec gives
it (done, data, segment number, multi-packet text), echoing the request's packet number.

The cases are generated from the spec table, one per opcode (``server.reply.<name>``); their hazard is
the opcode's, so on hardware the motion and power ones are left out unless ``--allow-motion``.  A target
that refuses the request (a Puma extension it does not implement, say) is not judged on the shape: the
case ends not-judged with the error it gave (the error string itself is still checked).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from typing import Final

from manip.conformance.cases._support import NOT_SERVED, error_of, extension_name, power_on, valid_values
from manip.conformance.judge.checks import check_reply
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.spec import SPEC, RequestOpcode
from manip.spec.notation import octal

_KIND_CLAUSES: Final[Mapping[str, tuple[str, ...]]] = {
    "done": ("response.done-empty",),
    "data": ("response.data-layout",),
    "segment": ("response.segment-number",),
    "multi": ("describe.reply-shape", "multi.terminated-by-empty", "multi.same-request-number"),
}
_COMMON: Final = (
    "request.one-reply",
    "response.echoes-request-number",
    "response.word-byte-order",
    "response.server-opcodes",
)


def opcode_clauses(op: RequestOpcode) -> tuple[str, ...]:
    """The clauses a well-formed exchange of ``op`` exercises: the common ones, the response form's,
    and the opcode's own reply clauses as the spec data states them (``reply_clauses``)."""
    return (*_COMMON, *_KIND_CLAUSES[op.response.form], *op.reply_clauses)


async def _release_free_joint(ctx: CaseContext, probe: Probe) -> None:
    """The packet after free joint is discarded with an empty done (it un-frees the joint)."""
    follow = await probe.call("here")
    ctx.expect_response(
        follow, clause="free-joint.replies", expected="an empty done for the packet after free joint", size=2
    )


def _done_clauses(op: RequestOpcode) -> tuple[str, ...]:
    """The opcode's own reply clauses that state its answer is an empty done (``calibrate.done``...):
    a done carrying anything after the request number breaks them, as well as ``response.done-empty``."""
    return tuple(c for c in op.reply_clauses if op.response.form == "done" and c.endswith(".done"))


FollowUp = Callable[[CaseContext, Probe], Awaitable[None]]
_FOLLOW_UPS: Final[Mapping[str, tuple[FollowUp, tuple[str, ...]]]] = {
    "free-joint": (_release_free_joint, ("free-joint.replies",)),
}
"""What an opcode's case does after a normal reply, and the clauses that adds."""


@case.each(SPEC.requests.values())
def _reply_case(op: RequestOpcode) -> None:
    follow_up, follow_clauses = _FOLLOW_UPS.get(op.name, (None, ()))
    done_clauses = _done_clauses(op)

    async def reply_shape(ctx: CaseContext) -> None:
        probe = await ctx.connect()
        if (op.hazard in ("motion", "power") or op.name == "hand") and op.name != "enable-power":
            await power_on(ctx, probe)  # enable power itself is judged whole, not required as a step
        values = await valid_values(ctx, probe, op)
        # a reply that waits for the arm gets the time the spec allows it
        timeout = op.answer_time(ctx.options.reply_timeout, ctx.options.deadline_scale)
        answer = await probe.call(op.name, timeout=timeout, **values)
        error = error_of(answer)
        if error is not None:
            ctx.check(check_reply(answer.request, answer.packets))  # echo and error-string format
            said = repr(error.error.render())
            if op.extension:
                ctx.not_judged(
                    f"the target refused {extension_name(op.name)} ({said}): its reply is judged on a target "
                    "that serves it"
                )
            if error.error.code in NOT_SERVED:
                ctx.not_judged(
                    f"the target does not serve {op.name} ({said}): its reply is judged on a target that "
                    "serves it"
                )
            ctx.not_judged(
                f"the target refused a well-formed {op.name} ({said}): its reply's shape shows only in a "
                "normal reply (a target in the state a normal reply needs would judge it)"
            )
        ctx.check(check_reply(answer.request, answer.packets))
        for clause in done_clauses:
            ctx.expect_done(answer, clause=clause, expected=f"{op.name} answered with an empty done")
        if follow_up is not None:
            await follow_up(ctx, probe)
        ctx.note(f"{op.name}: {answer}")

    case(
        f"server.reply.{op.name}",
        summary=f"{op.title} ({octal(op.opcode)}): one {op.response.form} reply echoing the request.",
        clauses=(*opcode_clauses(op), *follow_clauses),
        hazard=op.hazard,
        deadline=10.0 + (op.answer_within or 0.0),
        extensions=[op.name] if op.extension else [],
    )(reply_shape)
