"""What a client chooses for itself, judged live: the number a new guard gets, what it sends when the
hand's load changes, and that it leaves the gravity model alone while a guard is armed.

The harness is told only *what* to do (the contract's choice operations ``arm-guard`` and
``change-load``, docs/client-harness.md section 4.4); the client decides which packets that takes.  The
packets it sent are judged by :func:`~manip.conformance.judge.client_checks.check_client_guards`, the rule
``manip-conform verify --judge client`` applies to a recording, over the same packets a recording would
hold (:func:`~manip.conformance.client.wire.judged_packets`).
"""

from __future__ import annotations

from typing import Any, Final

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_request
from manip.conformance.cases.client._support import close, connect, expect_error_parts, request, wait
from manip.conformance.client.contract import Op
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide, WireRecord, plain_answer
from manip.conformance.client.wire import client_requests, judged_packets
from manip.conformance.judge.client_checks import check_client_guards
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC
from manip.spec.constants import ServerOp

GUARDS: Final = 16
SET_GUARD: Final = SPEC.request("set-guard").opcode
SET_WEIGHT: Final = SPEC.request("set-weight").opcode
SET_FRAME_VECTOR: Final = SPEC.request("set-frame-vector").opcode
CLEAR_GUARD: Final = SPEC.request("clear-guard").opcode
STOP_BIT: Final = 0x8000
"""Bit 15 of set guard's first word: a trip stops the move (clear: the move continues)."""


def _guard_args(ctx: ClientContext) -> dict[str, Any]:
    """An arm-guard's args drawn from the seed: a force direction, a threshold, stop or continue."""
    dvec = [0.0] * 6
    dvec[ctx.random.randrange(3)] = 1.0
    return {"dvec": dvec, "tol": float(ctx.random.randint(2, 40)), "stop": ctx.random.random() < 0.5}


def _load(ctx: ClientContext, *, offset: bool) -> dict[str, Any]:
    rng = ctx.random
    load: dict[str, Any] = {
        "weight": float(rng.randint(1, 64)),
        "cg": [float(rng.randint(-40, 40)) for _ in range(3)],
    }
    if offset:
        load["offset"] = [float(rng.randint(-100, 100)) for _ in range(3)]
    return load


def _expect_rule(ctx: ClientContext, play: Play, clause: str) -> None:
    """The recording rule for ``clause``, over the packets of the play."""
    for violation in check_client_guards(judged_packets(play.wire)):
        if violation.clause == clause:
            ctx.expect(False, clause=clause, expected=violation.expected, seen=violation.message)


def _sent(play: Play, opcode: int) -> list[bytes]:
    return [r.packet.data for r in client_requests(play.wire) if r.packet.opcode == opcode]


def _expect_guard_words(ctx: ClientContext, play: Play, arms: list[tuple[int, dict[str, Any]]]) -> None:
    """Each arm-guard op (id, args), in order, went out as one set guard whose first word holds the
    number the harness reported in its low 4 bits and bit 15 set exactly when the guard stops the move,
    with the op's dvec and tol (client.guard-word)."""
    sent = _sent(play, SET_GUARD)
    for (op_id, args), data in zip(arms, sent, strict=False):
        reply = play.one("reply", op_id)
        number = (reply.get("values") or {}).get("guard") if reply is not None else None
        if not isinstance(number, int) or not 0 <= number < GUARDS:
            continue  # judged by client.guard-numbers
        stop = bool(args.get("stop", True))
        first = (STOP_BIT if stop else 0) | number
        want = encode_request("set-guard", type_index=first, dvec=args["dvec"], tol=args["tol"])
        ctx.expect(
            data == want,
            clause="client.guard-word",
            expected=f"op {op_id}: set guard {want.hex()} (first word {first:#06x}: guard {number}, "
            f"{'stop' if stop else 'continue'}: bit 15 {'set' if stop else 'clear'})",
            seen=f"set guard {data.hex()} (first word {int.from_bytes(data[:2], 'little'):#06x})",
        )


