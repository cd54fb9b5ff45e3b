"""The diff's verdict and reports from classified differences (sans-I/O): a violation fails, a gap fails
unless allowed, a difference both allowed never does; the JSON follows its schema."""

from __future__ import annotations

from pathlib import Path

from manip.conformance.diff.classify import Finding, FindingClass
from manip.conformance.diff.driver import StreamResult
from manip.conformance.diff.pairing import Difference, SideEvent
from manip.conformance.diff.report import DiffReport, load_schema, write_html, write_junit, write_markdown
from manip.conformance.diff.streams import Stream
from tests.support.json_schema import validate


def _report(cls: FindingClass, *, allow: bool = False) -> DiffReport:
    a, b = SideEvent("packet", 0o200, b"\x01\x00\x01"), SideEvent("packet", 0o200, b"\x01\x00\x02")
    finding = Finding(cls, "stream 0", Difference(3, 0, ("data",), a, b), ("here.transform",), section="E.1")
    result = StreamResult(Stream(0, ()), [finding])
    report = DiffReport("A", "B", 9, 8, "manip-conform diff embedded embedded", ("manip-conform", "diff"))
    report.allow_unexplained = allow
    report.results.append(result)
    return report


def test_what_fails_the_diff() -> None:
    assert _report("violation").exit_code == 1
    assert _report("violation", allow=True).exit_code == 1
    assert _report("unexplained").exit_code == 1
    assert _report("unexplained", allow=True).exit_code == 0
    assert _report("allowed").exit_code == 0
    unstable = DiffReport("A", "B", 9, 8, "", ())
    unstable.results.append(StreamResult(Stream(1, ()), unstable=True, unstable_detail="came and went"))
    assert unstable.exit_code == 0 and unstable.to_json()["unstable"][0]["stream"] == "stream 1"


def test_the_reports(tmp_path: Path) -> None:
    report = _report("unexplained")
    validate(report.to_json(), load_schema())
    report.results[0].runaway.append("B: the side did not finish the stream within 30 s")
    validate(report.to_json(), load_schema())
    assert report.to_json()["runaways"][0]["stream"] == "stream 0"
    assert report.to_json()["findings"][0]["reproduce"].endswith("--seed 9 --stream 0 --length 8")
    write_markdown(report, tmp_path / "d.md")
    write_html(report, tmp_path / "d.html")
    write_junit(report, tmp_path / "d.xml")
    assert "(c) unexplained" in (tmp_path / "d.md").read_text()
    assert "<mark>02</mark>" in (tmp_path / "d.html").read_text()
    assert 'failures="1"' in (tmp_path / "d.xml").read_text()
    allowed = _report("unexplained", allow=True)
    write_junit(allowed, tmp_path / "a.xml")
    assert 'failures="0"' in (tmp_path / "a.xml").read_text()


def test_what_a_check_could_not_judge_is_reported_and_fails_nothing(tmp_path: Path) -> None:
    report = _report("allowed")
    why = "side B: motion.servo-period: two samples in a row typically spanned 40.0 ms"
    report.results[0].unjudged.append(why)
    validate(report.to_json(), load_schema())
    assert report.to_json()["not_judged"] == [{"stream": "stream 0", "detail": why}]
    assert report.exit_code == 0
    write_markdown(report, tmp_path / "d.md")
    assert why in (tmp_path / "d.md").read_text()
