"""The Chaos NCP transport: a :class:`~manip.reference_client.transport.ManipTransport` over a
:class:`manip.links.ChaosConnection` (TCP link, CHUDP or chaosd, whatever the address names).

Theory of operation
-------------------
* ``set_up_communications`` opens the connection (RFC to the address's contact, or ``contact``),
  with ``wrap_link`` (a recording tap, :class:`manip.captures.RecorderTap`) between node and link;
  a refusal, a timeout or a link failure becomes :class:`~manip.reference_client.errors.ConnectionLostError`
  with the links' :class:`~manip.links.ChaosError` as its ``__cause__``.
* ``send_user_request`` sends the request's opcode and data as one data packet and sets
  ``request.packet_number`` to the number the NCP gave it (the number the reply will carry).
  ``may_transmit`` is the connection's ``can_send``: the send window has room.
* Packets are read with ``receive_nowait``, one packet of lookahead: ``response_available`` fetches
  the next packet (taking it acknowledges it, erratum ``links-read-on-take``) and ``get_next_packet``
  hands it over as a :class:`~manip.reference_client.packets.ServerPacket` with the Chaos opcode,
  packet number, ack number and data.  Packets buffered before the connection ended stay readable.
* The connection's wake-up drives the background process: a packet arrived, the window opened or the
  connection ended.
* The end of the connection (the server's EOF, CLS, LOS, a broken link) is read like a packet: from
  then on ``connection_open`` is false and ``handle_closed_connection`` says why; ``close_cause`` is
  the ChaosError.
* ``disconnect`` is idempotent: a graceful close (our EOF, then CLS once the server acknowledges it,
  bounded by ``close_timeout``), or an abort (CLS at once) after the server sent a fatal error (0201)
  or when :meth:`NcpTransport.abort` was called.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from manip.codecs.packet import Packet
from manip.links import (
    ChaosConnection,
    ChaosError,
    ConnectionBroken,
    ConnectionClosed,
    Link,
    LinkAddress,
    NcpConfig,
    open_connection,
    parse_address,
)
from manip.links import ConnectionLost as ChaosConnectionLost
from manip.links.api import LinkWrapper
from manip.ncp.config import MAX_WINDOW
from manip.ncp.packets import pack_status, unpack_status
from manip.ncp.seq import seq_gt
from manip.reference_client.errors import ConnectionLostError
from manip.reference_client.faults import NO_FAULTS, ClientFault, ClientFaults
from manip.reference_client.packets import ResponseInfo, ServerPacket, chaos_response_info
from manip.reference_client.request import Request
from manip.spec.constants import ChaosOp, ServerOp

DEFAULT_CLOSE_TIMEOUT = 2.0
"""Seconds a graceful close waits for the server to acknowledge our EOF before aborting."""


def describe_chaos_end(error: ChaosError) -> str:
    """How a links error reads in a ConnectionLostError: who ended the connection and why."""
    reason = error.reason or type(error).__name__
    if isinstance(error, ConnectionClosed):
        return f"closed by the server ({reason})" if error.by_peer else f"closed here ({reason})"
    if isinstance(error, ChaosConnectionLost):
        return f"lost (LOS: {reason})"
    if isinstance(error, ConnectionBroken):
        return f"broken ({reason})"
    return str(error)


class NcpTransport:
    """The client end of the Chaos manipulator protocol over ``manip.links``."""

    def __init__(
        self,
        address: str | LinkAddress,
        *,
        contact: str | None = None,
        connect_timeout: float | None = 10.0,
        close_timeout: float = DEFAULT_CLOSE_TIMEOUT,
        ncp_options: NcpConfig | None = None,
        wrap_link: LinkWrapper | None = None,
        faults: ClientFaults = NO_FAULTS,
    ) -> None:
        self.address = parse_address(address) if isinstance(address, str) else address
        self.contact = contact or self.address.contact
        self.connect_timeout = connect_timeout
        self.close_timeout = close_timeout
        # A server that sends an illegal packet is answered with LOS, which ends the connection for it:
        # the client gives the connection up at once rather than wait for replies that cannot come.
        self.ncp_options = replace(ncp_options or NcpConfig(), lose_on_illegal=True)
        self.wrap_link = _no_ack(wrap_link) if ClientFault.NEVER_ACK in faults else wrap_link
        if ClientFault.NO_CLS in faults:
            self.wrap_link = _dropping(self.wrap_link, ChaosOp.CLS)
        if faults & _WINDOW_FAULTS:
            self.wrap_link = _bent_window(self.wrap_link, _WindowBend(faults))
        self._conn: ChaosConnection | None = None
        self._ahead: Packet | None = None
        self._end: ChaosError | None = None
        self._fatal_seen = False
        self._abort_reason: str | None = None
        self._disconnected = False
        self._wakeup: Callable[[], None] | None = None

    def __repr__(self) -> str:
        return f"<NcpTransport {self.address} contact {self.contact}>"

    @property
    def connection(self) -> ChaosConnection | None:
        """The Chaos connection once open (for its statistics)."""
        return self._conn

    @property
    def close_cause(self) -> ChaosError | None:
        """The links error that ended the connection, once it has ended."""
        if self._end is not None:
            return self._end
        return None if self._conn is None else self._conn.end_reason

    # ------------------------------------------------------------------ ManipTransport

    def may_transmit(self) -> bool:
        return self._conn is not None and self._conn.can_send()

    def response_available(self) -> bool:
        self._look_ahead()
        return self._ahead is not None

    def get_next_packet(self) -> ServerPacket | None:
        self._look_ahead()
        packet, self._ahead = self._ahead, None
        if packet is None:
            return None
        if packet.opcode == ServerOp.FATAL_ERROR:
            self._fatal_seen = True  # the server gives up: no point in a graceful close
        return ServerPacket(packet.opcode, packet.data, packet.packet_no, packet.ack_no)

    def return_packet(self, packet: ServerPacket) -> None:
        pass  # taking the packet already acknowledged it

    def connection_open(self) -> bool:
        conn = self._conn
        return conn is not None and self._end is None and not conn.ended and self._abort_reason is None

    def handle_closed_connection(self) -> str:
        cause = self.close_cause
        if cause is not None:
            return describe_chaos_end(cause)
        if self._abort_reason is not None:
            return f"aborted ({self._abort_reason})"
        return "not connected" if self._conn is None else "connection closed"

    async def send_user_request(self, request: Request[Any]) -> None:
        conn = self._conn
        if conn is None or not self.connection_open():
            raise ConnectionLostError(self.handle_closed_connection())
        try:
            number = await conn.send(bytes(request.data), request.opcode)
        except ChaosError as exc:
            raise ConnectionLostError(describe_chaos_end(exc)) from exc
        request.packet_number = number

    def get_response_info(self, packet: ServerPacket) -> ResponseInfo:
        return chaos_response_info(packet)

    async def set_up_communications(self) -> None:
        if self._conn is not None or self._disconnected:
            raise ConnectionLostError("an NCP transport opens only once")
        try:
            conn = await open_connection(
                self.address,
                timeout=self.connect_timeout,
                contact=self.contact,
                options=self.ncp_options,
                wrap_link=self.wrap_link,
            )
        except (ChaosError, OSError) as exc:
            raise ConnectionLostError(
                f"cannot connect to {self.address} (contact {self.contact}): {exc}"
            ) from exc
        self._conn = conn
        conn.set_wakeup(self._poke)

    async def disconnect(self) -> None:
        conn = self._conn
        if conn is None or self._disconnected:
            self._disconnected = True
            return
        self._disconnected = True
        conn.set_wakeup(None)
        if self._fatal_seen or self._abort_reason is not None:
            conn.abort(self._abort_reason or "fatal error")
        with contextlib.suppress(ChaosError):
            await conn.close(self.close_timeout)  # after an abort this only closes the node

    def set_wakeup(self, callback: Callable[[], None] | None) -> None:
        self._wakeup = callback

    # ------------------------------------------------------------------ more

    def abort(self, reason: str = "aborted by the client") -> None:
        """End the connection at once (CLS ``reason``); the background process sees it closed."""
        if self._abort_reason is None:
            self._abort_reason = reason
            if self._conn is not None:
                self._conn.abort(reason)
            self._poke()

    def _look_ahead(self) -> None:
        conn = self._conn
        if self._ahead is not None or conn is None or self._end is not None:
            return
        try:
            self._ahead = conn.receive_nowait()
        except ChaosError as exc:
            self._end = exc

    def _poke(self) -> None:
        if self._wakeup is not None:
            self._wakeup()


SendFilter = Callable[[Packet], Packet | None]
"""What goes out in place of a packet the client's NCP sends (None: nothing)."""