@case(
    "client.choice.guard-numbers",
    clauses=["client.guard-numbers", "client.guard-word"],
    hazard="config",
    summary="arm-guard gives no number that is armed, and puts the number in bits 0-3 and stop in bit 15",
)
async def guard_numbers(base: CaseContext) -> None:
    """With guard hits reported, the harness arms sixteen guards, some to stop the move on a trip and
    some to let it continue (drawn from the seed), leaving the numbers to the client; one of them trips
    (a guard-hit asynchronous response, drawn from the seed) and it arms one more: no guard number is
    ever given while it is armed, so the last takes the tripped one, and each set guard's first word
    carries the number in its low 4 bits and the stop choice in bit 15."""
    ctx = client_context(base)
    tripped: list[int] = []

    async def script(side: ServerSide) -> None:
        armed: list[int] = []
        while len(armed) < GUARDS + 1 and (req := await side.next_request()) is not None:
            await plain_answer(side, req)
            if req.opcode == SET_GUARD and len(req.data) >= 2:
                armed.append(int.from_bytes(req.data[:2], "little") & 0xF)
            if len(armed) == GUARDS and not tripped:
                tripped.append(ctx.random.choice(armed))
                await side.async_response(1, 2, tripped[0])
        await side.serve_plainly()

    arms = [(i, _guard_args(ctx)) for i in range(2, GUARDS + 2)]
    last = (GUARDS + 3, _guard_args(ctx))
    ops: list[Op] = [connect(0), request(1, "request-notifications", {"mask": 1})]
    ops += [Op(i, "arm-guard", args=args) for i, args in arms]
    ops += [wait(GUARDS + 2, 0.3), Op(last[0], "arm-guard", args=last[1]), close(GUARDS + 4)]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.guard-numbers")
    _expect_guard_words(ctx, play, [*arms, last])
    chosen = [r.get("values", {}).get("guard") for i in range(2, GUARDS + 4) if (r := play.one("reply", i))]
    ctx.expect(
        len(chosen) == GUARDS + 1,
        clause="client.guard-numbers",
        expected=f"{GUARDS + 1} arm-guard ops answered (one guard number free for the last: {tripped})",
        seen=play.describe(),
    )
    numbers = [int.from_bytes(d[:2], "little") & 0xF for d in _sent(play, SET_GUARD)]
    ctx.expect(
        not tripped or numbers[-1:] == tripped,
        clause="client.guard-numbers",
        expected=f"the last guard armed with number {tripped}, the only one free",
        seen=f"set-guard numbers sent: {numbers}",
    )


@case(
    "client.choice.newwc-on-load",
    clauses=["client.newwc-on-load"],
    hazard="config",
    summary="change-load with an offset: set frame vector, then set weight (NEWWC), before forces are read",
)
async def newwc_on_load(base: CaseContext) -> None:
    """The hand takes a new object and the frame vector moves (change-load with an offset), then the
    forces are read: the client sends set frame vector, then set weight (NEWWC) with the object's
    weight and centre of gravity, before the read."""
    ctx = client_context(base)
    load = _load(ctx, offset=True)

    async def script(side: ServerSide) -> None:
        await side.serve_plainly()

    ops = [connect(0), Op(1, "change-load", args=load), request(2, "read-forces"), close(3)]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.newwc-on-load")
    want = encode_request("set-weight", weight=load["weight"], cg=load["cg"])
    ctx.expect(
        want in _sent(play, SET_WEIGHT),
        clause="client.newwc-on-load",
        expected=f"set weight {want.hex()} (weight {load['weight']}, cg {load['cg']}) after the load changed",
        seen=f"set weight data sent: {[d.hex() for d in _sent(play, SET_WEIGHT)]}",
    )
    answer = play.answer(1)
    ctx.expect_result(answer, clause="client.newwc-on-load", expected="change-load done")


