"""The spec data: loads, is self-consistent, and the generated constants are current."""

from __future__ import annotations

import re

import pytest

from manip.spec import SPEC, SpecError, load_spec
from manip.spec import loader as spec_loader
from tests.support.paths import ROOT
from tests.support.tools import load_tool

SLUG = re.compile(r"^[a-z0-9]+(?:[.-][a-z0-9]+)*$")


def _gen_module():  # type: ignore[no-untyped-def]
    return load_tool("gen_constants")


def test_generated_constants_are_current() -> None:
    generated = _gen_module().render()
    on_disk = (ROOT / "src" / "manip" / "spec" / "constants.py").read_text()
    assert on_disk == generated, "run: python tools/gen_constants.py"


def test_clause_ids_are_stable_slugs() -> None:
    for cid, clause in SPEC.clauses.items():
        assert SLUG.match(cid), cid
        assert not re.search(r"\d+\.\d+", cid), f"{cid} looks like a section number"
        assert clause.level in ("MUST", "SHOULD", "MAY", "INFO")
        assert clause.text.strip() and clause.section.strip()


def test_request_table_covers_the_guide() -> None:
    # E.1 defines 0200-0221; every one must be in the table, none twice, each with a hazard class.
    assert set(range(0o200, 0o222)) <= set(SPEC.requests)
    for op in SPEC.requests.values():
        assert op.hazard in ("read-only", "config", "motion", "power")
        assert (op.opcode >= 0o240) == op.extension, op.name


def test_motion_replies_carry_segments() -> None:
    for opcode in (0o204, 0o205, 0o211, 0o212, 0o214, 0o215):
        assert SPEC.requests[opcode].response.form == "segment"


def test_layout_sizes() -> None:
    assert SPEC.request("move").request.fixed_size == 48
    assert SPEC.request("solve-forwards").request.fixed_size == 72
    assert SPEC.request("here").response.data.fixed_size == 48
    assert SPEC.request("set-damping").request.fixed_size == 144


def test_cougar_table_matches_table_1() -> None:
    words = {c.name: c.data_words for c in SPEC.cougar_commands.values()}
    assert words["NPR"] == 36  # 3 x 6 floats
    assert words["NB"] == 72  # 36 floats
    assert words["GUARDS"] == 15  # word + 6 floats + float
    assert words["NEWWC"] == 8
    assert words["DPST"] == 2 and words["EXMN"] == 2 and words["VERS"] == 1
    assert words["WGOV"] == 8 and words["RRAW"] == 0
    assert sorted(SPEC.cougar_commands) == list(range(20))
    assert sorted(SPEC.cougar_responses) == [1, 2, 4, 5, 6, 7, 8, 9]


def test_severities_and_codes() -> None:
    assert set(SPEC.severities) == {"F", "E", "C", "W", "BF", "BE"}
    assert {"NAP", "AWA", "JOR", "TOR", "NZI"} <= set(SPEC.error_codes)
    for code in SPEC.error_codes:
        assert re.fullmatch("[A-Z]{3}", code)
    assert {s.generic_code for s in SPEC.server_opcodes.values()} >= {0, 1, 2, 4}


def test_every_erratum_is_cited_by_its_clauses() -> None:
    for erratum in SPEC.errata.values():
        assert erratum.clauses
        for cid in erratum.clauses:
            assert cid in SPEC.clauses


def test_every_erratum_gives_its_reason() -> None:
    """An erratum is a decision where the 1985 guide is silent or ambiguous; without its reason a reader
    cannot tell whether a peer that decided otherwise is wrong."""
    bare = [e.id for e in SPEC.errata.values() if not (e.reason or "").strip()]
    assert not bare, f"errata with no reason: {bare}"


def test_inconsistent_data_is_rejected(monkeypatch: pytest.MonkeyPatch) -> None:
    real = spec_loader._read

    def broken(name: str) -> dict[str, object]:
        data = real(name)
        if name == "clauses.toml":
            data["clause"] = [*data["clause"], dict(data["clause"][0])]  # type: ignore[index]
        return data

    monkeypatch.setattr(spec_loader, "_read", broken)
    load_spec.cache_clear()
    try:
        with pytest.raises(SpecError, match="defined twice"):
            load_spec()
    finally:
        load_spec.cache_clear()
        monkeypatch.undo()
        load_spec()


def test_generated_spec_docs_are_current() -> None:
    module = load_tool("gen_spec_docs")
    on_disk = (ROOT / "docs" / "spec.md").read_text()
    # the guide-only column comes from a whole run, which tests/conformance/test_guide_only.py checks
    assert on_disk == module.render(module.guide_column(on_disk)), "run: python tools/gen_spec_docs.py"


def test_one_chaos_opcode_name_for_every_opcode() -> None:
    """The spec's table names each assigned opcode as the generated enum does, every 8-bit data opcode
    DAT, every 16-bit one DWD, and writes an unassigned one in octal."""
    from manip.spec.constants import ChaosOp

    for value in range(0o400):
        name = SPEC.chaos_opcode_name(value)
        if value >= ChaosOp.DWD:
            assert name == "DWD"
        elif value >= ChaosOp.DAT:
            assert name == "DAT"
        elif value in ChaosOp._value2member_map_:
            assert name == ChaosOp(value).name
        else:
            assert name == f"0{value:o}" if value else name == "0"
