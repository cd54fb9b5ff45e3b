"""The one-file HTML report of a run: ``manip-conform run|verify|replay --html FILE`` and
``manip-conform report REPORT.json --html FILE``.

One page, no network: the style sheet and the script (``assets/report.css``, ``assets/report.js``) are
inlined, so the file works from ``file://`` and as a CI artifact.  From the top: the verdict and the
counts by verdict and by level, the failures grouped by the clause they break (with the clause's text
and its section of the 1985 guide), a sortable and filterable table of the cases, every clause the run
checked, and then each case: expected and actual, the clauses it checks, the command that reproduces it
(with a copy button) and its packets as a two-column sequence, client left and server right, each packet
decoded and its data bytes in the link's wire order.

Every piece of text from the report goes through :func:`html.escape`: case output holds ``<``, ``&`` and
quotes.  The script reads nothing but the page's own attributes (no data inside ``<script>``).
"""

from __future__ import annotations

import html
from collections import Counter
from collections.abc import Iterable, Mapping
from importlib import resources
from typing import Any, Final

from manip.conformance.output.culprit import AFTER, BEFORE, OPENING
from manip.conformance.output.report_view import (
    ATTENTION,
    FAILING,
    OUTCOME_ORDER,
    PacketRow,
    Report,
    WireOrder,
    campaign_line,
    clause_info,
    clause_status_entries,
    completeness_line,
    failure_groups,
    group_message,
    not_judged_line,
    packet_rows,
    plural,
    seeded,
    target_label,
    wire_order,
)
from manip.spec.model import LEVELS

__all__ = ["render_html"]

_RANK: Final[dict[str, int]] = {str(outcome): outcome.rank for outcome in OUTCOME_ORDER}
_CASES_PER_GROUP: Final = 12
"""Cases listed under each broken clause at the top; the rest are in the table (filter by clause)."""
DETAILS_FOR_EVERY_CASE: Final = 300
"""Up to this many cases, every case has its details (packets included); a larger report (``verify`` of a
long recording has thousands) details only the cases that need attention, so that the page stays small
and opens fast: the table lists the rest, and the JSON report keeps their packets."""


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _asset(name: str) -> str:
    return resources.files("manip.conformance.output").joinpath("assets", name).read_text(encoding="utf-8")


def _badge(outcome: str) -> str:
    return f'<span class="badge o-{_e(outcome)}">{_e(outcome)}</span>'


def _level(level: str) -> str:
    return f'<span class="level l-{_e(level)}">{_e(level)}</span>'


def _anchor(case_id: str) -> str:
    return f"case-{_e(case_id)}"


def _case_link(case_id: str) -> str:
    return f'<a href="#{_anchor(case_id)}">{_e(case_id)}</a>'


def _copy_line(command: str) -> str:
    """A command on one line and a button that copies it."""
    return (
        f'<div class="cmd"><code>{_e(command)}</code>'
        f'<button type="button" class="copy" data-copy="{_e(command)}" title="Copy to the clipboard">'
        "Copy</button></div>"
    )


def _header(report: Report) -> str:
    verdict = str(report["verdict"])
    ok = int(report["exit_code"]) == 0
    total = len(report["cases"])
    facts = [
        ("target", target_label(report)),
        ("seed", report["seed"] if seeded(report) else "-"),
        ("started", report.get("started", "") or "-"),
        (
            "duration",
            f"{float(report.get('duration', 0.0)):.1f} s"
            + (" (virtual time)" if report.get("time") == "virtual" else ""),
        ),
        ("cases", total),
        ("spec", report.get("spec_revision", "")),
    ]
    dl = "".join(f"<div><dt>{_e(k)}</dt><dd>{_e(v)}</dd></div>" for k, v in facts)
    return (
        '<header class="top">'
        f'<div class="title"><h1>manip-conform report</h1>'
        f'<span class="verdict {"ok" if ok else "bad"}">{_e(verdict)} <small>exit {_e(report["exit_code"])}'
        "</small></span></div>"
        f'<dl class="facts">{dl}</dl>'
        f"{_copy_line(str(report.get('command', '')))}"
        "</header>"
    )