@case(
    "client.choice.no-newwc-with-guard",
    clauses=["client.no-newwc-with-guard"],
    hazard="config",
    summary="change-load under an armed guard is refused, or clears the guards first: no NEWWC while armed",
)
async def no_newwc_with_guard(base: CaseContext) -> None:
    """The load changes while a guard is armed: the client sends neither set weight nor set frame
    vector while the guard is armed (it may refuse the change, or clear the guard first)."""
    ctx = client_context(base)
    load = _load(ctx, offset=ctx.random.random() < 0.5)

    async def script(side: ServerSide) -> None:
        await side.serve_plainly()

    ops = [
        connect(0),
        request(1, "request-notifications", {"mask": 1}),
        Op(2, "arm-guard", args=_guard_args(ctx)),
        Op(3, "change-load", args=load),
        close(4),
    ]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.no-newwc-with-guard")
    answer = play.answer(3)
    refused = answer is not None and answer.type == "error" and answer.get("kind") == "refused-locally"
    ctx.expect(
        answer is not None and (refused or answer.type == "reply"),
        clause="client.no-newwc-with-guard",
        expected="change-load refused (refused-locally) or done",
        seen=str(answer),
    )


def _expect_newwc(ctx: ClientContext, play: Play, load: dict[str, Any], *, after: int = 0) -> None:
    """A set weight (NEWWC) with the load's weight and centre of gravity among the client's requests
    from its ``after``-th set weight on."""
    want = encode_request("set-weight", weight=load["weight"], cg=load["cg"])
    sent = _sent(play, SET_WEIGHT)[after:]
    ctx.expect(
        want in sent,
        clause="client.newwc-on-load",
        expected=f"set weight {want.hex()} (weight {load['weight']}, cg {load['cg']}) after the load changed",
        seen=f"set weight data sent: {[d.hex() for d in sent]}",
    )


@case(
    "client.choice.newwc-without-offset",
    clauses=["client.newwc-on-load"],
    hazard="config",
    summary="change-load without an offset, no guard armed: set weight (NEWWC) is still sent",
)
async def newwc_without_offset(base: CaseContext) -> None:
    """The hand takes a new object and the frame vector stays (change-load without an offset), no
    guard armed, then the forces are read: the client sends set weight (NEWWC) with the object's
    weight and centre of gravity (B.8: whenever the hand picks up a new object)."""
    ctx = client_context(base)
    load = _load(ctx, offset=False)

    async def script(side: ServerSide) -> None:
        await side.serve_plainly()

    ops = [connect(0), Op(1, "change-load", args=load), request(2, "read-forces"), close(3)]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.newwc-on-load")
    _expect_newwc(ctx, play, load)
    answer = play.answer(1)
    ctx.expect_result(answer, clause="client.newwc-on-load", expected="change-load done")


@case(
    "client.choice.plain-guards",
    clauses=["client.guard-numbers", "client.no-newwc-with-guard", "client.newwc-on-load"],
    hazard="config",
    summary="guards of plain set guard and clear guard requests count for new guard numbers and for the load",
)
async def plain_guards(base: CaseContext) -> None:
    """Guards armed by plain set guard requests count as the client's own: with guard 0 and one drawn
    from the seed armed so (one stopping, one continuing), a change of load sends neither set weight
    nor set frame vector, and arm-guard picks neither number; once both are cleared by plain clear
    guard requests and the arm-guard's guard is reported tripped, a change of load without an offset
    sends set weight."""
    ctx = client_context(base)
    rng = ctx.random
    other = rng.randrange(1, GUARDS)
    hit: list[int] = []

    async def script(side: ServerSide) -> None:
        guards = 0
        while (req := await side.next_request()) is not None:
            await plain_answer(side, req)
            guards += req.opcode == SET_GUARD
            if req.opcode == SET_GUARD and guards == 3 and len(req.data) >= 2:  # the arm-guard's
                hit.append(int.from_bytes(req.data[:2], "little") & 0xF)
                await side.async_response(1, 1 if req.data[1] & 0x80 else 2, hit[0])
        await side.until_ended(3.0)

    guard = _guard_args(ctx)
    first, second = _load(ctx, offset=True), _load(ctx, offset=False)
    ops: list[Op] = [
        connect(0),
        request(1, "request-notifications", {"mask": 1}),
        request(2, "set-guard", {"type_index": STOP_BIT, "dvec": guard["dvec"], "tol": guard["tol"]}),
        request(3, "set-guard", {"type_index": other, "dvec": guard["dvec"], "tol": guard["tol"]}),
        Op(4, "change-load", args=first),
        Op(5, "arm-guard", args=_guard_args(ctx)),
        request(6, "clear-guard", {"index": 0}),
        request(7, "clear-guard", {"index": other}),
        wait(8, 0.3),
        Op(9, "change-load", args=second),
        close(10),
    ]
    play = await ctx.play(ops, script)
    ctx.note(f"plain guards 0 and {other}; the arm-guard's guard {hit} reported tripped")
    for clause in ("client.guard-numbers", "client.no-newwc-with-guard", "client.newwc-on-load"):
        _expect_rule(ctx, play, clause)
    chosen = play.one("reply", 5)
    ctx.expect(
        chosen is not None and isinstance((chosen.get("values") or {}).get("guard"), int),
        clause="client.guard-numbers",
        expected=f"arm-guard done, with a number not armed (0 and {other} are, unless the client cleared "
        "them before the change of load)",
        seen=str(chosen) if chosen is not None else play.describe(),
    )
    answer = play.answer(4)
    ctx.expect(
        answer is not None
        and (answer.type == "reply" or (answer.type == "error" and answer.get("kind") == "refused-locally")),
        clause="client.no-newwc-with-guard",
        expected="the change-load under plain guards refused (refused-locally) or done",
        seen=str(answer),
    )
    before = sum(
        1 for r in client_requests(play.wire) if r.packet.opcode == SET_WEIGHT and _before_clear(play, r)
    )
    _expect_newwc(ctx, play, second, after=before)
    answer = play.answer(9)
    ctx.expect_result(
        answer, clause="client.newwc-on-load", expected="the change-load with no guard armed done"
    )


