"""One Chaos connection as an asyncio object: send with back-pressure, receive in order, close.

The object holds no protocol state of its own beyond what the user has not read yet: numbers, windows
and timers are the core's.  ``receive`` is what acknowledges a packet, so a peer can only get
``window`` packets ahead of our user, and ``send`` waits while the peer's window is full; that wait is
the manip client's "may transmit".
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Final

from manip.codecs.packet import MAX_DATA, Packet
from manip.ncp import ConnectionInfo, NcpError
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

from .errors import ChaosError, ConnectionClosed, fresh

if TYPE_CHECKING:
    from .ncp_driver import Node, _Listener

UNCONTROLLED_KEPT: Final = 64
"""UNC packets kept per connection (oldest dropped); they are not sequenced or acknowledged."""
CLOSE_TIMEOUT: Final = 5.0
_DAT: Final = int(ChaosOp.DAT)  # plain ints: enum attribute reads are slow on the per-packet path
_EOF: Final = int(ChaosOp.EOF)


@dataclass(slots=True)
class ConnectionStats:
    """Per-connection counters; the core's sequencing state is in :meth:`ChaosConnection.info`."""

    packets_sent: int = 0
    bytes_sent: int = 0
    packets_received: int = 0
    bytes_received: int = 0
    send_waits: int = 0
    """How often ``send`` had to wait for the peer's window."""
    uncontrolled_received: int = 0


