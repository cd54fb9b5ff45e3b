"""The error-code table of the spec data is exactly what the reference server can send.

The server's error strings are all built in a few places: ``ErrorMessage(where, severity, code, ...)``
calls with literal severity and code, and the arm's refusals (``Refused("CODE", ...)``), which
``reference_server.errors.refusal_error`` turns into strings (severity from its table, else C).  This
test reads those sources, collects every (severity, code) the server can emit and holds the table to
it, both ways.  A call whose severity or code is not a literal must be one of the few known to take it
from a table; any other is a path this test cannot read, and fails it.  Fault switches (faults.py) send
deliberately wrong strings and are left out.
"""

from __future__ import annotations

import ast

from manip.reference_server import errors
from manip.spec import SPEC
from tests.support.paths import ROOT

SRC = ROOT / "src" / "manip"
SCANNED = sorted(
    [*(SRC / "reference_server").glob("*.py"), *(SRC / "arm").glob("*.py")],
)
SKIPPED = {"faults.py"}
# Functions whose ErrorMessage takes its severity and code from a table read below.
TABLE_DRIVEN = {("errors.py", "refusal_error")}


def _emitted() -> tuple[set[tuple[str, str]], list[str]]:
    pairs: set[tuple[str, str]] = set()
    refused: set[str] = set()
    unreadable: list[str] = []
    for path in SCANNED:
        if path.name in SKIPPED:
            continue
        tree = ast.parse(path.read_text(), str(path))
        for func in [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]:
            for call in [n for n in ast.walk(func) if isinstance(n, ast.Call)]:
                name = call.func.id if isinstance(call.func, ast.Name) else getattr(call.func, "attr", "")
                args = call.args
                if name == "ErrorMessage":
                    literal = len(args) >= 3 and all(
                        isinstance(a, ast.Constant) and isinstance(a.value, str) for a in args[1:3]
                    )
                    if literal:
                        pairs.add((args[1].value, args[2].value))  # type: ignore[attr-defined]
                    elif (path.name, func.name) not in TABLE_DRIVEN:
                        unreadable.append(f"{path.name}:{call.lineno} in {func.name}")
                elif name == "Refused":
                    if args and isinstance(args[0], ast.Constant) and isinstance(args[0].value, str):
                        refused.add(args[0].value)
                    else:
                        unreadable.append(f"{path.name}:{call.lineno} Refused without a literal code")
    table = errors._REFUSALS
    pairs |= {(table[code][0], code) if code in table else ("C", code) for code in refused}
    return pairs, unreadable


def test_every_error_path_of_the_server_is_readable() -> None:
    _, unreadable = _emitted()
    assert not unreadable, f"error strings this test cannot read: {unreadable}"


def test_the_table_holds_exactly_the_codes_the_server_can_send() -> None:
    pairs, _ = _emitted()
    emitted = {code for _, code in pairs}
    assert len(emitted) >= 15  # the scan found the server's error paths
    assert emitted - set(SPEC.error_codes) == set(), "codes the server sends but the table lacks"
    assert set(SPEC.error_codes) - emitted == set(), "codes in the table that nothing sends"


def test_the_table_gives_each_code_the_severities_it_is_sent_with() -> None:
    pairs, _ = _emitted()
    table = {(severity, e.code) for e in SPEC.error_codes.values() for severity in e.severities}
    assert pairs == table
    assert all(severity in SPEC.severities for severity, _ in pairs)


def test_the_guide_codes_are_the_1985_guide_s() -> None:
    # NAP, AWA, JOR and TOR are the codes the 1985 guide defines (E.2); NZI is its example.
    assert {c for c, e in SPEC.error_codes.items() if e.origin == "guide"} == {
        "NAP",
        "AWA",
        "JOR",
        "TOR",
        "NZI",
    }