def _summary(report: Report) -> str:
    counts: Mapping[str, int] = report["counts"]
    cards = "".join(
        f'<button type="button" class="card o-{_e(o)}{"" if counts.get(o, 0) else " zero"}" '
        f'data-verdict="{_e(o)}" title="Show only {_e(o)} cases in the table">'
        f'<span class="n">{int(counts.get(o, 0))}</span><span class="k">{_e(o)}</span></button>'
        for o in OUTCOME_ORDER
    )
    by_level: Counter[tuple[str, str]] = Counter((c["level"], c["outcome"]) for c in report["cases"])
    columns = [o for o in OUTCOME_ORDER if counts.get(o, 0)]
    head = "".join(f"<th>{_badge(o)}</th>" for o in columns)
    rows = ""
    for level in LEVELS:
        cells = [by_level[(level, o)] for o in columns]
        if not any(cells):
            continue
        tds = "".join(f'<td class="num{"" if n else " zero"}">{n}</td>' for n in cells)
        rows += f"<tr><th>{_level(level)}</th>{tds}<td class='num'>{sum(cells)}</td></tr>"
    problems = "".join(
        f"<li>{_e(p)}</li>" for p in [*report.get("problems", []), *report.get("unstable", [])]
    )
    if unjudged := not_judged_line(report):
        problems += f'<li class="o-not-judged">{_e(unjudged)}</li>'
    judged = completeness_line(report)

    if report.get("internal_error"):
        problems += f"<li>internal error<pre>{_e(report['internal_error'])}</pre></li>"
    return (
        '<section id="summary"><h2>Summary</h2><div class="overview">'
        f'<div class="cards">{cards}</div>'
        '<table class="levels"><caption>cases by level</caption><thead><tr><th></th>'
        f"{head}<th>total</th></tr></thead><tbody>{rows}</tbody></table></div>"
        + (
            f'<p class="judged">{_e(judged)} (each clause\'s status: <a href="#clauses">clauses</a>)</p>'
            if judged
            else ""
        )
        + (f'<p class="campaign">{_e(campaign)}</p>' if (campaign := campaign_line(report)) else "")
        + (f'<ul class="problems">{problems}</ul>' if problems else "")
        + "</section>"
    )


def _failures(report: Report) -> str:
    groups = failure_groups(report)
    if not groups:
        return (
            '<section id="failures"><h2>Failures by clause</h2><p class="none">No clause broke.</p></section>'
        )
    parts = []
    for tally, cases in groups:
        clause = tally["clause"] if tally is not None else None
        if tally is None:
            title, level, section = "(no clause: errors of the suite, stale known-failing entries)", "", ""
            text = "These cases failed without breaking a clause of the spec."
            counts = f"{len(cases)} case(s)"
        else:
            title = clause if clause is not None else f"(no clause: {tally['kind']})"
            level, section, text = tally["level"], tally["section"], tally["text"]
            counts = ", ".join(
                f"{n} {word}"
                for n, word in (
                    (tally["failures"], "failing"),
                    (tally["warnings"], "warning" if tally["warnings"] == 1 else "warnings"),
                    (tally["known_failures"], "known failing"),
                )
                if n
            )
        shown = cases[:_CASES_PER_GROUP]
        items = "".join(
            f"<li>{_badge(c['outcome'])} {_case_link(c['id'])}"
            f'<span class="msg">{_e(group_message(c, tally))}</span></li>'
            for c in shown
        )
        more = len(cases) - len(shown)
        if more:
            filter_value = _e(clause or "")
            items += (
                f'<li class="more">and {more} more: <a href="#cases" data-filter="{filter_value}">'
                f"show them in the table</a></li>"
            )
        kind = "bad" if tally is None or tally["failures"] else "soft"
        parts.append(
            f'<article class="group {kind}"><div class="ghead">{_level(level) if level else ""}'
            f'<code class="clause">{_e(title)}</code><span class="count">{_e(counts)}</span>'
            + (f'<span class="section">\u00a7 {_e(section)}</span>' if section else "")
            + f'</div><blockquote>{_e(text)}</blockquote><ul class="cases">{items}</ul></article>'
        )
    failing = sum(1 for c in report["cases"] if c["outcome"] in FAILING)
    return (
        f'<section id="failures"><h2>Failures by clause <small>{failing} failing case(s), '
        f"{len(groups)} group(s)</small></h2>{''.join(parts)}</section>"
    )