def _filtered(inner: LinkWrapper | None, bend: SendFilter) -> LinkWrapper:
    """A link wrapper that sends ``bend(packet)`` for every packet (a fault of the client's NCP)."""

    def wrap(link: Link) -> Link:
        wrapped = inner(link) if inner is not None else link
        send = wrapped.send

        def send_bent(packet: Packet, next_hop: int | None = None) -> bool:
            bent = bend(packet)
            return True if bent is None else send(bent, next_hop)

        wrapped.send = send_bent  # type: ignore[method-assign]
        return wrapped

    return wrap


def _dropping(inner: LinkWrapper | None, opcode: int) -> LinkWrapper:
    """Fault no-cls: no packet of ``opcode`` goes out (the link is dropped without it)."""
    return _filtered(inner, lambda packet: None if packet.opcode == opcode else packet)


def _no_ack(inner: LinkWrapper | None) -> LinkWrapper:
    """Fault never-ack: every packet goes out with ack 0 and no STS goes out at all."""
    return _filtered(inner, lambda packet: None if packet.opcode == ChaosOp.STS else packet.with_(ack_no=0))


_WINDOW_FAULTS = frozenset(
    {ClientFault.IGNORE_WINDOW, ClientFault.IGNORE_WINDOW_SHRINK, ClientFault.WINDOW_ON_NEW_ACK_ONLY}
)


