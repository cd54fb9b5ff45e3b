"""The state machine of one Chaos connection, as a table.

Theory of operation
===================

A Chaos connection is in one of seven states.  Things happen to it from three directions: the local
user calls the NCP (connect, accept, send, close ...), a packet arrives from the peer, or time passes.
Each of those is a :class:`ConnInput`.  The table :data:`TRANSITIONS` maps ``(state, input)`` to a
:class:`Transition`: the names of the actions to run, in order, and the state that follows.  The table
is the whole of the state logic; :mod:`manip.ncp.connection` implements each action name as a small
method and :mod:`manip.ncp.node` only decides *which* connection an input belongs to.  The diagram in
``docs/ncp-states.md`` is generated from this table (``tools/gen_ncp_diagram.py``).

The life of a connection:

* A caller's connection starts CLOSED; ``connect`` sends an RFC and waits in RFC_SENT.  An OPN opens
  it; CLS (refusal), ANS (simple answer) or FWD (forwarding) close it again; a LOS makes it LOST; no
  reply within the RFC timeout makes it INCOMPLETE.
* A listener is a standing LSN for one contact name.  Each matching RFC creates a connection that
  passes through LISTEN, takes the RFC and waits in RFC_RECEIVED for the user to accept, refuse,
  answer or forward it.  Accepting sends an OPN and enters OPEN.
* OPEN has an implicit "half-open" phase on the accepting side: until the first STS arrives the
  peer's receive window is unknown, so the transmit window is 0 and nothing may be sent.  The first STS
  gives the window, and only then does the user get :class:`~manip.ncp.events.Opened`.  This phase is
  not a separate state because every input is handled exactly as in OPEN.
* Sequencing inside OPEN (packet numbers, acknowledgements, receipts, windows, retransmission,
  probing) is bookkeeping, not state: it lives in the connection object and never changes the state.
* ``close`` is graceful: an EOF is queued behind the data, and when the peer acknowledges it (meaning
  its user has read everything) a CLS is sent and the connection is CLOSED (EOF_ACKED).  If the peer
  sent its EOF first, ours is left out: the peer is closing too and sends CLS once its EOF is
  acknowledged, so an EOF of ours would cross that CLS and draw a LOS.  A CLS alone ends it, once
  everything we sent is acknowledged (PEER_FINISHED).  ``abort``
  sends a CLS at once.  A CLS from the peer closes, a LOS loses, and ``broken_after`` seconds without
  any packet from the peer (SILENCE) make the connection INCOMPLETE.
* CLOSED, LOST and INCOMPLETE are final: an NCP treats packets for a finished connection exactly as
  packets for a connection that never existed.

Inputs missing from the table: a packet is ignored; a user call raises
:class:`~manip.ncp.errors.InvalidStateError`.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Final


class ConnState(enum.Enum):
    """The states of a Chaos connection."""

    CLOSED = "CLOSED"
    LISTEN = "LISTEN"
    RFC_SENT = "RFC_SENT"
    RFC_RECEIVED = "RFC_RECEIVED"
    OPEN = "OPEN"
    LOST = "LOST"
    INCOMPLETE = "INCOMPLETE"

    # Members are singletons compared by identity, so identity hashing is exact, and it is done in C;
    # ``Enum.__hash__`` hashes the name in Python, which showed up on every packet's path.
    __hash__ = object.__hash__


FINAL_STATES: Final = frozenset({ConnState.CLOSED, ConnState.LOST, ConnState.INCOMPLETE})
"""States a connection never leaves once it got there after being used."""


class InputSource(enum.Enum):
    """Where an input comes from: the user, a packet, or the passing of time and internal conditions."""

    USER = "user"
    PACKET = "packet"
    INTERNAL = "internal"


class ConnInput(enum.Enum):
    """Everything that can happen to a connection.  The value is (source, description)."""

    # The local user.
    CONNECT = (InputSource.USER, "connect(): send an RFC")
    LISTEN = (InputSource.USER, "a listener takes the connection")
    ACCEPT = (InputSource.USER, "accept() a received RFC")
    REFUSE = (InputSource.USER, "refuse() a received RFC")
    ANSWER = (InputSource.USER, "answer() a received RFC with ANS")
    FORWARD = (InputSource.USER, "forward() a received RFC with FWD")
    SEND = (InputSource.USER, "send() a data packet")
    READ = (InputSource.USER, "read_ack(): the user has read up to a packet")
    CLOSE = (InputSource.USER, "close(): graceful close")
    ABORT = (InputSource.USER, "abort(): CLS now")
    # Packets from the peer (DATA is any opcode 0200-0377).
    RFC = (InputSource.PACKET, "RFC received")
    OPN = (InputSource.PACKET, "OPN received")
    CLS = (InputSource.PACKET, "CLS received")
    ANS = (InputSource.PACKET, "ANS received")
    FWD = (InputSource.PACKET, "FWD received")
    SNS = (InputSource.PACKET, "SNS received")
    STS = (InputSource.PACKET, "STS received")
    LOS = (InputSource.PACKET, "LOS received")
    EOF = (InputSource.PACKET, "EOF received")
    UNC = (InputSource.PACKET, "UNC received")
    DATA = (InputSource.PACKET, "data packet (0200-0377) received")
    # Time and internal conditions.
    EOF_ACKED = (InputSource.INTERNAL, "our EOF was acknowledged after close()")
    PEER_FINISHED = (InputSource.INTERNAL, "close() after the peer's EOF, everything we sent acknowledged")
    RFC_TIMEOUT = (InputSource.INTERNAL, "no reply to our RFC within rfc_timeout")
    UNANSWERED = (InputSource.INTERNAL, "the user left a received RFC unanswered for rfc_timeout")
    SILENCE = (InputSource.INTERNAL, "no packet from the peer for broken_after")

    __hash__ = object.__hash__  # see ConnState

    @property
    def source(self) -> InputSource:
        src: InputSource = self.value[0]
        return src

    @property
    def description(self) -> str:
        text: str = self.value[1]
        return text


@dataclass(frozen=True, slots=True)
class Transition:
    """What to do, and where to go, for one ``(state, input)``."""

    actions: tuple[str, ...]
    next_state: ConnState


_S = ConnState
_I = ConnInput  # short aliases keep the table readable


def _t(next_state: ConnState, *actions: str) -> Transition:
    return Transition(actions, next_state)


_TABLE: dict[tuple[ConnState, ConnInput], Transition] = {
    # --- CLOSED: the start of every connection, and the end of most.
    (_S.CLOSED, _I.CONNECT): _t(_S.RFC_SENT, "send_rfc"),
    (_S.CLOSED, _I.LISTEN): _t(_S.LISTEN),
    (_S.CLOSED, _I.CLOSE): _t(_S.CLOSED),
    (_S.CLOSED, _I.ABORT): _t(_S.CLOSED),
    # --- LISTEN: a listener's connection waiting for its RFC.
    (_S.LISTEN, _I.RFC): _t(_S.RFC_RECEIVED, "take_rfc", "deliver_request"),
    (_S.LISTEN, _I.CLOSE): _t(_S.CLOSED),
    (_S.LISTEN, _I.ABORT): _t(_S.CLOSED),
    # --- RFC_SENT: our RFC is retransmitted until one of these arrives.
    (_S.RFC_SENT, _I.OPN): _t(_S.OPEN, "take_opn", "send_sts", "deliver_opened"),
    (_S.RFC_SENT, _I.CLS): _t(_S.CLOSED, "discard_queues", "deliver_closed"),
    (_S.RFC_SENT, _I.ANS): _t(_S.CLOSED, "discard_queues", "deliver_answer"),
    (_S.RFC_SENT, _I.FWD): _t(_S.CLOSED, "discard_queues", "deliver_forward"),
    (_S.RFC_SENT, _I.LOS): _t(_S.LOST, "discard_queues", "deliver_lost"),
    (_S.RFC_SENT, _I.SNS): _t(_S.RFC_SENT),
    (_S.RFC_SENT, _I.DATA): _t(_S.RFC_SENT, "los_not_open"),
    (_S.RFC_SENT, _I.EOF): _t(_S.RFC_SENT, "los_not_open"),
    (_S.RFC_SENT, _I.RFC_TIMEOUT): _t(_S.INCOMPLETE, "discard_queues", "deliver_broken"),
    (_S.RFC_SENT, _I.CLOSE): _t(_S.CLOSED, "discard_queues"),
    (_S.RFC_SENT, _I.ABORT): _t(_S.CLOSED, "discard_queues"),
    # --- RFC_RECEIVED: the user decides.
    (_S.RFC_RECEIVED, _I.RFC): _t(_S.RFC_RECEIVED),
    (_S.RFC_RECEIVED, _I.ACCEPT): _t(_S.OPEN, "send_opn"),
    (_S.RFC_RECEIVED, _I.REFUSE): _t(_S.CLOSED, "send_refusal"),
    (_S.RFC_RECEIVED, _I.ANSWER): _t(_S.CLOSED, "send_ans"),
    (_S.RFC_RECEIVED, _I.FORWARD): _t(_S.CLOSED, "send_fwd"),
    (_S.RFC_RECEIVED, _I.CLOSE): _t(_S.CLOSED, "send_refusal"),
    (_S.RFC_RECEIVED, _I.ABORT): _t(_S.CLOSED, "send_refusal"),
    (_S.RFC_RECEIVED, _I.DATA): _t(_S.RFC_RECEIVED, "los_not_open"),
    (_S.RFC_RECEIVED, _I.EOF): _t(_S.RFC_RECEIVED, "los_not_open"),
    (_S.RFC_RECEIVED, _I.UNANSWERED): _t(_S.CLOSED, "send_refusal", "deliver_closed"),
    # --- OPEN: data flows.
    (_S.OPEN, _I.RFC): _t(_S.OPEN, "resend_opn"),
    (_S.OPEN, _I.OPN): _t(_S.OPEN, "process_ack", "send_sts"),
    (_S.OPEN, _I.STS): _t(_S.OPEN, "take_sts"),
    (_S.OPEN, _I.SNS): _t(_S.OPEN, "process_ack", "send_sts"),
    (_S.OPEN, _I.DATA): _t(_S.OPEN, "process_ack", "take_data"),
    (_S.OPEN, _I.EOF): _t(_S.OPEN, "process_ack", "take_data"),
    (_S.OPEN, _I.UNC): _t(_S.OPEN, "process_ack", "deliver_unc"),
    (_S.OPEN, _I.CLS): _t(_S.CLOSED, "discard_queues", "deliver_closed"),
    (_S.OPEN, _I.LOS): _t(_S.LOST, "discard_queues", "deliver_lost"),
    (_S.OPEN, _I.SEND): _t(_S.OPEN, "send_data"),
    (_S.OPEN, _I.READ): _t(_S.OPEN, "mark_read"),
    (_S.OPEN, _I.CLOSE): _t(_S.OPEN, "start_close"),
    (_S.OPEN, _I.EOF_ACKED): _t(_S.CLOSED, "send_cls", "discard_queues", "deliver_closed"),
    (_S.OPEN, _I.PEER_FINISHED): _t(_S.CLOSED, "send_cls", "discard_queues", "deliver_closed"),
    (_S.OPEN, _I.ABORT): _t(_S.CLOSED, "send_cls", "discard_queues"),
    (_S.OPEN, _I.SILENCE): _t(_S.INCOMPLETE, "discard_queues", "deliver_broken"),
    # --- LOST and INCOMPLETE: final; closing them again is harmless.
    (_S.LOST, _I.CLOSE): _t(_S.LOST),
    (_S.LOST, _I.ABORT): _t(_S.LOST),
    (_S.INCOMPLETE, _I.CLOSE): _t(_S.INCOMPLETE),
    (_S.INCOMPLETE, _I.ABORT): _t(_S.INCOMPLETE),
}

TRANSITIONS: Final[Mapping[tuple[ConnState, ConnInput], Transition]] = MappingProxyType(_TABLE)
"""The transition table, read-only."""

ACTION_DOCS: Final[Mapping[str, str]] = MappingProxyType(
    {
        "send_rfc": "allocate the first packet number; send RFC (retransmitted until answered)",
        "take_rfc": "remember the peer; the RFC counts as received and read",
        "deliver_request": "event ConnectionRequested",
        "take_opn": "remember the peer's index; the OPN counts as received and read; take ack, window",
        "send_sts": "send STS (ack = last read, receipt = last received in order, our window)",
        "deliver_opened": "event Opened",
        "discard_queues": "stop retransmitting; forget buffered packets",
        "deliver_closed": "event Closed",
        "deliver_answer": "event Answered",
        "deliver_forward": "event Forwarded",
        "deliver_lost": "event Lost",
        "deliver_broken": "event Broken",
        "deliver_unc": "event UncontrolledReceived",
        "los_not_open": "answer with LOS 'Connection is closed'",
        "send_opn": "send OPN (receipt = RFC's number, our window); transmit window 0 until the first STS",
        "send_refusal": "send CLS with the reason (source index 0)",
        "send_ans": "send ANS with the answer (source index 0)",
        "send_fwd": "send FWD (new host in the ack field, new contact as data)",
        "resend_opn": "duplicate RFC from our peer: send the OPN again if it is not yet receipted",
        "process_ack": "take the ack field: opens the window and receipts",
        "take_sts": "take ack, receipt and window; retransmit what is still unreceipted; first STS: Opened",
        "take_data": "sequence the packet: deliver in order, buffer out of order, STS on duplicates",
        "send_data": "number and send a data packet (window permitting); keep it until receipted",
        "mark_read": "advance the read mark; STS if a third of the window was read or an EOF",
        "start_close": "queue an EOF behind the data (sent when the window allows)",
        "send_cls": "send CLS with our index",
    }
)
"""One line per action name, for the generated documentation."""


def transition(state: ConnState, inp: ConnInput) -> Transition | None:
    """The table entry for ``(state, inp)``, or None when the table has none."""
    return _TABLE.get((state, inp))


def all_actions() -> frozenset[str]:
    """Every action name the table uses."""
    return frozenset(a for t in _TABLE.values() for a in t.actions)