def _detailed(report: Report, case: Mapping[str, Any]) -> bool:
    """Whether the page details ``case`` (see :data:`DETAILS_FOR_EVERY_CASE`)."""
    return len(report["cases"]) <= DETAILS_FOR_EVERY_CASE or case["outcome"] in ATTENTION


def _case_table(report: Report) -> str:
    rows = []
    for c in sorted(report["cases"], key=lambda c: (_RANK.get(c["outcome"], 99), c["id"])):
        broke = {v["clause"] for v in c.get("violations", []) if v.get("clause")}
        shown = " ".join(
            f'<code class="broke">{_e(x)}</code>' if x in broke else f"<code>{_e(x)}</code>"
            for x in c["clauses"]
        )
        # the filter searches the id and clause cells; a broken clause the case does not cite (an
        # invariant's) is added for it, the only text a row carries twice
        extra = " ".join(sorted(broke - set(c["clauses"])))
        search = f' data-search="{_e(extra)}"' if extra else ""
        rows.append(
            f'<tr data-verdict="{_e(c["outcome"])}" data-rank="{_RANK.get(c["outcome"], 99)}" '
            f'data-id="{_e(c["id"])}" data-level="{_e(c["level"])}" '
            f'data-duration="{float(c["duration"]):.6f}"{search}>'
            f"<td>{_badge(c['outcome'])}</td>"
            f'<td class="cid">{_case_link(c["id"]) if _detailed(report, c) else _e(c["id"])}</td>'
            f'<td class="clauses">{shown}</td><td>{_level(c["level"])}</td>'
            f'<td class="num">{float(c["duration"]):.3f}</td></tr>'
        )
    verdicts = "".join(
        f'<label class="chip o-{_e(o)}"><input type="checkbox" name="verdict" value="{_e(o)}" checked> '
        f"{_e(o)}</label>"
        for o in OUTCOME_ORDER
        if report["counts"].get(o, 0)
    )
    levels = "".join(f'<option value="{lv}">{lv}</option>' for lv in LEVELS)
    return (
        '<section id="cases"><h2>Cases <small id="shown"></small></h2>'
        '<div class="filters"><input type="search" id="filter" placeholder="Filter by case id or clause" '
        f'aria-label="Filter cases">{verdicts}<select id="level" aria-label="Level">'
        f'<option value="">every level</option>{levels}</select></div>'
        '<table id="case-table" class="cases"><thead><tr>'
        '<th data-sort="rank" aria-sort="ascending">verdict</th><th data-sort="id">case</th>'
        '<th>clauses</th><th data-sort="level">level</th>'
        '<th data-sort="duration" class="num">duration (s)</th>'
        f"</tr></thead><tbody>{''.join(rows)}</tbody></table></section>"
    )


