"""One Chaos connection: its state, its two packet-number sequences, its queues and its timers.

The state logic is the table in :mod:`manip.ncp.states`; this module implements each action the table
names (methods decorated with ``@_action``) and the bookkeeping that does not change the state.  At
import the table is copied into ``_PLAN`` with every action name resolved to its method, so running a
transition is one dictionary lookup (states and inputs hash by identity) and a few direct calls.

Bookkeeping, per direction (all numbers modulo 2^16, see :mod:`manip.ncp.seq`):

Transmit side
    ``tlast``      number of the last controlled packet we sent (RFC/OPN, then data and EOF);
    ``tacked``     highest number the peer acknowledged (the ack field): the window starts here;
    ``receipted``  highest number the peer receipted (ack field or STS receipt): retransmission stops;
    ``twsize``     the peer's receive window, from OPN or STS.  We may send while
                   ``tlast - tacked < twsize``.  RFC and OPN go out before any window is known and
                   are not counted: ``tacked`` starts equal to their number.
    ``queue``      sent, unreceipted controlled packets, oldest first, each with the time it was last
                   sent.  A packet is sent again when it has waited ``retransmit_interval`` and, after an
                   STS, when it has waited at least a fifth of that.

Receive side
    ``rlast``      highest number received in order (what our STS calls the receipt);
    ``rread``      highest number the user has read (what our ack field says);
    ``racked``     the ack we last told the peer; ``receipt_told`` the highest receipt it has from us;
    ``rwsize``     our receive window; packets beyond ``rread + rwsize`` are dropped;
    ``ooo``        packets received out of order, waiting for the gap to fill.

When a packet counts as read: with ``auto_read`` (the default) when the NCP delivers it in order, i.e.
when it queues the DataReceived or EofReceived event; otherwise when the user calls ``read_ack`` with its
number (or a later one).  The RFC and the OPN count as read on arrival.  STS goes out: in answer to SNS,
OPN and every duplicate; as soon as an EOF is read; when more than a third of the receive window has been
read but not yet acknowledged; and otherwise ``ack_delay`` after anything new was received or read, unless
an outgoing packet carried the news first (every controlled packet, SNS and STS carries the current ack).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, NamedTuple

from manip.codecs.packet import Packet, make_packet
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

from .config import MAX_WINDOW, NcpConfig
from .errors import InvalidStateError, WindowFullError
from .events import (
    Answered,
    Broken,
    Closed,
    ConnectionRequested,
    DataReceived,
    EofReceived,
    Event,
    Forwarded,
    Lost,
    Opened,
    UncontrolledReceived,
)
from .packets import make_los, pack_status, text, unpack_status
from .seq import seq_add, seq_le, seq_lt, seq_sub
from .states import FINAL_STATES, TRANSITIONS, ConnInput, ConnState, InputSource

# Module-level aliases: reading an attribute of an enum class is several times slower than reading a
# global, and these are read on every packet's path.
_EOF: Final = int(ChaosOp.EOF)
_OPEN: Final = ConnState.OPEN
_RFC_SENT: Final = ConnState.RFC_SENT
_RFC_RECEIVED: Final = ConnState.RFC_RECEIVED

Config = NcpConfig
"""The NCP's settings as a connection reads them (:class:`manip.ncp.config.NcpConfig`)."""


@dataclass(slots=True)
class NcpStats:
    """Counters, for tests and for the curious."""

    packets_sent: int = 0
    retransmissions: int = 0
    packets_received: int = 0
    duplicates_received: int = 0
    delivered: int = 0
    los_sent: int = 0
    dropped: int = 0


class Outbox:
    """Where connections put what they produce; the ``Ncp`` drains it."""

    __slots__ = ("events", "packets", "stats")

    def __init__(self) -> None:
        self.packets: list[Packet] = []
        self.events: deque[Event] = deque()
        self.stats = NcpStats()

    def packet(self, packet: Packet) -> None:
        self.packets.append(packet)
        self.stats.packets_sent += 1

    def event(self, event: Event) -> None:
        self.events.append(event)


