"""The HTML and Markdown reports of manip-conform: the report of a failing run (the embedded server with a
fault switched on) opened in a real browser, and the documents checked without one.

The browser is Debian's ``chromium`` (``.ci/run`` installs it).  Without it the browser tests are skipped
and the run's last line says so, except under ``MANIP_REQUIRE_PROGRAMS=1`` (set by ``.ci/run``), where
they fail: CI must never pass without having opened the page (the one rule of
``tests/support/programs.py``).  The screenshot is kept in ``test-artifacts/report-html.png``.
"""

from __future__ import annotations

import copy
import json
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from manip.conformance.cli import main
from manip.conformance.output.html import render_html
from manip.conformance.output.markdown import render_markdown
from manip.conformance.output.report import load_schema
from manip.conformance.output.report_view import wire_bytes, wire_order
from manip.spec import SPEC
from tests.support.json_schema import validate as _validate
from tests.support.paths import ROOT
from tests.support.programs import need_program

ARTIFACT = ROOT / "test-artifacts" / "report-html.png"
FAULT = "error-without-colon"
BROKEN = "error-string.format"
"""The clause the fault breaks; every error the server sends shows it, so the cases fail in 0.1 s."""
SELECTION = ("server.error.*", "server.reply.here")
NASTY = "<script>alert('x')</script> & \"quoted\" <b>bold</b>"
BROWSER_TIMEOUT = 90.0


@dataclass
class Element:
    tag: str
    attrs: dict[str, str]
    text: list[str] = field(default_factory=list)

    @property
    def content(self) -> str:
        return "".join(self.text)

    @property
    def classes(self) -> set[str]:
        return set(self.attrs.get("class", "").split())


class Page(HTMLParser):
    """Every element of a page with its attributes and the text inside it (descendants' included)."""

    VOID = frozenset({"meta", "input", "br", "img", "link", "hr", "col", "source", "wbr", "area", "base"})

    def __init__(self, text: str) -> None:
        super().__init__(convert_charrefs=True)
        self.elements: list[Element] = []
        self.open: list[Element] = []
        self.feed(text)
        self.close()

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        element = Element(tag, {k: v or "" for k, v in attrs})
        self.elements.append(element)
        if tag not in self.VOID:
            self.open.append(element)

    def handle_endtag(self, tag: str) -> None:
        for i in range(len(self.open) - 1, -1, -1):
            if self.open[i].tag == tag:
                del self.open[i:]
                return

    def handle_data(self, data: str) -> None:
        for element in self.open:
            element.text.append(data)

    def by_id(self, element_id: str) -> Element:
        found = [e for e in self.elements if e.attrs.get("id") == element_id]
        assert len(found) == 1, f"{len(found)} elements with id {element_id!r}"
        return found[0]

    def by_class(self, name: str, tag: str | None = None) -> list[Element]:
        return [e for e in self.elements if name in e.classes and (tag is None or e.tag == tag)]


@dataclass(frozen=True)
class Run:
    json: Path
    html: Path
    markdown: Path
    data: dict[str, Any]


