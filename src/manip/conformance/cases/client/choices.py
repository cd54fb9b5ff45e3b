"""What a client chooses for itself, judged live: the number a new guard gets, what it sends when the
hand's load changes, and that it leaves the gravity model alone while a guard is armed.

The harness is told only *what* to do (the contract's choice operations ``arm-guard`` and
``change-load``, docs/client-harness.md section 4.4); the client decides which packets that takes.  The
packets it sent are judged by :func:`~manip.conformance.judge.checks.check_client_guards`, the rule
``manip-conform verify --judge client`` applies to a recording, over the same packets a recording would
hold (:func:`~manip.conformance.client.wire.judged_packets`).
"""

from __future__ import annotations

from typing import Any, Final

from manip.codecs.messages import encode_request
from manip.conformance.cases.client._support import close, connect, request, wait
from manip.conformance.client.contract import Op
from manip.conformance.client.runner import ClientContext, Play, client_context
from manip.conformance.client.server import ServerSide, plain_answer
from manip.conformance.client.wire import client_requests, judged_packets
from manip.conformance.judge.checks import check_client_guards
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.spec import SPEC

GUARDS: Final = 16
SET_GUARD: Final = SPEC.request("set-guard").opcode
SET_WEIGHT: Final = SPEC.request("set-weight").opcode
SET_FRAME_VECTOR: Final = SPEC.request("set-frame-vector").opcode
CLEAR_GUARD: Final = SPEC.request("clear-guard").opcode


def _guard_args(ctx: ClientContext) -> dict[str, Any]:
    dvec = [0.0] * 6
    dvec[ctx.random.randrange(3)] = 1.0
    return {"dvec": dvec, "tol": float(ctx.random.randint(2, 40)), "stop": True}


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
    for finding in check_client_guards(judged_packets(play.wire)):
        if finding.clause == clause:
            ctx.expect(False, clause=clause, expected=finding.expected, actual=finding.message)


def _sent(play: Play, opcode: int) -> list[bytes]:
    return [r.packet.data for r in client_requests(play.wire) if r.packet.opcode == opcode]


@case("client.choice.guard-numbers", clauses=["client.guard-numbers"], hazard="config")
async def guard_numbers(base: CaseContext) -> None:
    """With guard hits reported, the harness arms sixteen guards, leaving the numbers to the client;
    one of them trips (a guard-hit asynchronous response, drawn from the seed) and it arms one more:
    no guard number is ever given while it is armed, so the last takes the tripped one."""
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

    args = _guard_args(ctx)
    ops: list[Op] = [connect(0), request(1, "request-notifications", {"mask": 1})]
    ops += [Op(i, "arm-guard", args=args) for i in range(2, GUARDS + 2)]
    ops += [wait(GUARDS + 2, 0.3), Op(GUARDS + 3, "arm-guard", args=args), close(GUARDS + 4)]
    play = await ctx.play(ops, script)
    _expect_rule(ctx, play, "client.guard-numbers")
    chosen = [r.get("values", {}).get("guard") for i in range(2, GUARDS + 4) if (r := play.one("reply", i))]
    ctx.expect(
        len(chosen) == GUARDS + 1,
        clause="client.guard-numbers",
        expected=f"{GUARDS + 1} arm-guard ops answered (one guard number free for the last: {tripped})",
        actual=play.describe(),
    )
    numbers = [int.from_bytes(d[:2], "little") & 0xF for d in _sent(play, SET_GUARD)]
    ctx.expect(
        not tripped or numbers[-1:] == tripped,
        clause="client.guard-numbers",
        expected=f"the last guard armed with number {tripped}, the only one free",
        actual=f"set-guard numbers sent: {numbers}",
    )


@case("client.choice.newwc-on-load", clauses=["client.newwc-on-load"], hazard="config")
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
        actual=f"set weight data sent: {[d.hex() for d in _sent(play, SET_WEIGHT)]}",
    )
    answer = play.answer(1)
    ctx.expect(
        answer is not None and answer.type == "reply",
        clause="client.newwc-on-load",
        expected="change-load done",
        actual=str(answer),
    )


@case("client.choice.no-newwc-with-guard", clauses=["client.no-newwc-with-guard"], hazard="config")
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
        actual=str(answer),
    )
