"""docs/guide-audit.md, the statement-by-statement audit of the 1985 guide, stays true: every clause and
erratum it names exists, each row's status agrees with the spec data and the cases, and its totals are
its rows'."""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass

from manip.conformance.suite.case import all_cases
from manip.spec import SPEC
from tests.support.paths import ROOT

AUDIT = ROOT / "docs" / "guide-audit.md"
STATUSES = ("judged", "in part", "captured", "not captured", "not observable")
ROW = re.compile(r"^\| ([A-Z][A-Z0-9]*-\d+) \| (.+) \| ([a-z ]+) \| (.*) \|$")
TOTAL = re.compile(r"^\| (judged|in part|captured|not captured|not observable|all) \| (\d+) \|$")
NAMED = re.compile(r"`([a-z0-9][a-z0-9.*-]*)`")


@dataclass(frozen=True)
class Row:
    number: str
    statement: str
    status: str
    why: str

    @property
    def clauses(self) -> list[str]:
        """The clause ids the last column names (dotted; an erratum id has no dot)."""
        return [name for name in NAMED.findall(self.why) if "." in name]

    @property
    def errata(self) -> list[str]:
        return [name for name in NAMED.findall(self.why) if "." not in name]


def rows(text: str) -> list[Row]:
    return [Row(*m.groups()) for line in text.splitlines() if (m := ROW.match(line))]


def totals(text: str) -> dict[str, int]:
    return {m[1]: int(m[2]) for line in text.splitlines() if (m := TOTAL.match(line))}


def problems(text: str) -> list[str]:
    """What in the audit disagrees with the spec data, the cases or itself."""
    found: list[str] = []
    cited = {clause for case in all_cases() for clause in case.clauses}
    table = rows(text)
    numbers = Counter(r.number for r in table)
    found += [f"{n} is used for {k} rows" for n, k in numbers.items() if k > 1]
    for row in table:
        where = f"{row.number} ({row.status})"
        if row.status not in STATUSES:
            found.append(f"{where}: unknown status")
        unknown = [c for c in row.clauses if c not in SPEC.clauses or SPEC.clauses[c].retired]
        found += [f"{where}: no clause {c} in the spec data (or retired)" for c in unknown]
        found += [f"{where}: no erratum {e}" for e in row.errata if e not in SPEC.errata]
        judged = [c for c in row.clauses if c in cited]
        if row.status in ("judged", "in part") and not judged:
            found.append(f"{where}: no case declares any of {row.clauses}")
        if row.status == "captured" and (not row.clauses or judged):
            found.append(f"{where}: names {row.clauses}, of which a case declares {judged}")
    counted = Counter(r.status for r in table)
    expected = {**{s: counted.get(s, 0) for s in STATUSES}, "all": len(table)}
    if totals(text) != expected:
        found.append(f"the totals say {totals(text)}; the rows count {expected}")
    return found


def test_the_audit_agrees_with_the_spec_data_and_the_cases() -> None:
    text = AUDIT.read_text(encoding="utf-8")
    assert len(rows(text)) > 200
    assert not problems(text), "\n".join(problems(text))


def test_every_statement_not_captured_is_listed_with_what_would_judge_it() -> None:
    text = AUDIT.read_text(encoding="utf-8")
    listed = text.split("## Not captured, and what would judge it", 1)[1].split("\n## ", 1)[0]
    missing = [r.number for r in rows(text) if r.status == "not captured" and f"**{r.number}," not in listed]
    assert not missing, missing


def test_the_checks_find_a_wrong_row() -> None:
    text = AUDIT.read_text(encoding="utf-8")
    first = rows(text)[0]
    line = f"| {first.number} | {first.statement} | {first.status} | {first.why} |"
    for bad, expected in (
        (f"| {first.number} | x | judged | `no.such-clause` |", "no clause no.such-clause"),
        (f"| {first.number} | x | captured | `request.one-reply` |", "of which a case declares"),
        (f"| {first.number} | x | judged | `move.joint-interpolated` |", "no case declares"),
        (f"| {first.number} | x | judged | `units`, erratum `no-such-erratum` |", "no erratum"),
    ):
        found = problems(text.replace(line, bad))
        assert any(expected in p for p in found), (bad, found)
    assert any("the totals say" in p for p in problems(text.replace(line, "")))
