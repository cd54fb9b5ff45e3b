"""The coverage table of docs/spec.md: its facts come from the case declarations and the fault registries.

The table is read back from the generated document and checked against facts gathered here another way
(fault by fault rather than clause by clause), so a fault, case or column typed into the table by hand,
or a rule of :mod:`manip.conformance.fault_proof` that drifts from its stated meaning, fails.
"""

from __future__ import annotations

import re
from collections import defaultdict

from manip.conformance.fault_proof import REGISTRIES, clause_proofs, proves, totals
from manip.conformance.suite.case import all_cases
from manip.cougar.faults import CougarFault
from manip.reference_client.faults import ClientFault
from manip.reference_server.faults import Fault
from manip.spec import SPEC
from manip.spec.faults import FaultSwitch, defect
from tests.support.paths import ROOT

ROW = re.compile(
    r"^\| `(?P<clause>[^`]+)` \| (?P<level>\w+) \| (?P<judges>.*) \| (?P<faults>.*) \| "
    r"(?P<guide>held|broken|not-judged|not-exercised|n/a) \|$"
)


def table() -> dict[str, dict[str, str]]:
    """The coverage table's rows in docs/spec.md, by clause."""
    text = (ROOT / "docs" / "spec.md").read_text(encoding="utf-8")
    section = text[text.index("## Clause coverage") : text.index("## Errata")]
    return {m["clause"]: m.groupdict() for line in section.splitlines() if (m := ROW.match(line))}


def names(cell: str) -> set[str]:
    return set(re.findall(r"`([^`]+)`", cell))


def test_the_proving_faults_are_the_registries() -> None:
    """Each switch of each registry is listed under exactly the clauses it declares it breaks that one of
    the cases it declares catch it cites; no other switch is listed."""
    cases = {c.id: c for c in all_cases()}
    expected: dict[str, set[str]] = defaultdict(set)
    for implementation, registry in (("server", Fault), ("client", ClientFault), ("cougar", CougarFault)):
        for fault in registry:
            cited = {clause for case_id in fault.caught_by for clause in cases[case_id].clauses}
            for clause in set(fault.clauses) & cited:
                expected[clause].add(f"{implementation}:{fault.value}")
    rows = table()
    assert set(rows) == {c.id for c in SPEC.clauses.values() if not c.retired}
    assert {clause: names(row["faults"]) for clause, row in rows.items() if names(row["faults"])} == expected
    assert sum(len(v) for v in expected.values()) >= len(Fault) + len(CougarFault)


def test_the_judges_are_the_case_declarations_and_the_guide_run_the_server_cases() -> None:
    """A clause's judges are the cases declaring it (with the recording judges and invariants); the
    guide-only column gives a status to exactly the clauses a server case cites (a run's report gives
    none to a clause only an invariant judges; the values are held to a guide-profile run by
    tests/conformance/test_guide_only.py)."""
    declared: dict[str, set[str]] = defaultdict(set)
    server: set[str] = set()
    for case in all_cases():
        for clause in case.clauses:
            declared[clause].add(case.id)
            if case.target == "server":
                server.add(clause)
    for clause, row in table().items():
        judges = names(row["judges"])
        assert {j for j in judges if ":" not in j} == declared[clause], clause
        assert (row["guide"] != "n/a") == (clause in server), (clause, row["guide"])
        assert row["level"] == SPEC.clauses[clause].level


def test_the_totals_count_the_rows() -> None:
    rows = table()
    rules = {c: r for c, r in rows.items() if r["level"] != "INFO"}
    judged = {c for c, r in rules.items() if names(r["judges"])}
    proven = {c for c in judged if names(rules[c]["faults"])}
    text = (ROOT / "docs" / "spec.md").read_text(encoding="utf-8")
    assert f"- judged by a case proven by a fault: {len(proven)}\n" in text
    assert f"- judged, but proven by no fault: {len(judged) - len(proven)}\n" in text
    assert f"- not judged by any case: {len(rules) - len(judged)}\n" in text
    assert f"- INFO (not requirements, not judged as such): {len(rows) - len(rules)}\n" in text
    guide = sum(r["guide"] in ("held", "broken") for r in rules.values())
    assert f"- judged on a guide-only server (of the first three lines): {guide}\n" in text
    assert totals(clause_proofs(all_cases(), {})).proven == len(proven)


class _Probe(FaultSwitch):
    """A registry of two switches breaking the same clause, one caught by a case citing it, one not."""

    CITED = defect("cited", "x.", "connect.initial-response", caught_by=("server.connect.initial-response",))
    NOT_CITED = defect(
        "not-cited", "x.", "connect.initial-response", caught_by=("server.describe.pipelined",)
    )


def test_a_fault_proves_only_what_a_case_it_names_cites() -> None:
    cases = {c.id: c for c in all_cases()}
    assert proves(_Probe.CITED, "connect.initial-response", cases)
    assert not proves(_Probe.NOT_CITED, "connect.initial-response", cases)
    assert not proves(_Probe.CITED, "request.one-reply", cases)  # not a clause it declares
    assert set(REGISTRIES.values()) == {Fault, ClientFault, CougarFault}