class Trigger(NamedTuple):
    """The arguments of one input: when it happens and whatever it carries.

    ``data`` is the user's data or reason text; ``packet_no`` the first packet number (connect, accept)
    or the packet read (read_ack); ``host`` the host to connect or forward to.  (A named tuple: one is
    built for every input, and this is the cheapest immutable record to build.)"""

    now: float
    packet: Packet | None = None
    data: bytes = b""
    opcode: int = 0
    host: int = 0
    packet_no: int = 0


@dataclass(frozen=True, slots=True)
class ConnectionInfo:
    """A snapshot of one connection's bookkeeping (see the module docstring for the names)."""

    conn_id: int
    state: ConnState
    peer_host: int
    peer_index: int
    established: bool
    closing: bool
    send_window: int
    outstanding: int
    unreceipted: int
    last_sent: int
    last_acked: int
    last_receipted: int
    receive_window: int
    last_received: int
    last_read: int
    buffered: int


@dataclass(slots=True)
class _Sent:
    packet: Packet
    sent_at: float


_ActionFn = Callable[["Connection", Trigger], None]
_ACTIONS: dict[str, _ActionFn] = {}


def _action(fn: _ActionFn) -> _ActionFn:
    """Register a method as the implementation of the table action of the same name (minus ``_a_``)."""
    _ACTIONS[fn.__name__.removeprefix("_a_")] = fn
    return fn


def implemented_actions() -> frozenset[str]:
    """The action names this module implements (a test checks they match the table's)."""
    return frozenset(_ACTIONS)


