"""The transition table: well formed, fully implemented, and the generated diagram is current."""

from __future__ import annotations

from types import ModuleType

import pytest

from manip.ncp.connection import _PLAN, implemented_actions
from manip.ncp.states import (
    ACTION_DOCS,
    FINAL_STATES,
    TRANSITIONS,
    ConnInput,
    ConnState,
    InputSource,
    all_actions,
    transition,
)
from tests.support.paths import ROOT
from tests.support.tools import load_tool


def _generator() -> ModuleType:
    return load_tool("gen_ncp_diagram")


def test_generated_diagram_is_current() -> None:
    on_disk = (ROOT / "docs" / "ncp-states.md").read_text()
    assert on_disk == _generator().render(), "run: python tools/gen_ncp_diagram.py"


def test_every_action_is_implemented_and_documented() -> None:
    assert all_actions() <= implemented_actions()
    assert implemented_actions() <= all_actions(), "an implemented action the table never uses"
    assert set(ACTION_DOCS) == set(all_actions())


def test_every_state_is_reachable_from_closed() -> None:
    seen = {ConnState.CLOSED}
    frontier = [ConnState.CLOSED]
    while frontier:
        state = frontier.pop()
        for (src, _inp), tr in TRANSITIONS.items():
            if src is state and tr.next_state not in seen:
                seen.add(tr.next_state)
                frontier.append(tr.next_state)
    assert seen == set(ConnState)


def test_every_input_is_used() -> None:
    assert {inp for (_s, inp) in TRANSITIONS} == set(ConnInput)


def test_final_states_only_answer_close_and_abort() -> None:
    for (state, inp), tr in TRANSITIONS.items():
        if state in FINAL_STATES and not (
            state is ConnState.CLOSED and inp in (ConnInput.CONNECT, ConnInput.LISTEN)
        ):
            assert inp in (ConnInput.CLOSE, ConnInput.ABORT), (state, inp)
            assert tr.next_state is state and tr.actions == ()


def test_leaving_a_sending_state_stops_retransmission() -> None:
    for (state, inp), tr in TRANSITIONS.items():
        if state in (ConnState.RFC_SENT, ConnState.OPEN) and tr.next_state in FINAL_STATES:
            assert "discard_queues" in tr.actions, (state, inp)


def test_only_packets_deliver_packet_events() -> None:
    packet_events = {"deliver_request", "deliver_answer", "deliver_forward", "deliver_lost", "deliver_unc"}
    for (_state, inp), tr in TRANSITIONS.items():
        if packet_events & set(tr.actions):
            assert inp.source is InputSource.PACKET, inp


@pytest.mark.parametrize(
    ("state", "inp", "next_state"),
    [
        (ConnState.CLOSED, ConnInput.CONNECT, ConnState.RFC_SENT),
        (ConnState.RFC_SENT, ConnInput.OPN, ConnState.OPEN),
        (ConnState.RFC_SENT, ConnInput.CLS, ConnState.CLOSED),
        (ConnState.RFC_SENT, ConnInput.LOS, ConnState.LOST),
        (ConnState.RFC_SENT, ConnInput.RFC_TIMEOUT, ConnState.INCOMPLETE),
        (ConnState.LISTEN, ConnInput.RFC, ConnState.RFC_RECEIVED),
        (ConnState.RFC_RECEIVED, ConnInput.ACCEPT, ConnState.OPEN),
        (ConnState.RFC_RECEIVED, ConnInput.ANSWER, ConnState.CLOSED),
        (ConnState.OPEN, ConnInput.DATA, ConnState.OPEN),
        (ConnState.OPEN, ConnInput.EOF_ACKED, ConnState.CLOSED),
        (ConnState.OPEN, ConnInput.LOS, ConnState.LOST),
        (ConnState.OPEN, ConnInput.SILENCE, ConnState.INCOMPLETE),
    ],
)
def test_key_transitions(state: ConnState, inp: ConnInput, next_state: ConnState) -> None:
    tr = transition(state, inp)
    assert tr is not None and tr.next_state is next_state


def test_missing_entries_are_none() -> None:
    assert transition(ConnState.OPEN, ConnInput.ACCEPT) is None
    assert transition(ConnState.LOST, ConnInput.DATA) is None


def test_resolved_plan_is_the_table() -> None:
    """Connections run a copy of the table with the action names resolved; it must say the same."""
    assert set(_PLAN) == set(TRANSITIONS)
    for key, tr in TRANSITIONS.items():
        actions, next_state = _PLAN[key]
        assert [fn.__name__.removeprefix("_a_") for fn in actions] == list(tr.actions), key
        assert next_state is tr.next_state


def test_enum_members_hash_by_identity_and_still_compare_as_before() -> None:
    # The table is keyed by (state, input); identity hashing keeps lookups in C and must not merge members.
    assert len({*ConnState, *ConnInput}) == len(ConnState) + len(ConnInput)
    assert all(hash(m) == object.__hash__(m) for m in (*ConnState, *ConnInput))
    assert all(ConnState[m.name] is m and ConnState(m.value) is m for m in ConnState)
    assert all(ConnInput[m.name] is m for m in ConnInput)
    assert ConnState.OPEN.value == "OPEN" and ConnInput.SEND.source is InputSource.USER
