"""An in-memory transport: the client end of :class:`ManipTransport` and a server end for test peers.

Packet numbers imitate a Chaos connection: the "RFC" that opens it has number ``first_number`` and
each request takes the next number, modulo 2^16.  Flow control imitates a window: at most ``window``
requests may be sent that the peer has not yet taken with :meth:`MemoryPeer.receive`.

A scripted fake server drives :attr:`MemoryTransport.peer`::

    transport = MemoryTransport()
    peer = transport.peer
    await peer.wait_connected()
    peer.send_initial_response()
    request = await peer.receive()          # SentRequest(opcode, number, data)
    peer.reply(request.number, payload)     # a RESPONSE (0200) with that request number
"""

from __future__ import annotations

import asyncio
from collections import deque
from dataclasses import dataclass
from typing import Any

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_async, encode_error, encode_terminator
from manip.reference_client.errors import ConnectionLostError
from manip.reference_client.inbox import InboxTransport
from manip.reference_client.packets import ServerPacket
from manip.reference_client.request import Request
from manip.spec.constants import AsyncCondition, ServerOp


@dataclass(frozen=True, slots=True)
class SentRequest:
    """A request as the peer receives it."""

    opcode: int
    number: int
    data: bytes


class MemoryTransport(InboxTransport):
    """The client end.  ``refuse`` makes ``set_up_communications`` fail with that reason."""

    def __init__(self, *, window: int = 8, first_number: int = 1, refuse: str | None = None) -> None:
        super().__init__(window=window, first_number=first_number)
        self.refuse = refuse
        self.peer = MemoryPeer(self)
        self.returned = 0
        """How many packets the background process returned."""
        self._outbox: deque[SentRequest | None] = deque()
        self._outbox_ready = asyncio.Event()
        self._connected = asyncio.Event()
        self._unread = 0

    # ------------------------------------------------------------------ ManipTransport

    def may_transmit(self) -> bool:
        return self._open and self._unread < self.window

    def return_packet(self, packet: ServerPacket) -> None:
        self.returned += 1

    async def send_user_request(self, request: Request[Any]) -> None:
        number = self._number(request)
        self._unread += 1
        self._push(SentRequest(request.opcode, number, bytes(request.data)))

    async def set_up_communications(self) -> None:
        if self.refuse is not None:
            raise ConnectionLostError(f"refused: {self.refuse}")
        self._opening("memory")
        self._connected.set()

    async def disconnect(self) -> None:
        if self._open:
            self._close("closed by the client")
            self._push(None)

    # ------------------------------------------------------------------ used by the peer

    def _push(self, item: SentRequest | None) -> None:
        self._outbox.append(item)
        self._outbox_ready.set()


class MemoryPeer:
    """The server end of a :class:`MemoryTransport`."""

    def __init__(self, transport: MemoryTransport) -> None:
        self._t = transport
        self.received: list[SentRequest] = []
        """Every request taken so far, in order."""

    @property
    def rfc_number(self) -> int:
        """The packet number of the "RFC" that opened the connection."""
        return self._t.first_number

    @property
    def connected(self) -> bool:
        return self._t.connection_open()

    async def wait_connected(self) -> None:
        await self._t._connected.wait()

    async def receive(self) -> SentRequest | None:
        """The next request (waiting for it), or None once the client has disconnected."""
        t = self._t
        while not t._outbox:
            t._outbox_ready.clear()
            await t._outbox_ready.wait()
        item = t._outbox.popleft()
        if item is not None:
            t._unread -= 1
            self.received.append(item)
            t._wake()
        else:
            t._outbox.appendleft(None)  # stay at end of stream
        return item

    def pending_requests(self) -> int:
        """Requests sent by the client and not yet received."""
        return sum(1 for item in self._t._outbox if item is not None)

    # ------------------------------------------------------------------ sending

    def send(self, opcode: int, data: bytes) -> None:
        """Any packet; ignored once the connection is closed."""
        if not self._t._open:
            return
        self._t._inbox.append(ServerPacket(opcode, bytes(data)))
        self._t._wake()

    def send_initial_response(self, number: int | None = None) -> None:
        """The RESPONSE a server sends when the connection opens (erratum initial-response)."""
        self.reply(self.rfc_number if number is None else number)

    def reply(self, number: int, payload: bytes = b"") -> None:
        """A RESPONSE (0200): the request number, then ``payload``."""
        self.send(ServerOp.RESPONSE, number.to_bytes(2, "little") + payload)

    def reply_multi(self, number: int, chunks: list[bytes]) -> None:
        """A multi-packet RESPONSE: each chunk, then the empty terminator."""
        for chunk in chunks:
            self.reply(number, chunk)
        self.send(ServerOp.RESPONSE, encode_terminator(number))

    def error(self, opcode: int, number: int, error: ErrorMessage) -> None:
        """An error packet: 0201 fatal, 0202 non-fatal, 0204 asynchronous error, 0205 warning."""
        self.send(opcode, encode_error(opcode, number, error))

    def async_response(self, number: int, condition: int, word2: int, word3: int) -> None:
        self.send(ServerOp.ASYNCHRONOUS_RESPONSE, encode_async(number, condition, word2, word3))

    def segment_completed(self, number: int, segment: int) -> None:
        self.async_response(number, AsyncCondition.SEGMENT_COMPLETED, 0, segment)

    def guard_hit(self, number: int, guard: int, *, stop: bool) -> None:
        self.async_response(number, AsyncCondition.GUARD_HIT, 1 if stop else 2, guard)

    def close(self, reason: str = "closed by the server") -> None:
        """Close the connection (a CLS); packets already sent stay readable by the client."""
        self._t._close(reason)
