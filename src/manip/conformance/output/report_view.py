"""A JSON report (live or saved) as the HTML and Markdown documents read it.

Both documents are rendered from the JSON report's data (:func:`~.report.report_json`), never from the
run's objects, so ``manip-conform report REPORT.json`` renders a saved report exactly as ``run --html``
renders a fresh one.  Reports written before the ``clauses`` catalogue existed take the clause texts
from the spec data of this version instead.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from manip.conformance.judge.packets import WirePacket, describe
from manip.conformance.judge.verdict import Outcome, judging_hint
from manip.conformance.output.packet_text import annotated
from manip.conformance.output.report import SCHEMA_VERSION
from manip.conformance.suite.world import WITHOUT_WORLD
from manip.links import AddressError, parse_address
from manip.spec import SPEC

__all__ = [
    "ATTENTION",
    "FAILING",
    "OUTCOME_ORDER",
    "ClauseInfo",
    "PacketRow",
    "ReportError",
    "WireOrder",
    "campaign_line",
    "clause_info",
    "clause_status_entries",
    "completeness_line",
    "failure_groups",
    "group_message",
    "grouped",
    "load_report",
    "not_judged_line",
    "packet_rows",
    "plural",
    "seeded",
    "target_label",
    "wire_order",
]

OUTCOME_ORDER: Final = Outcome.by_rank()
"""Outcomes, the ones needing attention first (:attr:`Outcome.rank`)."""
FAILING: Final = frozenset(o for o in Outcome if o.fails_run)
"""Outcomes that fail the run."""
ATTENTION: Final = frozenset(o for o in Outcome if o.needs_attention)
"""Outcomes a reader needs to look at (the rest are quiet: passed, skipped, not run...)."""
_REQUIRED: Final = ("verdict", "exit_code", "counts", "cases", "by_clause", "seed", "target")
Report = Mapping[str, Any]


class ReportError(Exception):
    """A file that is not a JSON report manip-conform can render; the message says why."""


def load_report(path: Path) -> dict[str, Any]:
    """The data of the JSON report at ``path`` (``run``/``verify``/``replay --json``)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ReportError(f"{path} is not text (a JSON report is UTF-8)") from None
    except json.JSONDecodeError as exc:
        raise ReportError(f"{path} is not JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict) or data.get("tool") != "manip-conform":
        raise ReportError(f'{path} is JSON but not a manip-conform report (no "tool": "manip-conform")')
    version = data.get("schema_version")
    if not isinstance(version, int) or version > SCHEMA_VERSION:
        raise ReportError(
            f"{path} has schema_version {version!r}; this manip-conform reads reports up to "
            f"version {SCHEMA_VERSION} (a newer manip-conform wrote it?)"
        )
    missing = [key for key in _REQUIRED if key not in data]
    if missing:
        raise ReportError(f"{path} lacks the report field(s) {', '.join(missing)}")
    return data


def not_judged_line(report: Report) -> str:
    """The sentence on the MUST clauses no case could judge on the target ("" when there are none)."""
    clauses = [str(c) for c in report.get("not_judged", [])]
    if not clauses:
        return ""
    hints: dict[str, str] = {}
    for case in report.get("cases", []):
        if case.get("outcome") == "not-judged":
            for clause in case.get("clauses", []):
                hints.setdefault(str(clause), judging_hint(str(case.get("reason", ""))))
    listed = ", ".join(f"{c} ({hints.get(c, 'see its case')})" for c in clauses)
    world = f"; --world: {WITHOUT_WORLD}" if "--world" in hints.values() else ""
    return (
        f"{len(clauses)} MUST clause(s) not judged on this target: {listed}; what would judge each is in "
        f"brackets{world}"
    )


def campaign_line(report: Report) -> str:
    """A fuzz campaign in one line (its ``campaign`` block's summary); "" for every other report."""
    campaign = report.get("campaign")
    return f"fuzz campaign: {campaign.get('summary', '')}" if isinstance(campaign, Mapping) else ""


def completeness_line(report: Report) -> str:
    """ "N of M MUST clauses judged, ..." ("" for a report written before clause statuses existed)."""
    completeness = report.get("completeness")
    return str(completeness.get("text", "")) if isinstance(completeness, Mapping) else ""


def clause_status_entries(report: Report) -> dict[str, Mapping[str, Any]]:
    """Each clause's status as a report read back saved it (its ``clause_status`` entries: status, why,
    hint, cases), by clause id; a run computes them with
    :func:`~manip.conformance.judge.verdict.clause_statuses`."""
    return {str(s["clause"]): s for s in report.get("clause_status", []) if isinstance(s, Mapping)}


def seeded(report: Report) -> bool:
    """Whether the run drew at random (a run of the suite); verify and replay draw nothing (seed 0)."""
    options = report.get("options", {})
    return not (isinstance(options, Mapping) and options.get("mode") in ("verify", "replay", "serve"))


@dataclass(frozen=True)
class ClauseInfo:
    level: str
    section: str
    text: str


def clause_info(report: Report, clause_id: str) -> ClauseInfo | None:
    """A clause as the report's run judged it (its ``clauses`` catalogue), else as the spec has it now."""
    saved = report.get("clauses", {}).get(clause_id)
    if isinstance(saved, Mapping):
        return ClauseInfo(str(saved["level"]), str(saved["section"]), str(saved["text"]))
    spec = SPEC.clauses.get(clause_id)
    return ClauseInfo(spec.level, spec.section, spec.text) if spec is not None else None


def failure_groups(report: Report) -> list[tuple[Mapping[str, Any] | None, list[Mapping[str, Any]]]]:
    """The report's broken clauses (``by_clause``, most failures first) with their cases, then (``None``)
    the failing cases that broke no clause (errors of the suite, stale known-failing entries)."""
    cases = {c["id"]: c for c in report["cases"]}
    groups: list[tuple[Mapping[str, Any] | None, list[Mapping[str, Any]]]] = []
    grouped: set[str] = set()
    for tally in report["by_clause"]:
        members = [cases[i] for i in tally["cases"] if i in cases]
        groups.append((tally, members))
        grouped.update(tally["cases"])
    rest = [c for c in report["cases"] if c["outcome"] in FAILING and c["id"] not in grouped]
    if rest:
        groups.append((None, rest))
    return groups


def grouped(violation: Mapping[str, Any], tally: Mapping[str, Any] | None) -> bool:
    """Whether ``violation`` is one that the failure group of ``tally`` (a ``by_clause`` entry) counts:
    of its clause, or, for a group of violations that cite no clause, of its kind.  The group of failing
    cases that broke no clause (``None``) takes any."""
    if tally is None:
        return True
    if tally["clause"] is not None:
        return bool(violation.get("clause") == tally["clause"])
    return violation.get("clause") is None and violation.get("kind") == tally["kind"]


def group_message(case: Mapping[str, Any], tally: Mapping[str, Any] | None) -> str:
    """What a case listed under a failure group says: the message of its first violation the group
    counts (not merely its first violation), else why it failed without one."""
    for violation in case.get("violations", []):
        if grouped(violation, tally):
            return str(violation.get("message", ""))
    if case["outcome"] == "fixed":
        return "listed in --known-failing but passed: remove the entry"
    return str(case.get("reason", ""))


def plural(count: int, word: str) -> str:
    """``1 warning``, ``16 warnings``."""
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def target_label(report: Report) -> str:
    """The target as a reader should know it: the embedded reference server by name and seed (its
    temporary socket is gone once the run ends), any other by its address."""
    if report.get("embedded"):
        seed = f", seed {int(report['seed'])}" if seeded(report) else ""
        return f"the embedded reference server{seed}"
    return str(report["target"])


@dataclass(frozen=True)
class WireOrder:
    """How a link puts a packet's data bytes on the wire (the report's data are PDP-11 memory order)."""

    msb_first: bool
    note: str


def wire_order(report: Report) -> WireOrder:
    """The byte order of the data on the report's link: MSB first on tcp/chudp/unix (pairs swapped),
    as in memory on chaosd; unknown (``verify``: the target is a capture's path) leaves the memory
    order, saying so."""
    target = str(report["target"])
    try:
        framing = parse_address(target).framing if "://" in target else None
    except (AddressError, ValueError):
        framing = None
    if framing is None:
        return WireOrder(False, "PDP-11 memory order: the low byte of each word first (link unknown)")
    if framing == "chaosd":
        return WireOrder(False, "wire order of the chaosd link: each word low byte first, padded to a word")
    return WireOrder(
        True, f"wire order of the {framing} link: each word most significant byte first, padded to a word"
    )


def wire_bytes(data: bytes, order: WireOrder) -> bytes:
    """``data`` as the link sends it: padded to a whole word, each pair swapped when MSB first."""
    padded = data + b"\x00" * (len(data) % 2)
    if not order.msb_first:
        return padded
    return b"".join(padded[i + 1 : i + 2] + padded[i : i + 1] for i in range(0, len(padded), 2))


def _hex(data: bytes, order: WireOrder) -> str:
    return wire_bytes(data, order).hex(" ")


def _wire_hex(packet: WirePacket, order: WireOrder) -> str:
    """A packet's bytes in the link's order; a DRV-11J record's as the DRV-11J link sends them (each
    word low byte first, whatever link carries the server's packets)."""
    return packet.data.hex(" ") if packet.link else _hex(packet.data, order)


@dataclass(frozen=True)
class PacketRow:
    number: int
    packet: WirePacket
    head: str
    """Opcode name and octal code, the number it carries, its size (:func:`describe`)."""
    fields: str
    """What its data say, decoded by the spec layouts."""
    wire_hex: str


def _packet(item: Mapping[str, Any]) -> WirePacket:
    return WirePacket(
        "c2s" if item["dir"] == "c2s" else "s2c",
        int(item["opcode"], 8),
        int(item["packet_no"]),
        int(item["ack_no"]),
        bytes.fromhex(item["data"]),
        float(item.get("time", 0.0)),
        int(item.get("connection", 0)),
        str(item.get("link", "")),
    )


def packet_rows(case: Mapping[str, Any], order: WireOrder) -> list[PacketRow]:
    """The case's packets (those the report kept), numbered by their place in the case's transcript,
    described, decoded, in wire order."""
    items = case.get("packets", [])
    packets: Sequence[WirePacket] = [_packet(p) for p in items]
    numbers = [int(p.get("n", i)) for i, p in enumerate(items, 1)]  # older reports: the first ones
    return [
        PacketRow(n, packet, describe(packet), text, "" if packet.is_close else _wire_hex(packet, order))
        for n, (packet, text) in zip(numbers, annotated(packets, from_open=True), strict=True)
    ]
