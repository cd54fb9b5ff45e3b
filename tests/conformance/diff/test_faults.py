"""The diff against the fault registry: every protocol fault of the reference server, run as side B
against a clean side A, shows as a class (a) difference naming one of the clauses the fault matrix
names for it (side B the violator), or is on :data:`NOT_SHOWN` with the reason the diff cannot show it.

Each fault runs the scenarios (the directed cases' request sequences, with the conditions of the world
they need arranged on both sides) and two generated streams.  The clean side's observations are the
same for every fault, so each worker observes them once (:func:`clean_once`).  Everything runs in
virtual time.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from manip.conformance.diff import driver
from manip.conformance.diff.classify import Finding
from manip.conformance.diff.driver import DiffConfig, run_diff
from manip.conformance.diff.scenarios import scenarios
from manip.conformance.diff.sides import Observation, Side, observe
from manip.conformance.diff.streams import Stream, make_streams
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.fuzz.session import Allowance
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.faults import FAULTS, WRIST_SIDE, Fault

pytestmark = [pytest.mark.slow, pytest.mark.timeout(600)]

SEED = 7
CLEAN = Side("A", "clean", config=ServerConfig())
PROTOCOL_FAULTS = sorted(
    (f for f, info in FAULTS.items() if info.kind == "protocol" and f not in WRIST_SIDE),
    key=lambda f: f.value,
)
"""The server's protocol faults (the wrist side's are the Puma cases' to catch: they need the suite
playing Cougar)."""

NOT_SHOWN: dict[Fault, str] = {}
"""Faults the diff does not show as a violation of one of their clauses, and why (the directed case
that catches each is the fault matrix's, tests/conformance/test_faults.py)."""

_CLEAN_SEEN: dict[tuple[str, tuple[int, ...]], Observation] = {}


def streams() -> list[Stream]:
    return [*scenarios(), *make_streams(SEED, 2, 8, GenOptions())]


@pytest.fixture(autouse=True)
def clean_once(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The clean side observed once per stream in this worker (it is the same for every fault)."""

    def observed(side: Side, stream: Stream, allowance: Allowance, seed: int) -> Observation:
        if side.config != CLEAN.config:
            return observe(side, stream, allowance, seed)
        key = (stream.label, stream.input_numbers)
        if key not in _CLEAN_SEEN:
            _CLEAN_SEEN[key] = observe(side, stream, allowance, seed)
        return _CLEAN_SEEN[key]

    monkeypatch.setattr(driver, "observe", observed)
    yield


def findings(fault: Fault) -> list[Finding]:
    faulty = Side("B", fault.value, config=ServerConfig(faults=FaultSet.parse([fault.value])))
    results = run_diff(CLEAN, faulty, streams(), DiffConfig(SEED, shrink=False))
    return [f for r in results for f in r.findings]


@pytest.mark.parametrize("fault", PROTOCOL_FAULTS, ids=lambda f: f.value)
def test_a_protocol_fault_is_a_violation_of_its_clause(fault: Fault) -> None:
    found = findings(fault)
    assert not [f for f in found if f.cls == "violation" and f.violator in ("A", "both")], "the clean side"
    named = {n for f in found if f.cls == "violation" and f.violator == "B" for n in f.names}
    wanted = set(FAULTS[fault].clauses)
    shown = sorted({(f.cls, f.names) for f in found})
    print(f"{fault.value}: wanted {sorted(wanted)}; named {sorted(named)}; {len(found)} difference(s)")
    if fault in NOT_SHOWN:
        assert not named & wanted, f"{fault.value} now shows: take it off NOT_SHOWN"
        return
    assert named & wanted, shown


def test_the_allow_list_names_protocol_faults_with_reasons() -> None:
    assert set(NOT_SHOWN) <= set(PROTOCOL_FAULTS)
    assert all(len(why) > 40 for why in NOT_SHOWN.values())