@pytest.fixture(scope="module")
def failing_run(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """A run of a few cases against the embedded server with a fault: --json, --html and --markdown."""
    where = tmp_path_factory.mktemp("report")
    paths = {name: where / f"report.{name}" for name in ("json", "html", "md")}
    selected = [word for pattern in SELECTION for word in ("--select", pattern)]
    # A process of its own, as a user runs it: the report's command line is then manip-conform's.
    done = subprocess.run(
        [sys.executable, "-m", "manip.conformance.cli", "run", "-q", "--seed", "7", "--server-fault", FAULT,
         *selected, "--json", "report.json", "--html", "report.html", "--markdown", "report.md"],
        capture_output=True, text=True, timeout=120, check=False, cwd=where,
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    data = json.loads(paths["json"].read_text())
    assert data["counts"]["fail"] >= 2 and data["counts"]["pass"] >= 1, data["counts"]
    return Run(paths["json"], paths["html"], paths["md"], data)


def _failing(run: Run) -> list[dict[str, Any]]:
    return [c for c in run.data["cases"] if c["outcome"] == "fail"]


# ------------------------------------------------------------------------------------ without a browser


def test_the_json_report_carries_the_clauses_its_cases_cite(failing_run: Run) -> None:
    schema = load_schema()
    _validate(failing_run.data, schema, schema)
    catalog = failing_run.data["clauses"]
    cited = {c for case in failing_run.data["cases"] for c in case["clauses"]}
    assert set(catalog) == cited
    for clause_id, entry in catalog.items():
        _validate(entry, schema["$defs"]["clause"], schema, f"$.clauses.{clause_id}")
        assert entry["text"] == SPEC.clauses[clause_id].text


def test_the_html_parses_and_loads_nothing_from_outside(failing_run: Run) -> None:
    text = failing_run.html.read_text()
    page = Page(text)
    assert page.open == [], f"unclosed elements: {[e.tag for e in page.open]}"
    assert [e.tag for e in page.elements if e.tag in ("link", "iframe", "img", "object", "embed")] == []
    scripts = [e for e in page.elements if e.tag == "script"]
    assert len(scripts) == 1 and "src" not in scripts[0].attrs  # the inlined script only
    for element in page.elements:
        for name in ("src", "href", "action", "data", "poster"):
            value = element.attrs.get(name, "")
            assert not re.match(r"\s*(https?:|//|ftp:)", value, re.IGNORECASE), (element.tag, name, value)
    assert not re.search(r"https?://", text), "an external URL in the page"
    assert not re.search(r"@import|url\(", text), "the style sheet loads something"


def test_the_html_shows_failures_by_clause_cases_and_packets(failing_run: Run) -> None:
    page = Page(failing_run.html.read_text())
    failures = page.by_id("failures").content
    assert BROKEN in failures and SPEC.clauses[BROKEN].text in failures
    for case in _failing(failing_run):
        assert case["id"] in failures
        detail = page.by_id(f"case-{case['id']}")
        assert "open" in detail.attrs  # failures are unfolded
        assert case["reproduce"] in detail.content
        assert SPEC.clauses[BROKEN].section in detail.content
    rows = [e for e in page.elements if e.tag == "tr" and "data-verdict" in e.attrs]
    assert sorted(r.attrs["data-id"] for r in rows) == sorted(c["id"] for c in failing_run.data["cases"])
    copy = [e.attrs["data-copy"] for e in page.by_class("copy", "button")]
    assert all(c["reproduce"] in copy for c in failing_run.data["cases"])


def test_packets_are_two_columns_decoded_in_wire_order(failing_run: Run) -> None:
    page = Page(failing_run.html.read_text())
    case = _failing(failing_run)[0]
    detail = page.by_id(f"case-{case['id']}")
    start = page.elements.index(detail)
    rows = [e for e in page.elements[start:] if e.tag == "tr" and "prow" in e.classes][: len(case["packets"])]
    assert [("c2s" if "c2s" in r.classes else "s2c") for r in rows] == [p["dir"] for p in case["packets"]]
    order = wire_order(failing_run.data)
    assert order.msb_first  # the embedded server's link carries the TCP link's frames
    for row, packet in zip(rows, case["packets"], strict=True):
        hex_text = wire_bytes(bytes.fromhex(packet["data"]), order).hex(" ")
        assert hex_text in row.content
    # the first packet is the initial RESPONSE, in the server's column; the request after it is decoded
    cells = [e for e in page.elements[page.elements.index(rows[0]) :] if e.tag == "td"][:4]
    assert cells[2].content == "" and "initial RESPONSE" in cells[3].content
    assert "does not decode (no ': ' separating where from the severity)" in detail.content


def test_wire_order_swaps_each_word_on_msb_first_links() -> None:
    tcp = wire_order({"target": "tcp://127.0.0.1:5000"})
    assert wire_bytes(bytes.fromhex("0c0068"), tcp).hex() == "000c0068"
    chaosd = wire_order({"target": "chaosd:///run/chaos.sock"})
    assert wire_bytes(bytes.fromhex("0c0068"), chaosd).hex() == "0c006800"
    capture = wire_order({"target": "captures/errors.mcap"})
    assert not capture.msb_first and "link unknown" in capture.note


def _nasty(data: dict[str, Any]) -> dict[str, Any]:
    nasty = json.loads(json.dumps(data))
    case = next(c for c in nasty["cases"] if c["outcome"] == "fail")
    case["summary"] = case["expected"] = NASTY
    case["violations"][0]["actual"] = case["violations"][0]["message"] = NASTY
    case["notes"] = [NASTY]
    case["reproduce"] = f"manip-conform run --select '{NASTY}'"
    nasty["command"] = NASTY
    nasty["problems"] = [NASTY]
    return nasty


def test_report_text_is_escaped(failing_run: Run) -> None:
    text = render_html(_nasty(failing_run.data))
    page = Page(text)
    assert len([e for e in page.elements if e.tag == "script"]) == 1
    assert not [e for e in page.elements if e.tag == "b"]
    assert "<script>alert" not in text and "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;" in text
    buttons = [e.attrs["data-copy"] for e in page.by_class("copy", "button")]
    assert f"manip-conform run --select '{NASTY}'" in buttons  # the attribute gives back the exact command
    markdown = render_markdown(_nasty(failing_run.data))
    assert "<script>" not in markdown.replace(f"--select '{NASTY}'", "") and "&lt;script&gt;" in markdown


def test_markdown_counts_failures_by_clause_and_one_line_per_reproduce_command(failing_run: Run) -> None:
    lines = failing_run.markdown.read_text().splitlines()
    counts = failing_run.data["counts"]
    assert f"| fail | {counts['fail']} |" in lines and f"| pass | {counts['pass']} |" in lines
    heading = next(i for i, line in enumerate(lines) if line.startswith(f"#### `{BROKEN}`"))
    assert f"{counts['fail']} failing" in lines[heading]
    for case in _failing(failing_run):
        assert lines.count(case["reproduce"]) == 1, case["reproduce"]  # a line of its own, whole
        assert lines.index(case["reproduce"]) > heading
        assert any(line.startswith(f"- **fail** `{case['id']}`") for line in lines)
    fences = [i for i, line in enumerate(lines) if line.startswith("```")]
    assert len(fences) % 2 == 0 and fences


def test_both_documents_say_how_completely_the_run_judged_and_each_clauses_status(failing_run: Run) -> None:
    judged = failing_run.data["completeness"]["text"]
    assert judged.startswith(f"{failing_run.data['completeness']['levels']['MUST']['judged']} of ")
    statuses = {s["clause"]: s["status"] for s in failing_run.data["clause_status"]}
    assert statuses[BROKEN] == "broken"
    lines = failing_run.markdown.read_text().splitlines()
    assert f"**{judged}**" in lines
    assert any(line.startswith(f"| `{BROKEN}` | MUST | broken |") for line in lines)
    page = Page(failing_run.html.read_text())
    assert judged in page.by_id("summary").content
    assert "broken" in page.by_id("clauses").content and "status" in page.by_id("clauses").content


def test_report_renders_a_saved_report_as_the_run_did(failing_run: Run, tmp_path: Path) -> None:
    html, md = tmp_path / "again.html", tmp_path / "again.md"
    result = CliRunner().invoke(
        main, ["report", str(failing_run.json), "--html", str(html), "--markdown", str(md)]
    )
    assert result.exit_code == 0, result.output
    assert html.read_text() == failing_run.html.read_text()
    assert md.read_text() == failing_run.markdown.read_text()


def test_a_report_written_before_the_clause_catalogue_still_renders(failing_run: Run, tmp_path: Path) -> None:
    old = {k: v for k, v in failing_run.data.items() if k != "clauses"}
    path = tmp_path / "old.json"
    path.write_text(json.dumps(old))
    html = tmp_path / "old.html"
    result = CliRunner().invoke(main, ["report", str(path), "--html", str(html)])
    assert result.exit_code == 0, result.output
    case = _failing(failing_run)[0]
    other = next(c for c in case["clauses"] if c != BROKEN) if len(case["clauses"]) > 1 else BROKEN
    assert SPEC.clauses[other].text.replace("'", "&#x27;") in html.read_text()


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("not json", "is not JSON"),
        ('{"tool": "other"}', "not a manip-conform report"),
        ('{"tool": "manip-conform", "schema_version": 99}', "schema_version 99"),
        ('{"tool": "manip-conform", "schema_version": 1}', "lacks the report field(s) verdict"),
    ],
)
def test_report_refuses_what_is_not_a_report(tmp_path: Path, content: str, message: str) -> None:
    path = tmp_path / "r.json"
    path.write_text(content)
    result = CliRunner().invoke(main, ["report", str(path), "--html", str(tmp_path / "r.html")])
    assert result.exit_code == 2 and message in result.output, result.output
    assert not (tmp_path / "r.html").exists()


