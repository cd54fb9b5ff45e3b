"""Hostile servers against ``manip-conform run``: every run ends with a verdict naming what the target did
(exit 1), or exit 3 for a target that sent nothing, within its bounds and with no traceback.  The
scenarios are those of ``tools/hostile_servers.py`` (the long form, run by hand), each against a few
cases, as a real process whose peak memory is measured.  The bounds asserted are generous (a loaded
machine runs them slower); what they catch is growth without end, a hang, or the wait paid per case."""

from __future__ import annotations

from types import ModuleType

import pytest

from manip.conformance.judge.violation import MAX_EVIDENCE_BYTES, MAX_TEXT, Violation
from tests.support.tools import load_tool

pytestmark = pytest.mark.waits  # real processes against a real server: mostly waiting


def _tool() -> ModuleType:
    return load_tool("hostile_servers")


HOSTILE = _tool()
SCENARIOS = HOSTILE.scenarios()
RSS_MB = 300
REPORT_BYTES = 5 << 20


def _run(name: str, *select: str, timeout: float = 240.0) -> object:
    extra = [word for pattern in select for word in ("--select", pattern)]
    figures = HOSTILE.run_scenario(name, SCENARIOS[name], "run", timeout=timeout, extra=extra)
    assert figures.exit is not None, f"{name}: still running after {timeout} s"
    assert not figures.traceback, f"{name}: a traceback in the output"
    assert figures.rss_mb < RSS_MB, f"{name}: peak RSS {figures.rss_mb:.0f} MB"
    assert figures.report_bytes < REPORT_BYTES, f"{name}: a report of {figures.report_bytes} bytes"
    return figures


@pytest.mark.timeout(300)
def test_an_endless_describe_self_fails_at_the_reply_bound_instead_of_growing() -> None:
    # On main this grew a run to 3.3 GB; the 1 MiB bound of manip-client now ends each reply.
    figures = _run("endless-describe", "server.describe.alist", "server.reply.describe-self")
    assert figures.exit == 1 and "request.one-reply" in figures.failed_clauses, figures


@pytest.mark.timeout(300)
def test_a_target_that_opens_and_says_nothing_is_unreachable() -> None:
    figures = _run("silent-opn", "server.describe.*")
    assert figures.exit == 3 and figures.verdict == "target unreachable", figures


@pytest.mark.timeout(300)
def test_a_target_that_closes_at_its_first_request_gets_a_verdict_naming_it() -> None:
    # It was reached (the initial RESPONSE came) and then broke the exchange: not "unreachable".
    figures = _run("close-at-first", "server.reply.*")
    assert figures.exit == 1 and figures.verdict == "non-conformant", figures
    assert "request.one-reply" in figures.failed_clauses, figures


@pytest.mark.timeout(300)
def test_a_silent_target_is_noticed_once_not_paid_for_per_property_example() -> None:
    # The four property cases have deadlines of 77 s each; against a target that stopped answering
    # after its initial RESPONSE each example used to pay the reply timeout again.
    figures = _run("silent-initial", "property.*")
    assert figures.exit == 1, figures
    assert figures.seconds < 4 * 77 / 2, figures


@pytest.mark.timeout(300)
def test_a_target_that_answers_one_request_a_connection_is_given_up_once() -> None:
    # Each case used to pay the reply timeout again: the liveness probe (one request) found it alive.
    figures = _run("silent-after-one", "server.reply.*")
    counts = dict(figures.counts)
    assert figures.exit == 1 and counts["fail"] == 1 and counts["not-judged"] > 10, figures


def test_a_violation_keeps_bounded_evidence_and_says_what_it_cut() -> None:
    v = Violation("m" * (MAX_TEXT + 10), actual="short", data=bytes(MAX_EVIDENCE_BYTES + 100))
    assert len(v.data) == MAX_EVIDENCE_BYTES
    assert v.message.endswith("(10 more characters)")
    assert f"the first {MAX_EVIDENCE_BYTES:,} of {MAX_EVIDENCE_BYTES + 100:,} bytes shown" in v.actual
    small = Violation("m", actual="a", data=b"\x01\x02")
    assert (small.message, small.actual, small.data) == ("m", "a", b"\x01\x02")
