"""What the suite says when something breaks, as a first-time implementer reads it: plain grammar, every
value with its unit, the layout a packet should have had, and every violation of a case, not only its
first."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

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
    assert result.outcome == "warn"  # incremental.relative is a SHOULD: E.1 gives the deltas no frame
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


def test_cases_and_coverage_piped_are_one_record_per_line_never_padded() -> None:
    from click.testing import CliRunner

    from manip.conformance.cli import main

    for command, header in (
        (["cases"], "id\tlevel\tkind\thazard\textensions\tclauses"),
        (["coverage"], "clause\tlevel\tparty\tcases"),
    ):
        lines = CliRunner().invoke(main, command).output.splitlines()
        assert lines[0] == header
        records = [line.split("\t") for line in lines[1:] if "\t" in line]
        assert len(records) > 100 and all(len(r) == len(header.split("\t")) for r in records)
        assert not any(cell != cell.strip() or "  " in cell for r in records for cell in r)  # no padding
        assert not any(ch in "".join(lines) for ch in "┃│━")  # no table drawing
    ids = {
        r[0] for r in (line.split("\t") for line in CliRunner().invoke(main, ["cases"]).output.splitlines())
    }
    assert "server.describe.pipelined" in ids


def test_a_fuzz_violation_cuts_a_long_input_on_the_console_and_keeps_it_whole_in_the_report() -> None:
    from manip.conformance.fuzz.report import (
        CONSOLE_CUT,
        CampaignViolation,
        MinimalInput,
        violation_json,
        violation_text,
    )
    from manip.conformance.judge.violation import Violation

    data = bytes(range(256)) + bytes(232)  # a 488-byte input
    step = f"request 0201, {len(data)} data bytes: {data.hex(' ')}"
    violation = CampaignViolation(
        Violation("wrong answer", "request.data-length", expected="a C error", actual="done"),
        input_class="wrong-length",
        first_batch=1,
        minimal=[MinimalInput(7, "wrong-length", "488 bytes", [step])],
        reproduce="manip-conform fuzz --seed 1 --only 7 " + "x" * 300,
    )
    text = violation_text(violation)
    assert max(len(line) for line in text.splitlines() if "reproduce:" not in line) < CONSOLE_CUT + 80
    assert f"{len(step) + 6 - CONSOLE_CUT} more characters; whole in the JSON report" in text
    assert violation.reproduce in text  # a reproduce line is never cut
    assert step in str(violation_json(violation))


def test_a_case_summary_is_whole_sentences_never_its_first_line_cut() -> None:
    from manip.conformance.suite.case import summary_of

    doc = """Three moves queued back to back, sampled every 8 ms: they complete in order, the arm
    does not stop between them.

    More detail that is not the summary."""
    assert summary_of(doc) == (
        "Three moves queued back to back, sampled every 8 ms: they complete in order, the arm does not "
        "stop between them."
    )
    from_docstrings = [
        c for c in all_cases() if c.function.__doc__ and c.summary == summary_of(c.function.__doc__)
    ]
    assert len(from_docstrings) > 50
    assert all(c.summary.endswith((".", ")", "?")) for c in from_docstrings), [
        c.id for c in from_docstrings if not c.summary.endswith((".", ")", "?"))
    ]


def test_a_cougar_response_layout_is_stated_in_words() -> None:
    from manip.conformance.cougar.probe import layout_words
    from manip.spec import SPEC

    by_name = {m.name: m for m in SPEC.cougar_responses.values()}
    assert layout_words(by_name["OUT-OF-SYNC"]) == "words: 2, code"
    assert layout_words(by_name["EXMN-DATA"]) == "words: 4, count, words..."


def test_a_passing_cougar_case_keeps_its_exchange_in_the_report(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from manip.conformance.cli import main

    report = tmp_path / "c.json"
    args = ["run", "--cougar", "--seed", "1", "--select", "cougar.link.*", "--json", str(report)]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    cases = json.loads(report.read_text())["cases"]
    assert cases and all(c["outcome"] == "pass" for c in cases)
    assert all(any(n.startswith("DRV-11J exchange") and "<- " in n for n in c["notes"]) for c in cases)


def test_the_verify_verdict_line_says_how_many_clauses_it_judged() -> None:
    from click.testing import CliRunner

    from manip.conformance.cli import main
    from tests.support.paths import ROOT

    result = CliRunner().invoke(main, ["verify", str(ROOT / "captures" / "errors.mcap")])
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("conformant (exit 0)") and " MUST clauses judged" in last, last


def test_a_cougar_response_that_never_completes_shows_the_words_that_came() -> None:
    """A bare 2 (an OUT-OF-SYNC without its word) is not "nothing": the words received are shown."""
    from types import SimpleNamespace

    import pytest

    from manip.conformance.cougar.probe import CougarProbe, LinkLog
    from manip.conformance.suite.case import CaseFailure

    probe = CougarProbe.__new__(CougarProbe)  # no link: the ticks do nothing, one word waits
    probe.log = LinkLog(None)
    probe._inbox = []  # type: ignore[attr-defined]
    probe._stream = SimpleNamespace(pending=(2,))  # type: ignore[attr-defined]

    async def tick(_gap: object) -> None:
        return None

    probe._tick = tick  # type: ignore[method-assign]
    with pytest.raises(CaseFailure) as failed:
        asyncio.run(probe.reply("NOP", within=2))
    assert failed.value.actual == "no whole response: 1 word(s) came that make no Table 1 response yet: 02"


def test_the_clauses_no_case_reached_are_listed_with_the_case_that_would_reach_them() -> None:
    """A run that skips the link cases a TCP target cannot offer says, one line per reason, which
    clauses went unexercised and which case, had it run, would have reached them (and over what)."""
    from click.testing import CliRunner

    from manip.conformance.cli import main

    result = CliRunner().invoke(main, ["run", "--seed", "1", "--select", "server.link.*"])
    lines = result.output.splitlines()
    at = lines.index("not exercised (no check of the run reached them):")
    chudp, chaosd = lines[at + 1 : at + 3]
    assert chudp.startswith("  chudp.checksum, chudp.header, chudp.length, chudp.trailer, chudp.word-order: ")
    assert "server.link.chudp-frames (skip: " in chudp and "chudp:// address" in chudp, chudp
    assert chaosd.startswith("  link.chaosd.framing: ") and "server.link.chaosd-frames (skip: " in chaosd, (
        chaosd
    )
