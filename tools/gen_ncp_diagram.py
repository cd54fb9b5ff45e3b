"""Generate docs/ncp-states.md (a Mermaid state diagram and a table) from src/manip/ncp/states.py.

Run after changing the transition table; tests/ncp/test_states.py fails while the file is stale.
"""

from __future__ import annotations

import sys
from collections import defaultdict
from pathlib import Path

from manip.ncp.states import ACTION_DOCS, FINAL_STATES, TRANSITIONS, ConnInput, ConnState

TARGET = Path(__file__).resolve().parents[1] / "docs" / "ncp-states.md"


def _edges() -> dict[tuple[ConnState, ConnState], list[ConnInput]]:
    edges: dict[tuple[ConnState, ConnState], list[ConnInput]] = defaultdict(list)
    for (state, inp), tr in TRANSITIONS.items():
        edges[(state, tr.next_state)].append(inp)
    return edges


def render() -> str:
    out: list[str] = [
        "# Chaos NCP connection states",
        "",
        "Generated from the transition table in `src/manip/ncp/states.py` by `tools/gen_ncp_diagram.py`; "
        "do not edit by hand.",
        "",
        "Inputs come from the user (calls on `Ncp`), from packets (the opcode received; DATA is any "
        "opcode 0200-0377) or from time and internal conditions.  An input missing from the table is "
        "ignored if it is a packet and refused with `InvalidStateError` if it is a user call.  Sequencing "
        "inside OPEN (numbers, acks, receipts, windows, retransmission, probes) does not change the state.",
        "",
        "## Diagram",
        "",
        "Self-loops are left out of the diagram; the table lists them.",
        "",
        "```mermaid",
        "stateDiagram-v2",
        "    [*] --> CLOSED",
    ]
    for (src, dst), inputs in _edges().items():
        if src is dst:
            continue
        label = ", ".join(i.name for i in inputs)
        out.append(f"    {src.name} --> {dst.name} : {label}")
    for state in ConnState:
        if state in FINAL_STATES:
            out.append(f"    {state.name} --> [*]")
    out += [
        "```",
        "",
        "## Transition table",
        "",
        "| State | Input | Source | Actions | Next state |",
        "|---|---|---|---|---|",
    ]
    for (state, inp), tr in TRANSITIONS.items():
        actions = ", ".join(f"`{a}`" for a in tr.actions) or "—"
        nxt = "(same)" if tr.next_state is state else tr.next_state.name
        out.append(f"| {state.name} | {inp.name} | {inp.source.value} | {actions} | {nxt} |")
    out += ["", "## Inputs", "", "| Input | Source | Meaning |", "|---|---|---|"]
    for inp in ConnInput:
        out.append(f"| {inp.name} | {inp.source.value} | {inp.description} |")
    out += ["", "## Actions", "", "| Action | What it does |", "|---|---|"]
    for name in sorted(ACTION_DOCS):
        out.append(f"| `{name}` | {ACTION_DOCS[name]} |")
    return "\n".join(out) + "\n"


def main() -> int:
    TARGET.write_text(render())
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