def _clause_table(report: Report) -> str:
    cited: dict[str, Counter[str]] = {}
    for c in report["cases"]:
        for clause in c["clauses"]:
            cited.setdefault(clause, Counter())[c["outcome"]] += 1
    broken: Mapping[str, Mapping[str, Any]] = {t["clause"]: t for t in report["by_clause"] if t["clause"]}
    statuses = clause_status_entries(report)
    rows = []
    for clause in sorted(
        cited, key=lambda k: (-int(broken.get(k, {}).get("failures", 0)), k not in broken, k)
    ):
        info = clause_info(report, clause)
        tally = broken.get(clause)
        status = (
            f"{int(tally['failures'])} failing, {plural(int(tally['warnings']), 'warning')}"
            if tally
            else "held"
        )
        outcomes = ", ".join(f"{n} {o}" for o, n in sorted(cited[clause].items(), key=lambda i: _RANK[i[0]]))
        rows.append(
            f'<tr class="{"broke" if tally and tally["failures"] else ""}"><td><code>{_e(clause)}</code></td>'
            f"<td>{_level(info.level) if info else ''}</td><td>{_e(info.section if info else '')}</td>"
            f"<td>{_e(info.text if info else '(not in this version of the spec)')}</td>"
            f"<td>{_e(status)}</td><td>{_e(outcomes)}</td><td>{_status_cell(statuses.get(clause))}</td></tr>"
        )
    return (
        f'<section id="clauses"><details><summary><h2>Clauses checked <small>{len(cited)}</small></h2>'
        '</summary><table class="clause-table"><thead><tr><th>clause</th><th>level</th>'
        "<th>section of the 1985 guide</th><th>text</th><th>broken</th><th>cases citing it</th>"
        "<th>status</th></tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table></details></section>"
    )


def _status_cell(entry: Mapping[str, Any] | None) -> str:
    """A clause's status in the run (held, broken, not judged, not exercised), with why and what would
    judge it; empty for a report written before statuses existed."""
    if entry is None:
        return ""
    why = f" — {entry['why']}; what would judge it: {entry['hint']}" if entry.get("why") else ""
    return f'<span class="status">{_e(entry["status"])}</span>{_e(why)}'


def _bubble(row: PacketRow, connections: int) -> str:
    conn = f'<span class="conn">conn {row.packet.connection}</span>' if connections > 1 else ""
    hexdump = f'<code class="hex">{_e(row.wire_hex)}</code>' if row.wire_hex else ""
    return (
        f'<div class="pkt {row.packet.direction}">{conn}<div class="phead">{_e(row.head)}</div>'
        f'<div class="fields">{_e(row.fields)}</div>{hexdump}</div>'
    )


def _packet_anchor(case_id: str, number: int) -> str:
    return f"{_anchor(case_id)}-p{number}"


def _culprits(case: Mapping[str, Any]) -> dict[int, int]:
    """Packet number -> the number (from 1) of the first violation it is the culprit of."""
    found: dict[int, int] = {}
    for i, violation in enumerate(case.get("violations", []), 1):
        number = violation.get("packet")
        if isinstance(number, int):
            found.setdefault(number, i)
    return found


def _packet_row(row: PacketRow, connections: int, case_id: str, culprits: Mapping[int, int]) -> str:
    bubble = _bubble(row, connections)
    cells = f"<td>{bubble}</td><td></td>" if row.packet.direction == "c2s" else f"<td></td><td>{bubble}</td>"
    culprit = culprits.get(row.number)
    mark = (
        f' culprit" id="{_packet_anchor(case_id, row.number)}" title="the packet of violation {culprit}'
        if culprit
        else ""
    )
    return (
        f'<tr class="prow {row.packet.direction}{mark}"><td class="num">{row.number}</td>'
        f'<td class="num t">{row.packet.time:.3f}</td>{cells}</tr>'
    )


def _near(number: int, culprits: Iterable[int]) -> bool:
    """Whether packet ``number`` is shown open: the connection's opening or the window of a culprit."""
    return number <= OPENING or any(c - BEFORE <= number <= c + AFTER for c in culprits)


def _span(first: int, last: int) -> str:
    return f"#{first}" if first == last else f"#{first}\u2013#{last}"


def _fold(rows: list[str], first: int, last: int) -> str:
    return (
        f'<tr class="fold"><td colspan="4"><details><summary>{plural(len(rows), "packet")} '
        f"({_span(first, last)}), folded</summary>"
        f'<table class="packets">{"".join(rows)}</table></details></td></tr>'
    )


