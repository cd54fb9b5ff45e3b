"""Generate docs/spec.md (opcode tables, clauses, their coverage, errata) from the spec data files.

Run after editing src/manip/spec/data/*.toml, a case's clauses or a fault switch's declaration;
tests/spec/test_spec.py fails while docs/spec.md is stale.  The coverage table comes from the case
declarations and the fault registries (manip.conformance.fault_proof), and its guide-only column from a
run of the suite against the reference server's guide profile (about 40 s; ``--keep-guide-column`` keeps
the column docs/spec.md has, for a change that cannot move it; the slow test of
tests/conformance/test_guide_only.py holds the column to that run).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tempfile
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path

from manip.conformance.fault_proof import (
    GUIDE_RUN,
    NOT_RUN,
    ClauseProof,
    clause_proofs,
    guide_statuses,
    totals,
)
from manip.conformance.suite.case import all_cases
from manip.spec import SPEC, Layout
from manip.spec.model import Erratum

TARGET = Path(__file__).resolve().parents[1] / "docs" / "spec.md"


def _layout(layout: Layout) -> str:
    if not layout.fields:
        return "—"
    return ", ".join(f"{f.name}: {f.type.name}" for f in layout.fields)


def _reply(kind: str, layout: Layout) -> str:
    return {
        "done": "done",
        "segment": "segment number",
        "multi": "multi-packet text, empty packet ends it",
    }.get(kind, _layout(layout))


ORIGINS = {"guide": "guide", "manip": "**manip**", "chaosnet": "Chaosnet"}
"""How the *whose* column shows a clause's origin."""
CLAUSE_LEGEND = (
    "*Whose*: **guide**, the 1985 guide states it (in manip's words; an erratum may settle a detail of its "
    "reading); **manip**, manip's decision where the guide is silent or ambiguous, its erratum saying why "
    "(where a server written from the guide alone could do otherwise, the clause is a SHOULD or a MAY, or "
    "the suite accepts both readings); **Chaosnet**, the Chaosnet documents and link conventions the "
    "section names.",
    "",
    "*The implementation's choice*: parts of an answer a clause or erratum leaves to the implementation "
    "(`freedom` in the spec data); two conforming servers may differ there, and `manip-conform diff` names "
    "the clause or erratum for each such difference.",
)


def _erratum(erratum: Erratum) -> list[str]:
    """An erratum's section of the docs."""
    clauses = ", ".join(f"`{c}`" for c in erratum.clauses)
    out = [f"### `{erratum.id}`", "", f"*Clauses:* {clauses}", ""]
    out += [f"*Question.* {erratum.question}", "", f"*Decision.* {erratum.decision}", ""]
    if erratum.reason:
        out += [f"*Why.* {erratum.reason}", ""]
    if erratum.parameter:
        out += [f"*Configurable:* `{erratum.parameter}`", ""]
    if erratum.freedom:
        out += [f"*Two conforming servers may differ here*:{_freedom(erratum.freedom)}", ""]
    return out


def _freedom(parts: tuple[str, ...]) -> str:
    """The parts of an answer a clause or erratum leaves to the implementation, as the docs show them."""
    return " (the implementation's choice: " + ", ".join(f"`{f}`" for f in parts) + ")" if parts else ""


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


COVERAGE_LEGEND = (
    "For each live clause: what judges it (*judged by*: the cases that declare it, the judges of a "
    "client's recording as `verify:FAMILY`, and the suite's own checks of every exchange as "
    "`invariant:NAME`); the fault switches that *prove* it; and its status on a *guide-only server*.",
    "",
    "*Proven by*: a fault switch of the reference server (`server:`), the reference client (`client:`) or "
    "the simulated Cougar (`cougar:`) proves a clause when the clause is among those the switch declares "
    "it breaks, and one of the cases the switch declares catch it (`caught_by`) cites the clause: the "
    "switch's fault matrix requires each of those cases to catch it (to fail, or to warn for a SHOULD "
    "clause: `tests/conformance/test_faults.py` for the server, `tests/conformance/puma/test_puma.py` for "
    "its wrist side, `tests/conformance/client/test_faults.py`, and `tests/conformance/cougar/"
    "test_cougar.py`).  A switch is listed under every clause it proves.",
    "",
    f"*Guide-only server*: the clause's status in the report of `manip-conform {' '.join(GUIDE_RUN)}`, "
    "the reference server's guide profile, which serves what the 1985 guide describes and no Puma "
    "extension opcode: **held** (or **broken**), a case came to a verdict on it; **not-judged**, the cases "
    "that cite it need a Puma extension (the report says what would judge each); **not-exercised**, no "
    "check reached it (the clauses of a link the embedded server is not on); "
    f"**{NOT_RUN}**, no case of that run cites it (a clause of the client, the Cougar or the Puma's wrist "
    "side; or one only an invariant checks, which a run's report gives no status).",
    "",
    "The spec data has no notion of a statement the wire cannot show; the totals count INFO clauses "
    "(statements of fact, not requirements) apart, and every other live clause in one of the first three "
    "lines.",
)
GUIDE_CELL = re.compile(r"^\| `(?P<clause>[^`]+)` \| .* \| (?P<status>[a-z/-]+) \|$", re.MULTILINE)
"""A row of the coverage table: its clause and its guide-only column."""