class _WindowBend:
    """What the window faults make of the window each OPN and STS received offers: ignore-window reads
    the largest there is; ignore-window-shrink the widest offered so far; window-on-new-ack-only keeps
    the window it had when an STS acknowledges nothing new."""

    def __init__(self, faults: ClientFaults) -> None:
        self.faults = faults
        self.widest = 0
        self.window: int | None = None
        self.acked: int | None = None

    def __call__(self, packet: Packet) -> Packet:
        carries_ack = packet.opcode in (ChaosOp.OPN, ChaosOp.STS, ChaosOp.EOF) or packet.opcode >= ChaosOp.DAT
        new_ack = carries_ack and (self.acked is None or seq_gt(packet.ack_no, self.acked))
        if new_ack:
            self.acked = packet.ack_no
        status = unpack_status(packet.data) if packet.opcode in (ChaosOp.OPN, ChaosOp.STS) else None
        if status is None:
            return packet
        window = status[1]
        if ClientFault.IGNORE_WINDOW in self.faults:
            window = MAX_WINDOW
        if ClientFault.WINDOW_ON_NEW_ACK_ONLY in self.faults and packet.opcode == ChaosOp.STS and not new_ack:
            window = self.window if self.window is not None else window
        if ClientFault.IGNORE_WINDOW_SHRINK in self.faults:
            window = max(window, self.widest)
        self.widest, self.window = max(self.widest, window), window
        return packet.with_(data=pack_status(status[0], window) + packet.data[4:])


def _bent_window(inner: LinkWrapper | None, bend: _WindowBend) -> LinkWrapper:
    """The window faults: every packet received goes through ``bend`` before the NCP reads it."""

    def wrap(link: Link) -> Link:
        wrapped = inner(link) if inner is not None else link
        set_receiver = wrapped.set_receiver

        def set_bending_receiver(receiver: Any) -> None:
            if receiver is None:
                set_receiver(None)
                return

            def bent(source: Link, packet: Packet) -> None:
                receiver(source, bend(packet))

            set_receiver(bent)

        wrapped.set_receiver = set_bending_receiver  # type: ignore[method-assign]
        return wrapped

    return wrap
