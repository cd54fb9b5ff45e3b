"""A case's context with no target behind it, for tests of what a check records and names."""

from __future__ import annotations

from manip.conformance.suite.context import CaseContext, RunOptions
from manip.links import ChaosConnection


async def _no_connection(retry_busy: bool) -> ChaosConnection:
    raise AssertionError("the case connected")


def bare_context(case_id: str, *clauses: str) -> CaseContext:
    """Case ``case_id``'s context (level MUST, seed 1) declaring ``clauses``; connecting fails the test."""
    return CaseContext(
        case_id=case_id,
        level="MUST",
        seed=1,
        options=RunOptions(),
        connector=_no_connection,
        clauses=clauses,
    )