def test_report_needs_an_output(failing_run: Run) -> None:
    result = CliRunner().invoke(main, ["report", str(failing_run.json)])
    assert result.exit_code == 2 and "give --html FILE, --markdown FILE or both" in result.output


# ------------------------------------------------------------------------------------------- in a browser


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[list[str]]:
    """The headless Chromium command line, with a profile of its own (tests may run side by side)."""
    yield [
        need_program("chromium"),
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--no-first-run",
        "--hide-scrollbars",
    ]


def _dump_dom(browser: list[str], url: str) -> Page:
    done = subprocess.run(
        [*browser, "--dump-dom", url], capture_output=True, text=True, timeout=BROWSER_TIMEOUT, check=False
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return Page(done.stdout)


def test_the_report_in_chromium_after_its_script_ran(failing_run: Run, browser: list[str]) -> None:
    page = _dump_dom(browser, failing_run.html.as_uri())
    assert page.elements[0].tag == "html" and page.elements[0].attrs.get("data-ready") == "yes"
    total = len(failing_run.data["cases"])
    shown = page.by_id("shown")
    assert shown.content == f"{total} of {total} shown"  # written by the script
    cards = {e.attrs["data-verdict"]: e.content for e in page.by_class("card", "button")}
    for outcome, count in failing_run.data["counts"].items():
        assert cards[outcome].startswith(str(count)), (outcome, cards[outcome])
    group = page.by_class("group", "article")[0]
    assert BROKEN in group.content and _failing(failing_run)[0]["id"] in group.content
    rows = [e for e in page.elements if e.tag == "tr" and "prow" in e.classes]
    assert any("non-fatal-error 0202" in r.content for r in rows)


def test_the_filter_of_the_query_string_runs_in_chromium(failing_run: Run, browser: list[str]) -> None:
    page = _dump_dom(browser, failing_run.html.as_uri() + "?verdict=fail")
    fails = failing_run.data["counts"]["fail"]
    assert page.by_id("shown").attrs.get("data-count") == str(fails)
    rows = [e for e in page.elements if e.tag == "tr" and "data-verdict" in e.attrs]
    assert {r.attrs["data-verdict"] for r in rows if "hidden" not in r.attrs} == {"fail"}


def _png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")


def test_a_screenshot_of_the_report(failing_run: Run, browser: list[str], tmp_path: Path) -> None:
    shot = tmp_path / "report-html.png"
    done = subprocess.run(
        [*browser, f"--screenshot={shot}", "--window-size=1280,2000", failing_run.html.as_uri()],
        capture_output=True,
        text=True,
        timeout=BROWSER_TIMEOUT,
        check=False,
    )
    assert done.returncode == 0 and shot.exists(), done.stderr[-2000:]
    assert _png_size(shot) == (1280, 2000)
    assert shot.stat().st_size > 50_000  # a page drawn, not a blank one
    ARTIFACT.parent.mkdir(exist_ok=True)
    shutil.copyfile(shot, ARTIFACT)


FUZZ_FAULT = "length-unchecked"
"""A fault the fuzzer's wrong-length inputs find at once (request.data-length)."""


@pytest.fixture(scope="module")
def fuzz_campaign(tmp_path_factory: pytest.TempPathFactory) -> Run:
    """A short campaign against the reference server with a fault: --json, --html and --markdown, through
    the same writers as run's."""
    where = tmp_path_factory.mktemp("fuzz")
    done = subprocess.run(
        [sys.executable, "-m", "manip.conformance.cli", "fuzz", "-q", "--seed", "1", "--inputs", "100",
         "--class", "manip.wrong-length", "--no-shrink", "--server-fault", FUZZ_FAULT,
         "--json", "fuzz.json", "--html", "fuzz.html", "--markdown", "fuzz.md"],
        capture_output=True, text=True, timeout=120, check=False, cwd=where,
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    data = json.loads((where / "fuzz.json").read_text())
    schema = load_schema()
    _validate(data, schema, schema)
    return Run(where / "fuzz.json", where / "fuzz.html", where / "fuzz.md", data)


def test_a_fuzz_campaign_writes_the_suites_documents(fuzz_campaign: Run) -> None:
    data = fuzz_campaign.data
    assert data["campaign"]["inputs"] == 100 and data["counts"]["fail"] == 1
    (failed,) = _failing(fuzz_campaign)
    assert failed["id"] == "manip.wrong-length" and failed["kind"] == "fuzz"
    markdown = fuzz_campaign.markdown.read_text()
    assert "fuzz campaign: 100 inputs" in markdown and "request.data-length" in markdown
    assert markdown.splitlines()[2].startswith("1 case against the embedded reference server")
    assert failed["reproduce"] in markdown
    page = Page(fuzz_campaign.html.read_text())
    assert "fuzz campaign: 100 inputs" in page.by_class("campaign", "p")[0].content


def test_the_fuzz_report_in_chromium_after_its_script_ran(fuzz_campaign: Run, browser: list[str]) -> None:
    page = _dump_dom(browser, fuzz_campaign.html.as_uri())
    assert page.elements[0].tag == "html" and page.elements[0].attrs.get("data-ready") == "yes"
    total = len(fuzz_campaign.data["cases"])
    assert page.by_id("shown").content == f"{total} of {total} shown"  # written by the script
    group = page.by_class("group", "article")[0]
    assert "request.data-length" in group.content and "manip.wrong-length" in group.content
    assert page.by_class("campaign", "p")


def test_verify_writes_both_documents_of_a_golden_capture(tmp_path: Path) -> None:
    """verify's report: its target is a file, not a link, so the bytes are said to be in memory order."""
    html, md = tmp_path / "v.html", tmp_path / "v.md"
    capture = ROOT / "captures" / "errors.mcap"
    result = CliRunner().invoke(main, ["verify", str(capture), "--html", str(html), "--markdown", str(md)])
    assert result.exit_code == 0, result.output
    page = Page(html.read_text())
    assert "PDP-11 memory order" in page.by_id("details").content
    assert [e for e in page.elements if e.tag == "tr" and "prow" in e.classes]
    summary = md.read_text()
    assert summary.startswith("## manip-conform: conformant (exit 0)") and "seed" not in summary


# ------------------------------------------------------------------------ packet logs centred on the failure

PLANTED_CASE = "server.planted.late-failure"
PLANTED_AT = 262
"""The culprit of the planted failure: a reply after packet 250 of a 300-packet case (to request 131)."""


def _planted_report() -> dict[str, Any]:
    """A report of one case whose 300 packets are 150 requests and replies, failing at packet 262 (the
    reply to request 131, which echoes 132), and one passing case."""
    from manip.conformance.judge.packets import WirePacket
    from manip.conformance.judge.violation import Violation
    from manip.conformance.output.report import report_json
    from manip.conformance.suite.results import CaseResult, RunReport

    packets = []
    for i in range(150):
        number = i + 1
        echoed = number + 1 if 2 * i + 2 == PLANTED_AT else number
        packets.append(WirePacket("c2s", 0o201, number, 0, b"", time=i * 0.01))
        packets.append(WirePacket("s2c", 0o200, 100 + i, number, echoed.to_bytes(2, "little") + bytes(48)))
    culprit = packets[PLANTED_AT - 1]
    failing = CaseResult(
        id=PLANTED_CASE, clauses=("response.echoes-request-number",), level="MUST", kind="scripted",
        hazard="read-only", summary="a long exchange", outcome="fail", seed=1, deadline=10.0, packets=packets,
        violations=[Violation.at(culprit, "response.echoes-request-number",
                                 "the reply echoes the wrong number", expected="request number 131")],
        reproduce=f"manip-conform run --select {PLANTED_CASE} --seed 1",
    )  # fmt: skip
    passing = replace(failing, id="server.planted.short", outcome="pass", violations=[], packets=packets[:6])
    run = RunReport("tcp://127.0.0.1:42085", False, 1, False, {}, "manip-conform run")
    run.results += [failing, passing]
    return report_json(run)


def test_the_packet_log_keeps_the_culprit_of_a_failure_after_packet_250() -> None:
    data = _planted_report()
    schema = load_schema()
    _validate(data, schema, schema)
    case = next(c for c in data["cases"] if c["id"] == PLANTED_CASE)
    assert case["packets_total"] == 300 and len(case["packets"]) <= 200
    assert case["violations"][0]["packet"] == PLANTED_AT
    kept = [p["n"] for p in case["packets"]]
    assert PLANTED_AT in kept and kept[:4] == [1, 2, 3, 4] and kept == sorted(kept)
    page = Page(render_html(data))
    row = page.by_id(f"case-{PLANTED_CASE}-p{PLANTED_AT}")
    assert row.tag == "tr" and "culprit" in row.classes and "request number 132" in row.content
    links = [e for e in page.elements if e.tag == "a" and "culprit-link" in e.classes]
    assert [a.attrs["href"] for a in links] == [f"#case-{PLANTED_CASE}-p{PLANTED_AT}"]
    detail = page.by_id(f"case-{PLANTED_CASE}")
    assert "300 packets; the report keeps" in detail.content
    folds = [e for e in page.elements if e.tag == "tr" and "fold" in e.classes]
    assert folds and all("folded" in f.content for f in folds)
    assert any("not kept in the report" in e.content for e in page.by_class("gap", "tr"))
    # the rows around the culprit are open: none of the folds holds it
    assert not any("request number 132" in f.content for f in folds)


def test_a_culprit_past_the_kept_packets_is_said_not_linked() -> None:
    data = _planted_report()
    case = next(c for c in data["cases"] if c["id"] == PLANTED_CASE)
    kept = {p["n"] for p in case["packets"]}
    case["violations"][0]["packet"] = next(n for n in range(300, 0, -1) if n not in kept)
    page = Page(render_html(data))
    assert not [e for e in page.elements if e.tag == "a" and "culprit-link" in e.classes]
    assert "(not kept in the report)" in page.by_id(f"case-{PLANTED_CASE}").content


def test_a_violation_finds_its_packet_by_its_evidence() -> None:
    from manip.conformance.judge.packets import WirePacket
    from manip.conformance.judge.violation import Violation
    from manip.conformance.output.culprit import culprit_index, kept_indices

    packets = [WirePacket("s2c", 0o200, i, 0, i.to_bytes(2, "little")) for i in range(1, 400)]
    assert culprit_index(packets, Violation("x", data=packets[300].data + b"more")) == 300
    assert culprit_index(packets, Violation("x", kind="deadline")) == len(packets) - 1
    assert culprit_index(packets, Violation("x")) is None
    kept = kept_indices(len(packets), [300, 10], 200)
    assert {0, 1, 2, 3, 288, 300, 306, 10} <= set(kept) and len(kept) == 200


def test_a_failure_group_without_a_clause_lists_its_own_violations() -> None:
    """The replay report's "(no clause: mismatch)" group shows the mismatch it groups, not the case's first
    violation (which cites a clause)."""
    data = _planted_report()
    case = next(c for c in data["cases"] if c["id"] == PLANTED_CASE)
    mismatch = {**case["violations"][0], "clause": None, "kind": "mismatch", "message": "joints[2]: differs"}
    case["violations"].append(mismatch)
    data["by_clause"].append(
        {"clause": None, "kind": "mismatch", "level": "MUST", "section": "", "text": "mismatches",
         "failures": 1, "warnings": 0, "known_failures": 0, "cases": [PLANTED_CASE]}
    )  # fmt: skip
    page = Page(render_html(data))
    group = next(g for g in page.by_class("group", "article") if "(no clause: mismatch)" in g.content)
    assert "joints[2]: differs" in group.content and "echoes the wrong number" not in group.content
    assert r"joints\[2\]: differs" in render_markdown(data).split("(no clause: mismatch)")[1]


def test_an_embedded_run_is_named_by_its_seed_not_its_temporary_socket(failing_run: Run) -> None:
    page = Page(failing_run.html.read_text())
    title = next(e for e in page.elements if e.tag == "title").content
    assert "embedded reference server, seed 7" in title and "unix://" not in title
    assert "unix://" not in page.by_class("facts", "dl")[0].content
    assert "unix://" not in failing_run.markdown.read_text()
    assert all("unix://" not in c["reproduce"] for c in failing_run.data["cases"])


def test_the_culprit_is_highlighted_and_opened_in_chromium(browser: list[str], tmp_path: Path) -> None:
    """The violation's link leads to the culprit's row: opening the page at it opens the case (folded
    rows stay folded), and the row is marked as the culprit."""
    page_file = tmp_path / "planted.html"
    page_file.write_text(render_html(_planted_report()), encoding="utf-8")
    anchor = f"case-{PLANTED_CASE}-p{PLANTED_AT}"
    page = _dump_dom(browser, f"{page_file.as_uri()}#{anchor}")
    row = page.by_id(anchor)
    assert "culprit" in row.classes and row.attrs.get("title") == "the packet of violation 1"
    case = page.by_id(f"case-{PLANTED_CASE}")
    assert "open" in case.attrs, "the case holding the culprit was not opened"
    opened = [e for e in page.elements if e.tag == "details" and "open" in e.attrs]
    assert opened == [case], "a fold of the packet log was opened too"
    assert any(e.tag == "tr" and "fold" in e.classes for e in page.elements)


FULL_PAGE_BYTES = 2_000_000


@pytest.mark.slow
def test_a_full_suite_verify_page_is_small_and_lists_every_check(browser: list[str], tmp_path: Path) -> None:
    """``verify`` of a recording of the whole suite (about 1,600 cases): the page stays under 2 MB, and in
    Chromium its script runs to the end and shows every row.  How soon it is usable depends on the
    machine: ``bench/report_page.py`` measures that, against a plain page of the same size."""
    capture = tmp_path / "run.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "manip.conformance.cli", "run", "-q", "--seed", "11", "--record", "run.mcap"],
        capture_output=True, text=True, timeout=300, check=False, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    html = tmp_path / "verify.html"
    result = CliRunner().invoke(main, ["verify", str(capture), "--html", str(html)])
    assert result.exit_code == 0, result.output
    page_text = html.read_text(encoding="utf-8")
    cases = page_text.count('<tr data-verdict="')
    assert cases > 1000, cases  # the whole suite's checks, every one in the table
    assert len(page_text.encode()) < FULL_PAGE_BYTES, len(page_text.encode())
    page = _dump_dom(browser, html.as_uri())
    assert page.elements[0].attrs.get("data-ready") == "yes"
    assert page.by_id("shown").content == f"{cases} of {cases} shown"


def _with_script(page: Path, script: str, out: Path) -> Path:
    """The page with ``script`` run after its own (a user's actions, played in the browser)."""
    text = page.read_text(encoding="utf-8")
    out.write_text(text.replace("</body>", f"<script>{script}</script></body>"), encoding="utf-8")
    return out


def test_the_filter_state_is_kept_in_the_url(failing_run: Run, browser: list[str], tmp_path: Path) -> None:
    """Typing in the filter, unticking a verdict and choosing a level write the query string, so a
    reload or a shared link shows the same rows."""
    script = """
      const search = document.getElementById("filter");
      search.value = "error-string"; search.dispatchEvent(new Event("input"));
      const pass = document.querySelector('input[name="verdict"][value="pass"]');
      pass.checked = false; pass.dispatchEvent(new Event("change"));
      const level = document.getElementById("level");
      level.value = "MUST"; level.dispatchEvent(new Event("change"));
      document.documentElement.dataset.query = location.search;
    """
    page = _dump_dom(browser, _with_script(failing_run.html, script, tmp_path / "p.html").as_uri())
    query = page.elements[0].attrs["data-query"]
    assert "q=error-string" in query and "level=MUST" in query and "verdict=" in query, query
    assert "pass" not in query.split("verdict=")[1].split("&")[0]


def test_the_copy_fallback_says_when_copying_failed(
    failing_run: Run, browser: list[str], tmp_path: Path
) -> None:
    """Without the clipboard API (an old browser, a page it does not trust) the fallback copies through a
    text area; when the browser refuses that too, the button must not say "Copied"."""
    script = """
      Object.defineProperty(navigator, "clipboard", { value: undefined });
      document.execCommand = () => false;
      const button = document.querySelector("button.copy");
      button.click();
      document.documentElement.dataset.said = button.textContent;
    """
    page = _dump_dom(browser, _with_script(failing_run.html, script, tmp_path / "c.html").as_uri())
    said = page.elements[0].attrs["data-said"]
    assert said.startswith("Copy failed") and said != "Copied", said


def test_a_case_that_uses_an_extension_says_so(failing_run: Run) -> None:
    data = copy.deepcopy(failing_run.data)
    data["cases"][0]["extensions"] = ["request-notifications", "reset-abort"]
    page = render_html(data)
    assert "uses request-notifications, reset-abort (Puma extensions)" in page
    assert page.count("(Puma extensions)") == 1  # only the case that declares one