def _before_clear(play: Play, record: WireRecord) -> bool:
    """The request went out before the client's last clear guard."""
    clears = [r.t for r in client_requests(play.wire) if r.packet.opcode == CLEAR_GUARD]
    return bool(clears) and record.t < clears[-1]


REFUSED_GUARD: Final = ErrorMessage("PUMA", "E", "BVA", "Guard ~ refused", (0,))
REFUSED_FRAME: Final = ErrorMessage("PUMA", "E", "BVA", "Frame vector refused")


@case(
    "client.choice.errors",
    clauses=["client.error-report", "client.guard-numbers"],
    hazard="config",
    summary="a choice operation's error names its op and the failed request; a refused guard is free",
)
async def choice_errors(base: CaseContext) -> None:
    """The judging server answers the first set guard and every set frame vector with a non-fatal
    error: arm-guard and change-load each report that error, with their own op and the number of the
    request it answered (docs/client-harness.md section 4.4); a refused guard is not armed, so its
    number may be given again; whether change-load still sends set weight is the client's choice."""
    ctx = client_context(base)
    refused: list[int] = []

    async def script(side: ServerSide) -> None:
        while (req := await side.next_request()) is not None:
            if req.opcode == SET_GUARD and not refused:
                refused.append(req.packet_no)
                await side.error(ServerOp.NON_FATAL_ERROR, req.packet_no, REFUSED_GUARD)
            elif req.opcode == SET_FRAME_VECTOR:
                await side.error(ServerOp.NON_FATAL_ERROR, req.packet_no, REFUSED_FRAME)
            else:
                await plain_answer(side, req)
        await side.until_ended(3.0)

    ops: list[Op] = [
        connect(0),
        request(1, "request-notifications", {"mask": 1}),
        Op(2, "arm-guard", args=_guard_args(ctx)),
        Op(3, "change-load", args=_load(ctx, offset=True)),
        Op(4, "arm-guard", args=_guard_args(ctx)),
        close(5),
    ]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.guard-numbers")
    for op_id, error in ((2, REFUSED_GUARD), (3, REFUSED_FRAME)):
        expect_error_parts(
            ctx,
            play.answer(op_id),
            error,
            "non-fatal-error",
            clause="client.error-report",
            play=play,
            ops=(op_id,),
        )
    answer = play.answer(4)
    ctx.expect_result(
        answer, clause="client.guard-numbers", expected="the arm-guard after a refused one done"
    )
