"""The NCP of one Chaos host, sans I/O: packets and time in, packets and events out.

``Ncp`` owns the connection table and does the part of receive processing that comes before a
connection is known, in this order (each step ends processing when it applies):

1. a packet for another host is dropped (we are a host, not a bridge; destination 0 is accepted);
2. more than 488 data bytes draws LOS "Illegal byte count N (at most 488)"; an opcode outside 001-016
   and 0200-0377 draws LOS "Illegal opcode NNN" (octal).  The links deliver such packets when their
   frame is otherwise sound (erratum ``illegal-packet-delivery``), so this is where they are answered;
3. MNT, RUT and BRD are dropped (a host has no use for them; BRD is not supported);
4. an RFC is matched against live connections by (source host, source index) - a duplicate goes to
   its connection - and otherwise against the listeners by contact name; no listener: CLS refusal;
5. anything else must name a live connection by destination index and come from that connection's
   peer (host and index; while our RFC is outstanding only the host is known).  If none matches, LOS,
   CLS, ANS and FWD are ignored and everything else draws LOS "Connection doesn't exist";
6. the connection's state table does the rest.

The NCP never sends a LOS in answer to a LOS or a CLS.

Connection ids are local indices: the low byte is a slot number (1-255), the high byte a uniquizer
that changes every time an index is handed out, so stale packets for a reused slot do not match.
A finished connection (CLOSED, LOST, INCOMPLETE) keeps its slot, for ``state``/``info``, until the slot
is needed again; slots are handed out round-robin.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import Any, Final

from manip.codecs.packet import MAX_DATA, Packet
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

from .config import MAX_WINDOW, NcpConfig
from .connection import Connection, ConnectionInfo, NcpStats, Outbox, Trigger
from .errors import NoFreeIndexError, UnknownConnectionError
from .events import Event
from .packets import is_legal_opcode, make_los
from .states import FINAL_STATES, ConnInput, ConnState

_SLOTS: Final = 255

_PACKET_INPUTS: Final[Mapping[int, ConnInput]] = MappingProxyType(
    {
        ChaosOp.RFC: ConnInput.RFC,
        ChaosOp.OPN: ConnInput.OPN,
        ChaosOp.CLS: ConnInput.CLS,
        ChaosOp.ANS: ConnInput.ANS,
        ChaosOp.FWD: ConnInput.FWD,
        ChaosOp.SNS: ConnInput.SNS,
        ChaosOp.STS: ConnInput.STS,
        ChaosOp.LOS: ConnInput.LOS,
        ChaosOp.EOF: ConnInput.EOF,
        ChaosOp.UNC: ConnInput.UNC,
    }
)
_NO_LOS_FOR: Final = frozenset({ChaosOp.LOS, ChaosOp.CLS})
_SILENT_IF_UNKNOWN: Final = frozenset({ChaosOp.LOS, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD})
_DROPPED: Final = frozenset({ChaosOp.MNT, ChaosOp.RUT, ChaosOp.BRD})
_RFC_SENT: Final = ConnState.RFC_SENT
_DATA: Final = ConnInput.DATA
_SEND: Final = ConnInput.SEND
_READ: Final = ConnInput.READ
_RFC: Final = int(ChaosOp.RFC)  # plain ints for the per-packet path (enum attribute reads are slow)
_DAT: Final = int(ChaosOp.DAT)


def _check_word(name: str, value: int, low: int = 0) -> None:
    if not low <= value <= 0xFFFF:
        raise ValueError(f"{name} must be in {low}..0xFFFF, not {value!r}")


def _contact_bytes(contact: str) -> bytes:
    raw = contact.encode("ascii")
    if not raw or b" " in raw:
        raise ValueError(f"a contact name is one non-empty word, not {contact!r}")
    return raw


class Ncp:
    """A Chaos NCP for one host address.

    ``config`` holds its settings (:class:`~manip.ncp.config.NcpConfig`, where each is described); a
    setting given by keyword overrides the config's (``Ncp(0o401, window=4)``).  Besides:

    ``uniquizer``            the high byte of the first local index handed out;
    ``first_slot``           the low byte of the first one (1-255; later ones take the next free slot).
    """

    def __init__(
        self,
        address: int,
        *,
        config: NcpConfig | None = None,
        window: int | None = None,
        retransmit_interval: float | None = None,
        probe_interval: float | None = None,
        broken_after: float | None = None,
        rfc_timeout: float | None = None,
        ack_delay: float | None = None,
        auto_read: bool | None = None,
        first_packet_no: int | None = None,
        uniquizer: int = 1,
        first_slot: int = 1,
    ) -> None:
        _check_word("address", address, 1)
        overrides: dict[str, Any] = {
            name: value
            for name, value in (
                ("window", window),
                ("retransmit_interval", retransmit_interval),
                ("probe_interval", probe_interval),
                ("broken_after", broken_after),
                ("rfc_timeout", rfc_timeout),
                ("ack_delay", ack_delay),
                ("auto_read", auto_read),
                ("first_packet_no", first_packet_no),
            )
            if value is not None
        }
        if not 0 <= uniquizer <= 0xFF:
            raise ValueError(f"uniquizer must be a byte, not {uniquizer!r}")
        if not 1 <= first_slot <= _SLOTS:
            raise ValueError(f"first_slot must be 1-{_SLOTS}, not {first_slot!r}")
        self._address = address
        self._config = replace(config or NcpConfig(), **overrides)  # NcpConfig checks every value
        self._first_packet_no = self._config.first_packet_no
        self._defects = self._config.defects
        self._uniquizer = uniquizer
        self._next_slot = first_slot
        self._slots: list[Connection | None] = [None] * (_SLOTS + 1)
        self._live: dict[int, Connection] = {}
        self._by_peer: dict[tuple[int, int], Connection] = {}
        self._listeners: set[bytes] = set()
        self._out = Outbox()

    # ------------------------------------------------------------------ properties

    @property
    def address(self) -> int:
        return self._address

    @property
    def config(self) -> NcpConfig:
        return self._config

    @property
    def stats(self) -> NcpStats:
        return self._out.stats

    # ------------------------------------------------------------------ listening and connecting

    def listen(self, contact: str) -> None:
        """Accept RFCs for ``contact`` from now on: each one becomes a ConnectionRequested event."""
        self._listeners.add(_contact_bytes(contact))

    def unlisten(self, contact: str) -> None:
        """Stop listening for ``contact`` (later RFCs for it are refused)."""
        self._listeners.discard(_contact_bytes(contact))

    def connect(
        self,
        now: float,
        host: int,
        contact: str,
        args: bytes | str = b"",
        *,
        window: int | None = None,
        first_packet_no: int | None = None,
    ) -> int:
        """Send an RFC for ``contact`` (with ``args``) to ``host``; return the new connection's id."""
        _check_word("host", host, 1)
        raw_args = args.encode("latin-1") if isinstance(args, str) else bytes(args)
        data = _contact_bytes(contact) + (b" " + raw_args if raw_args else b"")
        if len(data) > MAX_DATA:
            raise ValueError(f"RFC data is {len(data)} bytes, more than {MAX_DATA}")
        first = self._first(first_packet_no)
        conn = self._allocate(now, window)
        self._handle(conn, ConnInput.CONNECT, Trigger(now, data=data, host=host, packet_no=first))
        return conn.index

    def accept(
        self, now: float, conn_id: int, *, window: int | None = None, first_packet_no: int | None = None
    ) -> None:
        """Open a requested connection: send OPN.  The peer's STS then brings an Opened event."""
        conn = self._conn(conn_id)
        first = self._first(first_packet_no)
        if window is not None and conn.state is ConnState.RFC_RECEIVED:
            self._check_window(window)
            conn.rwsize = window
        self._handle(conn, ConnInput.ACCEPT, Trigger(now, packet_no=first))

    def refuse(self, now: float, conn_id: int, reason: str = "") -> None:
        """Refuse a requested connection with CLS."""
        self._handle(self._conn(conn_id), ConnInput.REFUSE, Trigger(now, data=_reason(reason)))

    def answer(self, now: float, conn_id: int, data: bytes) -> None:
        """Answer a requested connection with one ANS packet instead of opening it."""
        if len(data) > MAX_DATA:
            raise ValueError(f"ANS data is {len(data)} bytes, more than {MAX_DATA}")
        self._handle(self._conn(conn_id), ConnInput.ANSWER, Trigger(now, data=bytes(data)))

    def forward(self, now: float, conn_id: int, host: int, contact: str) -> None:
        """Tell the requester to try ``contact`` at ``host`` instead (FWD)."""
        _check_word("host", host, 1)
        data = _contact_bytes(contact)
        self._handle(self._conn(conn_id), ConnInput.FORWARD, Trigger(now, data=data, host=host))

    # ------------------------------------------------------------------ data

    def send(self, now: float, conn_id: int, data: bytes = b"", *, opcode: int = ChaosOp.DAT) -> int:
        """Send one data packet; return the packet number it was given.

        Raises WindowFullError when the peer's window is full or not yet known (check :meth:`can_send`
        first) and InvalidStateError when the connection is not open or is closing."""
        if not _DAT <= opcode <= 0o377:
            raise ValueError(f"data opcodes are 0200-0377, not {octal(opcode)}")
        if len(data) > MAX_DATA:
            raise ValueError(f"data is {len(data)} bytes, more than {MAX_DATA}")
        conn = self._conn(conn_id)
        self._handle(conn, _SEND, Trigger(now, None, bytes(data), opcode))
        return conn.tlast

    def can_send(self, conn_id: int) -> bool:
        """Whether :meth:`send` would accept a packet now (open, established, window not full)."""
        return self.window_space(conn_id) > 0

    def window_space(self, conn_id: int) -> int:
        """How many more packets may be sent before an acknowledgement arrives."""
        return self._conn(conn_id).window_space()

    def read_ack(self, now: float, conn_id: int, packet_no: int) -> None:
        """Mark every delivered packet up to ``packet_no`` as read (needed only without ``auto_read``)."""
        self._handle(self._conn(conn_id), _READ, Trigger(now, None, b"", 0, 0, packet_no))

    def close(self, now: float, conn_id: int) -> None:
        """Close gracefully: EOF after the data; CLS once the peer acknowledges the EOF; event Closed.

        On a connection that is not open yet this refuses (received RFC) or forgets it (sent RFC)."""
        self._handle(self._conn(conn_id), ConnInput.CLOSE, Trigger(now))

    def abort(self, now: float, conn_id: int, reason: str = "") -> None:
        """Close at once with CLS ``reason``; unacknowledged data may be lost.  No event follows."""
        self._handle(self._conn(conn_id), ConnInput.ABORT, Trigger(now, data=_reason(reason)))

    # ------------------------------------------------------------------ the network side

    def receive(self, now: float, packet: Packet) -> None:
        """Process one packet from the network."""
        out = self._out
        out.stats.packets_received += 1
        if packet.dest_host not in (self._address, 0):
            out.stats.dropped += 1
            return
        opcode = packet.opcode
        defects = self._defects
        if len(packet.data) > MAX_DATA and defects.bounds_data:
            self._illegal(now, packet, f"Illegal byte count {len(packet.data)} (at most {MAX_DATA})")
            return
        data = _DAT <= opcode <= 0o377
        if not data:
            if not is_legal_opcode(opcode):
                if defects.los_illegal_opcode:
                    # The wire text of erratum illegal-packet-delivery: three octal digits.
                    self._illegal(now, packet, f"Illegal opcode {opcode:03o}")
                return
            if opcode in _DROPPED:
                out.stats.dropped += 1
                return
            if opcode == _RFC:
                self._take_rfc(now, packet)
                return
        conn = self._live.get(packet.dest_index)  # self._find(packet), inlined: every packet comes here
        if conn is not None and (
            packet.src_host != conn.peer_host
            or (packet.src_index != conn.peer_index and conn.state is not _RFC_SENT)
        ):
            conn = None
        if conn is None:
            if opcode not in _SILENT_IF_UNKNOWN and defects.los_unknown_connection:
                self._los(packet, "Connection doesn't exist")
            return
        conn.last_heard = now
        inp = _DATA if data else _PACKET_INPUTS.get(opcode)
        if inp is None:  # LSN from the network: nothing to do with it
            return
        self._handle(conn, inp, Trigger(now, packet))

    def timer(self, now: float) -> None:
        """Let time pass: retransmissions, probes, delayed STS, timeouts."""
        for conn in list(self._live.values()):
            conn.timer(now)
            self._settle(conn)

    def next_deadline(self) -> float | None:
        """The earliest time at which :meth:`timer` has work, or None if it has none."""
        deadlines = [d for c in self._live.values() if (d := c.deadline()) is not None]
        return min(deadlines) if deadlines else None

    def packets_to_send(self) -> list[Packet]:
        """Take the packets produced so far, in order."""
        packets = self._out.packets
        self._out.packets = []
        return packets

    def next_event(self) -> Event | None:
        """Take the oldest pending event, or None."""
        events = self._out.events
        return events.popleft() if events else None

    def events(self) -> list[Event]:
        """Take all pending events, oldest first."""
        events = list(self._out.events)
        self._out.events.clear()
        return events

    # ------------------------------------------------------------------ introspection

    def state(self, conn_id: int) -> ConnState:
        return self._conn(conn_id).state

    def info(self, conn_id: int) -> ConnectionInfo:
        return self._conn(conn_id).info()

    def connections(self) -> list[int]:
        """Ids of the connections that are not finished."""
        return sorted(self._live)

    # ------------------------------------------------------------------ internals

    @staticmethod
    def _check_window(window: int) -> None:
        if not 1 <= window <= MAX_WINDOW:
            raise ValueError(f"window must be in 1..16384, not {window!r}")

    def _first(self, first_packet_no: int | None) -> int:
        if first_packet_no is None:
            return self._first_packet_no
        _check_word("first_packet_no", first_packet_no)
        return first_packet_no

    def _conn(self, conn_id: int) -> Connection:
        conn = self._slots[conn_id & 0xFF] if 0 <= conn_id <= 0xFFFF else None
        if conn is None or conn.index != conn_id:
            raise UnknownConnectionError(conn_id)
        return conn

    def _allocate(self, now: float, window: int | None) -> Connection:
        if window is not None:
            self._check_window(window)
        for k in range(_SLOTS):
            slot = (self._next_slot - 1 + k) % _SLOTS + 1
            old = self._slots[slot]
            if old is None or old.finished:
                index = (self._uniquizer << 8) | slot
                self._uniquizer = (self._uniquizer + 1) & 0xFF
                self._next_slot = slot % _SLOTS + 1
                conn = Connection(
                    index=index, address=self._address, config=self._config, outbox=self._out, now=now
                )
                if window is not None:
                    conn.rwsize = window
                self._slots[slot] = conn
                self._live[index] = conn
                return conn
        raise NoFreeIndexError(f"all {_SLOTS} connection slots are in use")

    def _handle(self, conn: Connection, inp: ConnInput, trig: Trigger) -> None:
        try:
            conn.handle(inp, trig)
        finally:
            if conn.state in FINAL_STATES:
                self._settle(conn)

    def _settle(self, conn: Connection) -> None:
        if conn.state in FINAL_STATES:
            self._live.pop(conn.index, None)
            key = (conn.peer_host, conn.peer_index)
            if self._by_peer.get(key) is conn:
                del self._by_peer[key]

    def _take_rfc(self, now: float, packet: Packet) -> None:
        key = (packet.src_host, packet.src_index)
        existing = self._by_peer.get(key) if self._defects.recognises_duplicate_rfc else None
        if existing is not None and not existing.finished:
            existing.last_heard = now
            self._handle(existing, ConnInput.RFC, Trigger(now, packet))
            return
        contact = packet.data.partition(b" ")[0]
        if contact not in self._listeners:
            self._refuse_unknown(packet, "No server for this contact name")
            return
        try:
            conn = self._allocate(now, None)
        except NoFreeIndexError:
            self._refuse_unknown(packet, "No free connection")
            return
        self._handle(conn, ConnInput.LISTEN, Trigger(now))
        self._handle(conn, ConnInput.RFC, Trigger(now, packet))
        self._by_peer[key] = conn

    def _refuse_unknown(self, rfc: Packet, reason: str) -> None:
        self._out.packet(
            Packet(
                opcode=ChaosOp.CLS,
                dest_host=rfc.src_host,
                dest_index=rfc.src_index,
                src_host=self._address,
                src_index=0,
                data=_reason(reason),
            )
        )

    def _illegal(self, now: float, packet: Packet, reason: str) -> None:
        """An illegal packet: LOS; and with ``lose_on_illegal``, the connection it names is given up."""
        self._los(packet, reason)
        if not self._config.lose_on_illegal or packet.opcode in _NO_LOS_FOR:
            return
        conn = self._live.get(packet.dest_index)
        if conn is None or packet.src_host != conn.peer_host or packet.src_index != conn.peer_index:
            return
        gave_up = replace(
            packet, opcode=ChaosOp.LOS, data=_reason(f"given up: the peer sent an illegal packet ({reason})")
        )
        self._handle(conn, ConnInput.LOS, Trigger(now, gave_up))

    def _los(self, packet: Packet, reason: str) -> None:
        if packet.opcode in _NO_LOS_FOR:
            self._out.stats.dropped += 1
            return
        self._out.packet(make_los(packet, self._address, reason))
        self._out.stats.los_sent += 1


def _reason(reason: str) -> bytes:
    data = reason.encode("latin-1")
    if len(data) > MAX_DATA:
        raise ValueError(f"reason is {len(data)} bytes, more than {MAX_DATA}")
    return data