def _gap(first: int, last: int) -> str:
    words = f"{plural(last - first + 1, 'packet')} ({_span(first, last)})"
    return f'<tr class="gap"><td colspan="4">{words} not kept in the report</td></tr>'


def _packet_body(rows: list[PacketRow], case_id: str, culprits: Mapping[int, int]) -> str:
    """The rows of a packet log: those near a culprit open, each run of the others folded, and a line
    where the report kept no packets."""
    connections = len({r.packet.connection for r in rows})
    parts: list[str] = []
    folded: list[PacketRow] = []

    def flush() -> None:
        if folded:
            parts.append(
                _fold(
                    [_packet_row(r, connections, case_id, culprits) for r in folded],
                    folded[0].number,
                    folded[-1].number,
                )
            )
            folded.clear()

    previous = 0
    for row in rows:
        if row.number > previous + 1:
            flush()
            parts.append(_gap(previous + 1, row.number - 1))
        previous = row.number
        if culprits and not _near(row.number, culprits):
            folded.append(row)
            continue
        flush()
        parts.append(_packet_row(row, connections, case_id, culprits))
    flush()
    return "".join(parts)


def _packet_log(case: Mapping[str, Any], order: WireOrder) -> str:
    rows = packet_rows(case, order)
    if not rows:
        return '<p class="none">No packets were recorded for this case.</p>'
    culprits = _culprits(case)
    total = int(case.get("packets_total", len(rows)))
    body = _packet_body(rows, str(case["id"]), culprits)
    if total > rows[-1].number:
        body += _gap(rows[-1].number + 1, total)
    said = [plural(total, "packet")]
    if total > len(rows):
        said.append(f"the report keeps {len(rows)}")
    if culprits:
        said.append("the ones around each failure are open (the culprit marked), the rest folded")
    return (
        f'<p class="wire">{_e("; ".join(said))}; data bytes in {_e(order.note)}.</p>'
        '<table class="packets"><thead><tr><th>#</th><th>time (s)</th><th class="c">client \u2192</th>'
        f'<th class="s">\u2190 server</th></tr></thead><tbody>{body}</tbody></table>'
    )


def _violation(report: Report, case_id: str, v: Mapping[str, Any], kept: frozenset[int]) -> str:
    clause = v.get("clause")
    info = clause_info(report, clause) if clause else None
    ref = (
        f'<div class="ghead">{_level(str(v.get("level", "")))}<code class="clause">{_e(clause)}</code>'
        + (f'<span class="section">\u00a7 {_e(info.section)}</span>' if info else "")
        + "</div>"
        + (f"<blockquote>{_e(info.text)}</blockquote>" if info else "")
        if clause
        else f'<div class="ghead">{_level(str(v.get("level", "")))}<code class="clause">'
        f"(no clause: {_e(v.get('kind', ''))})</code></div>"
    )
    fields = [
        ("message", v.get("message", "")),
        ("expected", v.get("expected", "")),
        ("actual", v.get("actual", "")),
    ]
    if v.get("bytes"):
        fields.append(("bytes", bytes.fromhex(str(v["bytes"])).hex(" ") + "  (data, PDP-11 memory order)"))
    dl = "".join(f"<dt>{_e(k)}</dt><dd><pre>{_e(text)}</pre></dd>" for k, text in fields if text)
    number = v.get("packet")
    if isinstance(number, int) and number in kept:
        dl += (
            f'<dt>packet</dt><dd><a class="culprit-link" href="#{_packet_anchor(case_id, number)}">'
            f"#{number} in the packets below</a></dd>"
        )
    elif isinstance(number, int):  # past the report's bound on kept packets
        dl += f"<dt>packet</dt><dd>#{number} (not kept in the report)</dd>"
    return f'<div class="violation">{ref}<dl class="ea">{dl}</dl></div>'