def _coverage(rows: list[ClauseProof]) -> list[str]:
    """The clause coverage section: legend, totals, and one row per clause."""
    t = totals(rows)
    out = ["## Clause coverage", "", *COVERAGE_LEGEND, ""]
    out += [
        f"- judged by a case proven by a fault: {t.proven}",
        f"- judged, but proven by no fault: {t.unproven}",
        f"- not judged by any case: {t.unjudged}",
        f"- INFO (not requirements, not judged as such): {t.info}",
        f"- judged on a guide-only server (of the first three lines): {t.guide_only}",
        "",
        "| clause | level | judged by | proven by | guide-only server |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        judges = ", ".join(f"`{c}`" for c in row.cases) or "—"
        faults = ", ".join(f"`{f}`" for f in row.faults) or "—"
        out.append(f"| `{row.clause}` | {row.level} | {judges} | {faults} | {row.guide_only} |")
    return [*out, ""]


def guide_run() -> dict[str, str]:
    """Each clause's status in the report of the guide-profile run (``GUIDE_RUN``), run for this."""
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "guide.json"
        command = [sys.executable, "-m", "manip.conformance.cli", *GUIDE_RUN, "-q", "--json", str(report)]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise SystemExit(f"the guide-profile run exited {done.returncode}:\n{done.stdout}{done.stderr}")
        return guide_statuses(json.loads(report.read_text(encoding="utf-8"))["clause_status"])


def guide_column(markdown: str) -> dict[str, str]:
    """The guide-only column of the coverage table in ``markdown`` (a docs/spec.md), by clause, without
    the clauses it marks as not in the run."""
    section = markdown[markdown.index("## Clause coverage") : markdown.index("## Errata")]
    rows = {m["clause"]: m["status"] for m in GUIDE_CELL.finditer(section)}
    return {clause: status for clause, status in rows.items() if status != NOT_RUN}


def render(guide: Mapping[str, str]) -> str:
    """docs/spec.md, with ``guide`` the clauses' statuses on a guide-only server (:func:`guide_run`)."""
    out: list[str] = [
        "# The Chaos manipulator protocol and the Cougar word protocol, as manip specifies them",
        "",
        "The source is the *Puma/Cougar Implementor's Guide* (MIT, 1985; called *the 1985 guide* here): "
        "Part I, the Lisp Puma system (the Manip system of the Lisp Machine); Part II, the Puma PDP-11 "
        "system; Part III, the Cougar PDP-11 system (the wrist computer); Appendices A to E: Cougar "
        "hardware, Cougar software, its command protocol (Table 1), Puma hardware, and the Chaos "
        "manipulator protocol. Section references in the tables below (the *1985 guide* column) are to "
        "it.",
        "",
        f"Generated from `src/manip/spec/data/*.toml` (revision `{SPEC.revision}`) by "
        "`tools/gen_spec_docs.py`; do not edit by hand.",
        "",
        "Opcodes are octal. Layouts give the request data and, after the request number, the reply data. "
        "Field types: float = PDP-11 F float (4 bytes); word = unsigned 16-bit; int16 = signed 16-bit; "
        "transform = 12 floats column major N O A P; joints = 6 floats from the base; pose-delta = dX dY dZ "
        "dO dA dT; small = one byte or one word.",
        "",
        "## Request opcodes",
        "",
        "| opcode | name | hazard | request data | reply | 1985 guide |",
        "|---|---|---|---|---|---|",
    ]
    for op in SPEC.requests.values():
        name = f"{op.name} *(manip extension)*" if op.extension else op.name
        within = "" if op.answer_within is None else f" (within {op.answer_within:g} s)"
        out.append(
            f"| {op.opcode:o} | {name} | {op.hazard} | {_layout(op.request)} | "
            f"{_reply(op.response.form, op.response.data)}{within} | {_cell(op.section)} |"
        )
    out += [
        "",
        "## Server opcodes",
        "",
        "| opcode | name | Manip response code | body |",
        "|---|---|---|---|",
    ]
    for s in SPEC.server_opcodes.values():
        code = f"{s.generic_code} ({s.generic_name})" if s.generic_name else str(s.generic_code)
        out.append(f"| {s.opcode:o} | {s.name} | {code} | {s.body} |")
    out += ["", "## Severities", "", "| letter | meaning | server opcodes |", "|---|---|---|"]
    for sev in SPEC.severities.values():
        ops = ", ".join(f"{o:o}" for o in sev.server_opcodes)
        out.append(f"| {sev.letter} | {sev.meaning} | {ops} |")
    out += [
        "",
        "## Error codes",
        "",
        "Exactly the codes the reference server can send, with the severities it sends them with (a test",
        "scans the server's error paths and holds this table to them).",
        "",
        "| code | meaning | severities | arguments | defined by |",
        "|---|---|---|---|---|",
    ]
    for e in SPEC.error_codes.values():
        severities = ", ".join(e.severities) or "—"
        out.append(f"| {e.code} | {e.meaning} | {severities} | {_cell(e.args or '—')} | {e.origin} |")
    out += [
        "",
        "## Asynchronous conditions (0203)",
        "",
        "| code | name | word 2 | word 3 |",
        "|---|---|---|---|",
    ]
    for a in SPEC.async_codes.values():
        out.append(f"| {a.code} | {a.name} | {a.word2} | {a.word3} |")
    out += [
        "",
        "## Cougar commands (Table 1)",
        "",
        "| code | name | label | data words | response | remarks |",
        "|---|---|---|---|---|---|",
    ]
    for c in SPEC.cougar_commands.values():
        out.append(
            f"| {c.code} | {c.name} | {c.label} | {c.data_words} | {_cell(c.response or '—')} | {c.remarks} |"
        )
    out += ["", "## Cougar responses", "", "| code | name | data words | remarks |", "|---|---|---|---|"]
    for c in SPEC.cougar_responses.values():
        words = "count + words" if c.data_words is None else str(c.data_words)
        out.append(f"| {c.code} | {c.name} | {words} | {c.remarks} |")

    out += ["", "## Clauses", "", *CLAUSE_LEGEND, ""]
    groups: dict[str, list[str]] = defaultdict(list)
    for clause in SPEC.clauses.values():
        if clause.retired:
            continue
        errata = f" (erratum `{clause.errata}`)" if clause.errata else ""
        errata += _freedom(clause.freedom)
        if clause.judged_from == "recording":
            errata += " (judged from a recording, `verify --judge client`, and live by the choice operations)"
        groups[clause.id.split(".")[0]].append(
            f"| `{clause.id}` | {clause.level} | {clause.party} | {ORIGINS[clause.origin]} | "
            f"{_cell(clause.text)}{errata} | {_cell(clause.section)} |"
        )
    for group, rows in groups.items():
        out += [
            f"### {group}",
            "",
            "| id | level | binds | whose | requirement | 1985 guide |",
            "|---|---|---|---|---|---|",
            *rows,
            "",
        ]

    out += _coverage(clause_proofs(all_cases(), guide))
    out += ["## Errata", ""]
    for erratum in SPEC.errata.values():
        out += _erratum(erratum)
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str]) -> int:
    if argv not in ([], ["--keep-guide-column"]):
        print("usage: gen_spec_docs.py [--keep-guide-column]", file=sys.stderr)
        return 2
    guide = guide_column(TARGET.read_text(encoding="utf-8")) if argv else guide_run()
    TARGET.parent.mkdir(exist_ok=True)
    TARGET.write_text(render(guide))
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
