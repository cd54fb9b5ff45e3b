"""What the suite says when something breaks, as a first-time implementer reads it: plain grammar, every
value with its unit, the layout a packet should have had, and every violation of a case, not only its
first."""

from __future__ import annotations

import asyncio

from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import CaseContext, Probe, RunOptions
from manip.conformance.suite.results import CaseResult
from manip.reference_server.faults import FaultSet
from manip.reference_server.session import ServerConfig
from tests.support.suite import run_suite


def _case(case_id: str, *faults: str) -> CaseResult:
    cases = [c for c in all_cases() if c.id == case_id]
    config = ServerConfig(faults=FaultSet.parse(list(faults)))
    return run_suite(cases, config, seed=3, time_scale=8.0, options={"reply_timeout": 0.5}).results[0]


def test_a_turn_off_by_some_amount_says_its_unit() -> None:
    result = _case("server.motion.incremental-oat", "increment-o-t-swapped")
    assert result.outcome == "fail"
    actual = result.violations[0].actual
    assert "rotation off by" in actual and " deg (its matrix by " in actual and "unitless" in actual
    assert "mm" in actual


def test_a_missing_reply_is_said_in_plain_words() -> None:
    async def no_answer() -> str:
        async def connector(_retry: bool) -> object:
            raise AssertionError("not used")

        ctx = CaseContext(case_id="t.m", level="MUST", seed=1, options=RunOptions(), connector=connector)  # type: ignore[arg-type]
        probe = Probe(ctx, _SilentConnection(), 0)  # type: ignore[arg-type]
        number = await probe.request("here")
        try:
            await probe.reply(number, timeout=0.01)
        except Exception as exc:  # CaseFailure
            return str(exc)
        raise AssertionError("an answer came")

    message = asyncio.run(no_answer())
    assert message.startswith("a reply to request #") and "did not come within 0.01 s" in message
    assert "no a reply" not in message


class _SilentConnection:
    """A Chaos connection that takes requests and never answers."""

    def __init__(self) -> None:
        self.number = 0

    async def send(self, data: bytes, opcode: int) -> int:
        self.number += 1
        return self.number

    async def receive(self) -> object:
        await asyncio.sleep(3600)
        raise AssertionError("unreachable")

    def info(self) -> None:
        return None