def _clause_list(report: Report, clauses: Iterable[str]) -> str:
    items = []
    for clause in clauses:
        info = clause_info(report, clause)
        text = f"{info.text} (\u00a7 {info.section})" if info else "(not in this version of the spec)"
        level = _level(info.level) if info else ""
        items.append(f"<li>{level}<code>{_e(clause)}</code> {_e(text)}</li>")
    return f'<ul class="clause-list">{"".join(items)}</ul>'


def _case_detail(report: Report, case: Mapping[str, Any], order: WireOrder) -> str:
    outcome = str(case["outcome"])
    is_open = " open" if outcome in FAILING or outcome == "warn" else ""
    parts = [f'<p class="summary">{_e(case.get("summary", ""))}</p>']
    kept = frozenset(int(p.get("n", i)) for i, p in enumerate(case.get("packets", []), 1))
    parts += [_violation(report, str(case["id"]), v, kept) for v in case.get("violations", [])]
    if outcome == "fixed":
        parts.append('<p class="reason">Listed in --known-failing but passed: remove the entry.</p>')
    if case.get("reason"):
        parts.append(f'<p class="reason">{_e(case["reason"])}</p>')
    if case.get("traceback"):
        parts.append(f'<pre class="traceback">{_e(case["traceback"])}</pre>')
    if case.get("notes"):
        parts.append('<ul class="notes">' + "".join(f"<li>{_e(n)}</li>" for n in case["notes"]) + "</ul>")
    parts.append(f"<h4>Reproduce</h4>{_copy_line(str(case.get('reproduce', '')))}")
    parts.append(f"<h4>Packets</h4>{_packet_log(case, order)}")
    parts.append(f"<h4>Clauses it checks</h4>{_clause_list(report, case['clauses'])}")
    extensions = case.get("extensions") or []
    uses = f"uses {_e(', '.join(str(x) for x in extensions))} (Puma extensions) \u00b7 " if extensions else ""
    meta = (
        f"{_e(case['level'])} \u00b7 {_e(case['kind'])} \u00b7 {_e(case['hazard'])} \u00b7 {uses}"
        f"{float(case['duration']):.3f} s of its {float(case['deadline']):g} s time budget"
        + (
            f" (the contract's deadline for the harness: {float(case['harness_deadline']):g} s)"
            if "harness_deadline" in case
            else ""
        )
        + f" \u00b7 seed {_e(case['seed'])}"
    )
    return (
        f'<details class="case o-{_e(outcome)}" id="{_anchor(str(case["id"]))}"{is_open}>'
        f'<summary>{_badge(outcome)}<span class="cid">{_e(case["id"])}</span>'
        f'<span class="meta">{meta}</span></summary><div class="body">{"".join(parts)}</div></details>'
    )


def render_html(report: Report) -> str:
    """The whole page of the JSON report's data ``report``."""
    order = wire_order(report)
    cases = sorted(report["cases"], key=lambda c: (_RANK.get(c["outcome"], 99), c["id"]))
    detailed = [c for c in cases if _detailed(report, c)]
    details = "".join(_case_detail(report, c, order) for c in detailed)
    if len(detailed) < len(cases):
        details = (
            f'<p class="quiet">{len(report["cases"])} cases: the details of the {len(detailed)} that need '
            "attention are below; the table lists every case, and the JSON report (<code>--json</code>) "
            f"keeps the packets of all.</p>{details}"
        )
    title = f"manip-conform: {report['verdict']} \u2014 {target_label(report)}"
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f"<title>{_e(title)}</title><style>{_asset('report.css')}</style></head><body>"
        f"{_header(report)}"
        '<nav><a href="#summary">Summary</a><a href="#failures">Failures by clause</a>'
        '<a href="#cases">Cases</a><a href="#clauses">Clauses</a><a href="#details">Case details</a></nav>'
        f"<main>{_summary(report)}{_failures(report)}{_case_table(report)}{_clause_table(report)}"
        f'<section id="details"><h2>Case details</h2>{details}</section></main>'
        f"<script>{_asset('report.js')}</script></body></html>\n"
    )
