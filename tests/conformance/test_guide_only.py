"""The suite against a server written from the 1985 guide alone: the reference server's guide profile
(``manip-server --profile guide``: no Puma extension opcodes, lengths in inches, the guide's 6-byte
asynchronous responses).  Its verdict is complete and honest: the cases that use an extension judge the
same clauses with the guide's own requests or end not-judged saying why, only the cases of other links
skip, and the run says which length unit it assumed and which MUST clauses it could not judge."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from manip.arm.units import unit_of
from manip.conformance.cli import main
from manip.conformance.fault_proof import GUIDE_RUN, guide_statuses
from manip.conformance.suite.results import ExitCode
from manip.spec import SPEC
from tests.support.paths import ROOT
from tests.support.tools import load_tool

LINK_SPECIFIC = frozenset(
    {"server.link.chaosd-frames", "server.link.chudp-frames", "server.ncp.los-oversize"}
)
"""The cases of a link the embedded server is not on: the only skips a guide-only server may get."""
CARTESIAN = ("server.motion.straight-line", "server.motion.incremental-reference")
"""The cases whose moves are sized in millimetres unless --length-unit says otherwise."""
GUIDE_ROUTES = ("server.speed.scales", "server.motion.queued-segments", "server.motion.abort-drops-queue")
"""Cases whose first route is request notifications, judged by polling the joint angles instead."""


def _cartesian(unit: str, tmp_path: Path) -> dict[str, tuple[str, str]]:
    """The Cartesian cases against the embedded guide profile (in virtual time), sized in ``unit``."""
    report_path = tmp_path / f"{unit}.json"
    select = [arg for case_id in CARTESIAN for arg in ("--select", case_id)]
    args = ["run", "--server-profile", "guide", "--length-unit", unit, "--seed", "3", "-q", *select]
    result = CliRunner().invoke(main, [*args, "--json", str(report_path)])
    assert result.exit_code == ExitCode.CONFORMANT, result.output
    return {c["id"]: (c["outcome"], c["reason"]) for c in json.loads(report_path.read_text())["cases"]}


def test_a_server_in_inches_is_judged_with_length_unit_inch(tmp_path: Path) -> None:
    """Sized in millimetres, the straight-line and incremental moves are out of an inch server's reach:
    not judged, saying the unit may be why; sized in inches they are judged and pass."""
    in_mm = _cartesian("mm", tmp_path)
    assert {outcome for outcome, _ in in_mm.values()} == {"not-judged"}, in_mm
    assert all("--length-unit" in reason and "sized in mm" in reason for _, reason in in_mm.values())
    assert _cartesian("inch", tmp_path) == dict.fromkeys(CARTESIAN, ("pass", ""))


@pytest.mark.slow
def test_the_guide_profile_gets_a_complete_and_honest_verdict(tmp_path: Path) -> None:
    """Against the guide profile with its world (the embedded server's), run exits 0, skips nothing but the
    cases of other links, and names every MUST clause it could not judge, in its output and its report;
    docs/spec.md's coverage table gives each clause the status this run gives it."""
    report_path = tmp_path / "guide.json"
    args = [*GUIDE_RUN, "-q"]
    result = CliRunner().invoke(main, [*args, "--json", str(report_path)])
    assert result.exit_code == ExitCode.CONFORMANT, result.output
    assert "lengths taken in inch" in result.output
    data = json.loads(report_path.read_text())
    assert data["length_unit"] == "inch"
    outcomes = {c["id"]: c["outcome"] for c in data["cases"]}
    skipped = {case_id for case_id, outcome in outcomes.items() if outcome == "skip"}
    assert skipped <= LINK_SPECIFIC, skipped
    for case_id in GUIDE_ROUTES:
        assert outcomes[case_id] == "pass", case_id  # judged through the guide's own requests
    for case_id in CARTESIAN:
        assert outcomes[case_id] == "pass", case_id  # sized in inches
    # judged: reached by a check of a case that came to a verdict (a clause a passing case cites but never
    # reached, such as the asynchronous layout without notifications, is not judged by it)
    judged = {cl for c in data["cases"] if c["outcome"] in ("pass", "fail", "warn") for cl in c["reached"]}
    unjudged = {
        cl
        for c in data["cases"]
        if c["outcome"] == "not-judged"
        for cl in c["clauses"]
        if SPEC.clauses[cl].level == "MUST" and cl not in judged
    }
    assert unjudged, "a guide-only server leaves the wrist's clauses unjudged"
    assert set(data["not_judged"]) == unjudged
    assert all(clause in result.output for clause in unjudged), result.output
    for case in data["cases"]:
        if case["outcome"] == "not-judged":
            assert case["reason"], case["id"]  # each says what would judge it
    column = _generator().guide_column((ROOT / "docs" / "spec.md").read_text(encoding="utf-8"))
    assert column == guide_statuses(data["clause_status"]), "run: python tools/gen_spec_docs.py"


def _generator():  # type: ignore[no-untyped-def]
    return load_tool("gen_spec_docs")


@pytest.mark.parametrize(
    ("height", "unit"),
    [(864.87, "mm"), (86.49, "cm"), (34.05, "inch"), (865.0 * 3, None), (0.0, None), (-34.05, None)],
)
def test_a_unit_is_learned_only_from_a_height_that_fits_one(height: float, unit: str | None) -> None:
    assert unit_of(height, 864.87) == unit


@pytest.mark.parametrize(("profile", "unit"), [("guide", "inch"), ("manip", "mm")])
def test_length_unit_auto_learns_the_unit_from_the_ready_pose(
    tmp_path: Path, profile: str, unit: str
) -> None:
    report_path = tmp_path / "auto.json"
    select = [arg for case_id in CARTESIAN for arg in ("--select", case_id)]
    args = ["run", "--server-profile", profile, "--length-unit", "auto", "--seed", "2", *select]
    result = CliRunner().invoke(main, [*args, "--json", str(report_path)])
    assert result.exit_code == ExitCode.CONFORMANT, result.output
    assert f"lengths (--length-unit auto): learned {unit}" in result.output
    data = json.loads(report_path.read_text())
    assert data["length_unit"] == unit and data["counts"]["pass"] == len(CARTESIAN)
    assert all("--length-unit auto" in case["reproduce"] for case in data["cases"])
