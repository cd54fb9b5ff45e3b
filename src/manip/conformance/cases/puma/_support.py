"""Helpers of the Puma cases (no cases are declared here): the judging Cougar and a Chaos session with
the Puma, motion, and the asynchronous responses the cases wait for.

A Puma case drives the Puma through its Chaos side with the suite's probe and reads what the Puma sent
its wrist from the judging Cougar (:mod:`manip.conformance.puma.judge`).  Preparing a case (power,
notifications, the angles) judges nothing: a refusal skips the case, as for the server cases."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Final

from manip.codecs.messages import decode_reply
from manip.codecs.pdp11float import f_to_words, words_to_f
from manip.conformance.cases._support import power_on, read_floats, require_response
from manip.conformance.judge.checks import WirePacket, async_of
from manip.conformance.puma.judge import CougarScript, JudgingCougar, NoJudgeError, current_judge
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.spec import SPEC, RequestName
from manip.spec.constants import AsyncCondition, ServerOp

GUARD_BIT: Final = 1
SEGMENT_BIT: Final = 2
STOP_WORD: Final = 1
CONTINUE_WORD: Final = 2
TICK: Final = 0.016
"""The Puma's servo period (Part II §5.2: sixteen milliseconds)."""
SEGMENT_WITHIN: Final = SPEC.segment_within
"""Seconds a segment may take at speed factor 1 (spec data; erratum answer-allowance)."""


def judge_of(ctx: CaseContext) -> JudgingCougar:
    """The run's judging Cougar; the case skips without one."""
    try:
        return current_judge()
    except NoJudgeError as exc:
        ctx.skip(str(exc))


async def session(
    ctx: CaseContext, *, power: bool = True, notify: int | None = GUARD_BIT | SEGMENT_BIT
) -> Probe:
    """A fresh connection to the Puma: power on (which clears the wrist guards and an abort) and the
    asynchronous responses ``notify`` asks for."""
    probe = await ctx.connect()
    if power:
        await power_on(ctx, probe)
    if notify is not None:
        answer = await probe.call("request-notifications", mask=notify)
        require_response(ctx, answer, "asynchronous notifications (request-notifications)")
    return probe


def begin(ctx: CaseContext, script: CougarScript | None = None) -> tuple[JudgingCougar, int]:
    """The judge with this case's script, and the mark its record starts from."""
    judge = judge_of(ctx)
    return judge, judge.begin(script)


def f_float(x: float) -> float:
    """``x`` as a PDP-11 F float carries it (what the Puma receives and passes on)."""
    hi, lo = f_to_words(x)
    return words_to_f(hi, lo)


def segment_of(answer: Answer) -> int | None:
    """The segment number of a motion request's normal response."""
    if not answer.is_response:
        return None
    value = decode_reply(answer.data, SPEC.requests[answer.request.opcode]).values.get("segment")
    return value if isinstance(value, int) else None


async def move(ctx: CaseContext, probe: Probe, op: RequestName, **values: Any) -> int:
    """Queue a motion request; its segment number (the case skips when the Puma refuses it)."""
    answer = await probe.call(op, **values)
    require_response(ctx, answer, f"{op} accepted")
    segment = segment_of(answer)
    if segment is None:
        ctx.skip(f"{op} was answered without a segment number: {answer}")
    return segment


def async_words(packet: WirePacket) -> tuple[int, ...]:
    """The words of an asynchronous response after its request number (condition, word 2, word 3), in
    either layout (erratum ``async-request-number``); none when its length is neither."""
    message = async_of(packet)
    return () if message is None else (message.condition, message.word2, message.word3)


def is_completed(segment: int) -> Callable[[WirePacket], bool]:
    def match(p: WirePacket) -> bool:
        words = async_words(p)
        return (
            p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE
            and words[:1] == (AsyncCondition.SEGMENT_COMPLETED,)
            and words[2:3] == (segment,)
        )

    return match


def is_guard_hit(p: WirePacket) -> bool:
    return p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE and async_words(p)[:1] == (AsyncCondition.GUARD_HIT,)


def is_async_error(p: WirePacket) -> bool:
    return p.opcode == ServerOp.ASYNCHRONOUS_ERROR


async def wait_async(
    ctx: CaseContext, probe: Probe, match: Callable[[WirePacket], bool], timeout: float, *, after: int = 0
) -> WirePacket | None:
    """The first asynchronous packet that matches: already set aside (from ``probe.unsolicited[after]``
    on) or arriving within ``timeout``."""
    for packet in probe.unsolicited[after:]:
        if match(packet):
            return packet
    end = ctx.clock() + timeout
    while (left := end - ctx.clock()) > 0:
        arrived = await probe.next_packet(left)
        if arrived is None:
            return None
        probe.unsolicited.append(arrived)
        if match(arrived):
            return arrived
    return None


async def angles(ctx: CaseContext, probe: Probe) -> tuple[float, ...]:
    return await read_floats(ctx, probe, "joint-angles")


def close(a: Sequence[float], b: Sequence[float], tol: float) -> bool:
    return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def fmt(values: Sequence[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"