class Connection:
    """One connection.  Created and driven by :class:`manip.ncp.node.Ncp`; not for direct use."""

    def __init__(self, *, index: int, address: int, config: Config, outbox: Outbox, now: float) -> None:
        self.index = index
        self.address = address
        self.config = config
        self.out = outbox
        self.state = ConnState.CLOSED
        self.peer_host = 0
        self.peer_index = 0
        self.rfc: Packet | None = None
        # Transmit side.
        self.tlast = 0
        self.tacked = 0
        self.receipted = 0
        self.twsize = 0
        self.queue: deque[_Sent] = deque()
        self.established = False
        self.closing = False
        self.eof_no: int | None = None
        # Receive side.
        self.rlast = 0
        self.rread = 0
        self.racked = 0
        self.receipt_told = 0
        self.rwsize = config.window
        self.ooo: dict[int, Packet] = {}
        self.peer_eof: int | None = None
        # Timers.
        self.started_at = now
        self.last_heard = now
        self.probe_at = now + config.probe_interval
        self.ack_due: float | None = None

    # ------------------------------------------------------------------ driving

    def handle(self, inp: ConnInput, trig: Trigger) -> bool:
        """Run the table's transition for ``inp``.  False if the table has none (packet ignored)."""
        plan = _PLAN.get((self.state, inp))
        if plan is None:
            if inp.source is InputSource.USER:
                raise InvalidStateError(
                    f"connection {octal(self.index)}: {inp.name} is not allowed in {self.state.name}"
                )
            return False
        actions, next_state = plan
        for action in actions:
            action(self, trig)
        self.state = next_state
        if self.closing:
            self._after(trig.now)
        return True

    def timer(self, now: float) -> None:
        """Retransmit, probe, send a delayed STS or time the connection out, as due at ``now``."""
        cfg = self.config
        state = self.state
        if state is _RFC_SENT:
            if now >= self.started_at + cfg.rfc_timeout:
                self.handle(ConnInput.RFC_TIMEOUT, Trigger(now, data=b"Host not responding"))
                return
            self._retransmit(now, cfg.retransmit_interval)
        elif state is _RFC_RECEIVED:
            if now >= self.started_at + cfg.rfc_timeout:
                self.handle(ConnInput.UNANSWERED, Trigger(now, data=b"Timeout"))
        elif state is _OPEN:
            if now >= self.last_heard + cfg.broken_after and cfg.defects.gives_up_silent_peer:
                reason = f"No packet from the peer for {cfg.broken_after:g} s"
                self.handle(ConnInput.SILENCE, Trigger(now, data=reason.encode()))
                return
            self._retransmit(now, cfg.retransmit_interval)
            if self.ack_due is not None and now >= self.ack_due:
                self.ack_due = None
                if self._sts_wanted():
                    self._send_sts()
            if now >= self.probe_at:
                if self._probe_wanted(now):
                    self._send_sns()
                step = cfg.probe_interval if self.established else cfg.retransmit_interval
                self.probe_at = now + step

    def deadline(self) -> float | None:
        """When :meth:`timer` next has something to do (None: never, the connection is idle for good)."""
        cfg = self.config
        state = self.state
        if state is _RFC_SENT:
            return min(self.started_at + cfg.rfc_timeout, self._retransmit_deadline())
        if state is _RFC_RECEIVED:
            return self.started_at + cfg.rfc_timeout
        if state is _OPEN:
            silence = self.last_heard + cfg.broken_after if cfg.defects.gives_up_silent_peer else math.inf
            due = min(silence, self.probe_at, self._retransmit_deadline())
            if self.ack_due is not None:
                due = min(due, self.ack_due)
            return due
        return None

    # ------------------------------------------------------------------ queries

    @property
    def outstanding(self) -> int:
        """Controlled packets sent but not yet acknowledged (what the window limits)."""
        return seq_sub(self.tlast, self.tacked)

    def window_space(self) -> int:
        if self.state is not _OPEN or self.closing or not self.established:
            return 0
        return max(0, self.twsize - ((self.tlast - self.tacked) & 0xFFFF))  # twsize - outstanding

    def info(self) -> ConnectionInfo:
        return ConnectionInfo(
            conn_id=self.index,
            state=self.state,
            peer_host=self.peer_host,
            peer_index=self.peer_index,
            established=self.established,
            closing=self.closing,
            send_window=self.twsize,
            outstanding=self.outstanding,
            unreceipted=len(self.queue),
            last_sent=self.tlast,
            last_acked=self.tacked,
            last_receipted=self.receipted,
            receive_window=self.rwsize,
            last_received=self.rlast,
            last_read=self.rread,
            buffered=len(self.ooo),
        )

    # ------------------------------------------------------------------ packet building

    def _packet(self, opcode: int, *, packet_no: int = 0, ack_no: int = 0, data: bytes = b"") -> Packet:
        return make_packet(
            opcode, self.peer_host, self.peer_index, self.address, self.index, packet_no, ack_no, data
        )

    def _told_ack(self) -> int:
        """Note that the packet being built carries the current ack; return it."""
        rread = self.racked = self.rread
        if (self.receipt_told - rread) & 0x8000:  # seq_gt(rread, receipt_told)
            self.receipt_told = rread
        return rread

    def _start_sequence(self, first: int) -> None:
        self.tlast = first & 0xFFFF
        self.tacked = self.tlast
        self.receipted = seq_add(self.tlast, -1)
        self.twsize = 0

    def _send_controlled(self, now: float, opcode: int, data: bytes) -> int:
        number = (self.tlast + self.config.defects.packet_number_step) & 0xFFFF
        packet = make_packet(
            opcode, self.peer_host, self.peer_index, self.address, self.index, number, self._told_ack(), data
        )
        self.tlast = number
        self.queue.append(_Sent(packet, now))
        self.out.packet(packet)
        return number

    def _send_sts(self) -> None:
        ack = self._told_ack()
        self.receipt_told = self.rlast
        self.ack_due = None
        self.out.packet(
            self._packet(
                ChaosOp.STS,
                packet_no=seq_add(self.tlast, 1),
                ack_no=ack,
                data=pack_status(self.rlast, self.rwsize),
            )
        )

    def _send_sns(self) -> None:
        self.out.packet(self._packet(ChaosOp.SNS, packet_no=seq_add(self.tlast, 1), ack_no=self._told_ack()))

    # ------------------------------------------------------------------ transmit bookkeeping

    # The methods below run for every packet, so they compare packet numbers inline rather than through
    # manip.ncp.seq: all the numbers kept here are already reduced to 16 bits, so ``a`` comes before
    # ``b`` exactly when ``(a - b) & 0x8000`` (seq_lt), and seq_le(a, b) is ``a == b or seq_lt(a, b)``.

    def _take_ack(self, ack: int) -> None:
        tlast = self.tlast
        if (self.tacked - ack) & 0x8000 and (ack == tlast or (ack - tlast) & 0x8000):
            self.tacked = ack
        self._take_receipt(ack)

    def _take_receipt(self, receipt: int) -> None:
        tlast = self.tlast
        if (self.receipted - receipt) & 0x8000 and (receipt == tlast or (receipt - tlast) & 0x8000):
            self.receipted = receipt
            queue = self.queue
            while queue:
                number = queue[0].packet.packet_no
                if number != receipt and not (number - receipt) & 0x8000:
                    break
                queue.popleft()

    def _retransmit_deadline(self) -> float:
        if not self.queue or not self.config.defects.retransmits:
            return float("inf")
        return min(s.sent_at for s in self.queue) + self.config.retransmit_interval

    def _retransmit(self, now: float, min_age: float) -> None:
        if not self.config.defects.retransmits:
            return
        for sent in self.queue:
            if now >= sent.sent_at + min_age:
                packet = sent.packet
                if packet.opcode != ChaosOp.RFC and packet.ack_no != self.rread:
                    packet = packet.with_(ack_no=self.rread)
                    sent.packet = packet
                if packet.opcode != ChaosOp.RFC:
                    self._told_ack()
                sent.sent_at = now
                self.out.packet(packet)
                self.out.stats.retransmissions += 1

    def _probe_wanted(self, now: float) -> bool:
        return (
            self.outstanding > 0 or self.twsize == 0 or now >= self.last_heard + self.config.idle_probe_after
        )

    def _after(self, now: float) -> None:
        """Consequences of an input that the table does not spell out: the EOF of a close."""
        if self.state is not _OPEN or not self.closing:
            return
        if self.eof_no is None:
            if self.peer_eof is not None:  # the peer closes too: no EOF of ours (see states.py)
                if self.outstanding == 0:
                    self.handle(ConnInput.PEER_FINISHED, Trigger(now))
            elif self.established and self.outstanding < self.twsize:
                self.eof_no = self._send_controlled(now, ChaosOp.EOF, b"")
        elif self.tacked == self.eof_no:
            self.handle(ConnInput.EOF_ACKED, Trigger(now))

    # ------------------------------------------------------------------ receive bookkeeping

    def _sts_wanted(self) -> bool:
        return self.racked != self.rread or self.receipt_told != self.rlast

    def _deliver(self, packet: Packet) -> None:
        self.rlast = packet.packet_no
        self.out.stats.delivered += 1
        if packet.opcode == _EOF:
            self.peer_eof = packet.packet_no
            self.out.event(EofReceived(self.index, packet))
        else:
            self.out.event(DataReceived(self.index, packet))

    def _read_up_to(self, now: float, number: int) -> None:
        self.rread = number
        eof = self.peer_eof
        eof_read = eof is not None and seq_le(eof, number) and seq_lt(self.racked, eof)
        if eof_read or 3 * ((number - self.racked) & 0xFFFF) > self.rwsize:
            self._send_sts()
        elif self.ack_due is None:
            self.ack_due = now + self.config.ack_delay

    # ------------------------------------------------------------------ actions named by the table

    @_action
    def _a_send_rfc(self, t: Trigger) -> None:
        self.peer_host = t.host
        self.peer_index = 0
        self._start_sequence(t.packet_no)
        self.started_at = t.now
        packet = self._packet(ChaosOp.RFC, packet_no=self.tlast, ack_no=0, data=t.data)
        self.queue.append(_Sent(packet, t.now))
        self.out.packet(packet)

    @_action
    def _a_take_rfc(self, t: Trigger) -> None:
        p = _need(t)
        self.peer_host = p.src_host
        self.peer_index = p.src_index
        self.rfc = p
        self.rlast = self.rread = p.packet_no
        self.racked = self.receipt_told = seq_add(p.packet_no, -1)
        self.started_at = self.last_heard = t.now

    @_action
    def _a_deliver_request(self, t: Trigger) -> None:
        p = _need(t)
        contact, _, args = p.data.partition(b" ")
        self.out.event(ConnectionRequested(self.index, p.src_host, p.src_index, text(contact), args, p))

    @_action
    def _a_take_opn(self, t: Trigger) -> None:
        p = _need(t)
        self.peer_index = p.src_index
        self.rlast = self.rread = p.packet_no
        self.racked = self.receipt_told = seq_add(p.packet_no, -1)
        self._take_ack(p.ack_no)
        status = unpack_status(p.data)
        if status is not None:
            receipt, window = status
            self._take_receipt(receipt)
            self.twsize = min(window, MAX_WINDOW)
        self.established = True
        self.probe_at = t.now + self.config.probe_interval

    @_action
    def _a_send_sts(self, t: Trigger) -> None:
        self._send_sts()

    @_action
    def _a_deliver_opened(self, t: Trigger) -> None:
        self.out.event(Opened(self.index, self.peer_host, self.peer_index, self.twsize))

    @_action
    def _a_discard_queues(self, t: Trigger) -> None:
        self.queue.clear()
        self.ooo.clear()
        self.ack_due = None

    @_action
    def _a_deliver_closed(self, t: Trigger) -> None:
        if t.packet is not None:
            self.out.event(Closed(self.index, text(t.packet.data), by_peer=True))
        else:
            self.out.event(Closed(self.index, text(t.data), by_peer=False))

    @_action
    def _a_deliver_answer(self, t: Trigger) -> None:
        p = _need(t)
        self.out.event(Answered(self.index, p.data, p))

    @_action
    def _a_deliver_forward(self, t: Trigger) -> None:
        p = _need(t)
        self.out.event(Forwarded(self.index, p.ack_no, text(p.data), p))

    @_action
    def _a_deliver_lost(self, t: Trigger) -> None:
        p = _need(t)
        self.out.event(Lost(self.index, text(p.data), p))

    @_action
    def _a_deliver_broken(self, t: Trigger) -> None:
        self.out.event(Broken(self.index, text(t.data)))

    @_action
    def _a_deliver_unc(self, t: Trigger) -> None:
        self.out.event(UncontrolledReceived(self.index, _need(t)))

    @_action
    def _a_los_not_open(self, t: Trigger) -> None:
        self.out.packet(make_los(_need(t), self.address, "Connection is closed"))
        self.out.stats.los_sent += 1

    @_action
    def _a_send_opn(self, t: Trigger) -> None:
        self._start_sequence(t.packet_no)
        self.established = False
        packet = self._packet(
            ChaosOp.OPN,
            packet_no=self.tlast,
            ack_no=self._told_ack(),
            data=pack_status(self.rlast, self.rwsize),
        )
        self.receipt_told = self.rlast
        self.queue.append(_Sent(packet, t.now))
        self.out.packet(packet)
        self.last_heard = t.now
        self.probe_at = t.now + self.config.retransmit_interval

    @_action
    def _a_send_refusal(self, t: Trigger) -> None:
        self.out.packet(self._packet(ChaosOp.CLS, data=t.data).with_(src_index=0))

    @_action
    def _a_send_ans(self, t: Trigger) -> None:
        self.out.packet(self._packet(ChaosOp.ANS, data=t.data).with_(src_index=0))

    @_action
    def _a_send_fwd(self, t: Trigger) -> None:
        self.out.packet(self._packet(ChaosOp.FWD, ack_no=t.host, data=t.data).with_(src_index=0))

    @_action
    def _a_resend_opn(self, t: Trigger) -> None:
        for sent in self.queue:
            if sent.packet.opcode == ChaosOp.OPN:
                sent.sent_at = t.now
                self.out.packet(sent.packet)
                self.out.stats.retransmissions += 1

    @_action
    def _a_process_ack(self, t: Trigger) -> None:
        p = t.packet  # _need(t), inlined: this runs for every packet
        if p is None:  # pragma: no cover - the table only routes packet inputs here
            raise AssertionError("this action needs a packet")
        self._take_ack(p.ack_no)

    @_action
    def _a_take_sts(self, t: Trigger) -> None:
        p = _need(t)
        self._take_ack(p.ack_no)
        status = unpack_status(p.data)
        if status is None:
            return
        receipt, window = status
        self._take_receipt(receipt)
        self.twsize = min(window, MAX_WINDOW)
        self._retransmit(t.now, self.config.retransmit_guard)
        if not self.established:
            self.established = True
            self.probe_at = t.now + self.config.probe_interval
            self.out.event(Opened(self.index, self.peer_host, self.peer_index, self.twsize))

    @_action
    def _a_take_data(self, t: Trigger) -> None:
        p = t.packet  # _need(t), inlined: this runs for every data packet
        if p is None:  # pragma: no cover - the table only routes packet inputs here
            raise AssertionError("this action needs a packet")
        number = p.packet_no
        rlast = self.rlast
        if number == rlast or (number - rlast) & 0x8000 or number in self.ooo:  # seq_le(number, rlast)
            self.out.stats.duplicates_received += 1
            self._send_sts()
            return
        if (number - self.rread) & 0xFFFF > self.rwsize:
            return  # beyond our window: the sender broke the rules, or it is very old
        if number != (rlast + 1) & 0xFFFF:
            self.ooo[number] = p
            return
        self._deliver(p)
        ooo = self.ooo
        while ooo:
            following = ooo.pop(seq_add(self.rlast, 1), None)
            if following is None:
                break
            self._deliver(following)
        if self.config.auto_read:
            self._read_up_to(t.now, self.rlast)
        elif self.ack_due is None:
            self.ack_due = t.now + self.config.ack_delay

    @_action
    def _a_send_data(self, t: Trigger) -> None:
        if self.closing:
            raise InvalidStateError(f"connection {octal(self.index)} is closing: no more data")
        if not self.established or (self.tlast - self.tacked) & 0xFFFF >= self.twsize:  # outstanding
            raise WindowFullError(
                f"connection {octal(self.index)}: {self.outstanding} packets unacknowledged, "
                f"peer window {self.twsize}"
            )
        self._send_controlled(t.now, t.opcode, t.data)

    @_action
    def _a_mark_read(self, t: Trigger) -> None:
        number = t.packet_no & 0xFFFF
        if (self.rlast - number) & 0x8000:  # seq_gt(number, rlast)
            raise InvalidStateError(
                f"connection {octal(self.index)}: packet {number} has not been delivered (last {self.rlast})"
            )
        rread = self.rread
        if number == rread or (number - rread) & 0x8000:  # seq_le(number, rread)
            return
        self._read_up_to(t.now, number)

    @_action
    def _a_start_close(self, t: Trigger) -> None:
        self.closing = True

    @_action
    def _a_send_cls(self, t: Trigger) -> None:
        self.out.packet(self._packet(ChaosOp.CLS, data=t.data))

    @property
    def finished(self) -> bool:
        return self.state in FINAL_STATES


_PLAN: Final[dict[tuple[ConnState, ConnInput], tuple[tuple[_ActionFn, ...], ConnState]]] = {
    key: (tuple(_ACTIONS[name] for name in tr.actions), tr.next_state) for key, tr in TRANSITIONS.items()
}
"""The table with each action name resolved to its method, so running a transition does no name lookups."""


def _need(t: Trigger) -> Packet:
    if t.packet is None:  # pragma: no cover - the table only routes packet inputs here
        raise AssertionError("this action needs a packet")
    return t.packet