class ChaosConnection:
    """A connection made by :func:`~manip.links.open_connection` or accepted by a server.

    ``conn_id`` is our local index, ``peer`` the peer's (host, index); ``rfc_args`` the RFC's argument
    bytes after the contact name, and on the server side ``rfc`` the RFC packet itself."""

    def __init__(
        self,
        node: Node,
        conn_id: int,
        *,
        peer_host: int,
        peer_index: int,
        contact: str,
        rfc_args: bytes,
        rfc: Packet | None = None,
        client: bool = False,
        listener: _Listener | None = None,
    ) -> None:
        self._node = node
        self._loop = asyncio.get_running_loop()
        self.conn_id = conn_id
        self.contact = contact
        self.rfc_args = rfc_args
        self.rfc = rfc
        self.is_client = client
        self.opened = False
        self.stats = ConnectionStats()
        self.uncontrolled: deque[Packet] = deque(maxlen=UNCONTROLLED_KEPT)
        self.owns_node = False
        """Closing the connection also closes its node and links (:func:`open_connection` sets it)."""
        self._peer = (peer_host, peer_index)
        self._listener = listener
        self._rx: deque[Packet] = deque()
        self._rx_waiter: asyncio.Future[None] | None = None
        self._send_waiters: list[asyncio.Future[None]] = []
        self._opened_waiter: asyncio.Future[None] | None = None
        self._end_waiter: asyncio.Future[None] | None = None
        self._end: ChaosError | None = None
        self._eof_read = False
        self._closing = False
        self._wakeup: Callable[[], None] | None = None
        self._was_sendable = False

    def __repr__(self) -> str:
        host, index = self._peer
        state = "open" if self._end is None else f"ended: {self._end!r}"
        peer = f"{octal(host)}/{octal(index)}"
        return f"<ChaosConnection {octal(self.conn_id)} -> {peer} {self.contact} {state}>"

    # ---------------------------------------------------------------- state

    @property
    def peer(self) -> tuple[int, int]:
        """The peer's Chaos (host, index); the index is 0 until the OPN arrives."""
        return self._peer

    @property
    def node(self) -> Node:
        return self._node

    @property
    def ended(self) -> bool:
        """The connection is over; ``end_reason`` says how (buffered packets may still be received)."""
        return self._end is not None

    @property
    def end_reason(self) -> ChaosError | None:
        return self._end

    def info(self) -> ConnectionInfo | None:
        """The core's bookkeeping for this connection, or None once its slot has been reused."""
        try:
            return self._node.ncp.info(self.conn_id)
        except NcpError:
            return None

    def can_send(self) -> bool:
        """Whether :meth:`send` would go out at once (open, not closing, window not full)."""
        return self._end is None and not self._closing and self._node.ncp.can_send(self.conn_id)

    @property
    def pending(self) -> int:
        """Received packets not yet taken by :meth:`receive` (the peer's EOF counts as one)."""
        return len(self._rx)

    def set_wakeup(self, callback: Callable[[], None] | None) -> None:
        """For pollers (a background process re-checking ``pending``, ``can_send`` and ``ended``):
        ``callback()`` is scheduled on the loop whenever a packet arrives, the send window opens after
        being full, or the connection ends.  None stops it."""
        self._wakeup = callback
        self._was_sendable = self.can_send()
        if callback is None:
            self._node._watching.discard(self)
        else:
            self._node._watching.add(self)

    def window_space(self) -> int:
        """How many packets may be sent before the peer must acknowledge some."""
        if self._end is not None or self._closing:
            return 0
        return self._node.ncp.window_space(self.conn_id)

    # ---------------------------------------------------------------- data

    async def send(self, data: bytes, opcode: int = ChaosOp.DAT) -> int:
        """Send one data packet (opcode 0200-0377, at most 488 bytes); return its packet number.

        Waits while the peer's window is full.  Raises the connection's end (ConnectionClosed, ...)
        if it is over, and ConnectionClosed if we are closing it."""
        if not _DAT <= opcode <= 0o377:
            raise ValueError(f"data opcodes are 0200-0377, not {octal(opcode)}")
        if len(data) > MAX_DATA:
            raise ValueError(f"data is {len(data)} bytes, more than {MAX_DATA}")
        node = self._node
        ncp = node.ncp
        conn_id = self.conn_id
        while True:
            if self._end is not None or self._closing:
                self._check_sendable()
            if ncp.window_space(conn_id) > 0:
                break
            self.stats.send_waits += 1
            await self._wait_window()
        number = ncp.send(node._now(), conn_id, data, opcode=opcode)
        stats = self.stats
        stats.packets_sent += 1
        stats.bytes_sent += len(data)
        node._pump(windows=False)  # a send opens no window; only ours may have closed:
        if self._wakeup is not None:
            self._was_sendable = self.can_send()
        return number

    async def receive(self) -> Packet:
        """The next data packet, in order, with its header (``packet_no``, ``ack_no``, ``opcode``).

        Taking a packet acknowledges it.  At the end: ConnectionClosed (the peer's EOF, or a CLS),
        ConnectionLost or ConnectionBroken, with the reason; every later call raises it again.
        One task at a time may wait here (packets have one order, so one reader)."""
        while True:
            packet = self.receive_nowait()
            if packet is not None:
                return packet
            if self._rx_waiter is not None:
                raise RuntimeError("another task is already waiting in receive() on this connection")
            waiter = self._loop.create_future()
            self._rx_waiter = waiter
            try:
                await waiter
            finally:
                self._rx_waiter = None

    def receive_nowait(self) -> Packet | None:
        """Like :meth:`receive`, but None instead of waiting when nothing has arrived."""
        if self._rx:
            packet = self._rx.popleft()
            self._node._read(self.conn_id, packet.packet_no)
            if packet.opcode != _EOF:
                return packet
            self._eof_read = True
        if self._eof_read:
            raise ConnectionClosed("EOF", by_peer=True)
        if self._end is not None:
            raise fresh(self._end)
        return None

    def __aiter__(self) -> ChaosConnection:
        return self

    async def __anext__(self) -> Packet:
        """Packets until the peer's EOF or CLS; other ends (LOS, broken) still raise."""
        try:
            return await self.receive()
        except ConnectionClosed:
            raise StopAsyncIteration from None

    # ---------------------------------------------------------------- ending

    async def close(self, timeout: float | None = CLOSE_TIMEOUT) -> None:
        """Close gracefully: anything unread is discarded, our EOF follows our data, and once the peer
        acknowledges it a CLS ends the connection (after the peer's own EOF, no EOF: a CLS once our data
        is acknowledged; erratum ``ncp-close-after-peer-eof``).  After ``timeout`` seconds we abort
        instead."""
        node = self._node
        if self._end is None:
            if not self._closing:
                self._closing = True
                self._wake_senders()  # a send waiting for the window now fails: we are closing
                self._discard_unread()
                with contextlib.suppress(NcpError):
                    node.ncp.close(node._now(), self.conn_id)
                node._pump()
                if self._end is None and node._core_finished(self.conn_id):
                    node._finish(self, ConnectionClosed("closed", by_peer=False))
            if self._end is None:
                waiter = self._end_waiter
                if waiter is None:
                    waiter = self._end_waiter = self._loop.create_future()
                try:
                    async with asyncio.timeout(timeout):
                        await asyncio.shield(waiter)
                except TimeoutError:
                    self.abort("Close timed out")
        if self.owns_node:
            await node.aclose()

    def abort(self, reason: str = "") -> None:
        """End the connection at once with CLS ``reason``; unsent and unread data are lost."""
        node = self._node
        if self._end is None:
            self._rx.clear()
            text = f"aborted: {reason}" if reason else "aborted"
            node._abandon(self, ConnectionClosed(text, by_peer=False), reason)
        if self.owns_node:
            node.close()

    async def __aenter__(self) -> ChaosConnection:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None or issubclass(exc_type, ChaosError):
            await self.close()
        else:
            self.abort(f"client error: {exc_type.__name__}")

    # ---------------------------------------------------------------- called by the node

    def _check_sendable(self) -> None:
        if self._end is not None:
            raise fresh(self._end)
        if self._closing:
            raise ConnectionClosed("connection is closing", by_peer=False)

    async def _wait_window(self) -> None:
        waiter = self._loop.create_future()
        self._send_waiters.append(waiter)
        self._node._send_waiting.add(self)
        try:
            await waiter
        finally:
            if waiter in self._send_waiters:
                self._send_waiters.remove(waiter)

    def _wake_senders(self) -> None:
        waiters, self._send_waiters = self._send_waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(None)

    async def _wait_opened(self) -> None:
        if self.opened or self._end is not None:
            return
        waiter = self._opened_waiter = self._loop.create_future()
        await waiter

    def _on_opened(self, peer_index: int) -> None:
        self.opened = True
        self._peer = (self._peer[0], peer_index)
        _wake(self._opened_waiter)

    def _on_data(self, packet: Packet) -> None:
        stats = self.stats
        stats.packets_received += 1
        stats.bytes_received += len(packet.data)
        if self._closing:
            self._node._read(self.conn_id, packet.packet_no)
            return
        self._rx.append(packet)
        _wake(self._rx_waiter)
        self._poke()

    def _on_eof(self, packet: Packet) -> None:
        if self._closing:
            self._node._read(self.conn_id, packet.packet_no)
            return
        self._rx.append(packet)
        _wake(self._rx_waiter)
        self._poke()

    def _check_window(self) -> None:
        """Called by the node after it drained the core: poke a poller when the window has opened."""
        sendable = self.can_send()
        if sendable and not self._was_sendable:
            self._poke()
        self._was_sendable = sendable

    def _poke(self) -> None:
        if self._wakeup is not None:
            self._loop.call_soon(self._wakeup)

    def _on_uncontrolled(self, packet: Packet) -> None:
        self.stats.uncontrolled_received += 1
        self.uncontrolled.append(packet)

    def _set_end(self, error: ChaosError) -> None:
        if self._end is not None:
            return
        self._end = error
        _wake(self._opened_waiter)
        _wake(self._rx_waiter)
        _wake(self._end_waiter)
        self._wake_senders()
        self._poke()
        if self.owns_node and not self._node.is_closed:
            self._loop.call_soon(self._node.close)

    def _fresh_end(self) -> ChaosError:
        assert self._end is not None
        return fresh(self._end)

    def _discard_unread(self) -> None:
        if self._rx:
            last = self._rx[-1].packet_no
            self._rx.clear()
            self._node._read(self.conn_id, last)


def _wake(waiter: asyncio.Future[None] | None) -> None:
    if waiter is not None and not waiter.done():
        waiter.set_result(None)
