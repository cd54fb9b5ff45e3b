"""The client end shared by the in-memory transports: an inbox of server packets, NCP-like numbering.

Subclasses decide where a request goes (:meth:`InboxTransport.send_user_request`), when transmitting
is allowed and how the connection opens; the rest of
:class:`~manip.reference_client.transport.ManipTransport` is here.  Requests are numbered like a
Chaos connection's packets: the "RFC" has ``first_number``, each request the next number modulo 2^16.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable

from manip.reference_client.errors import ConnectionLostError
from manip.reference_client.packets import ResponseInfo, ServerPacket, chaos_response_info
from manip.reference_client.request import Request

MOD = 0x10000


class InboxTransport:
    def __init__(self, *, window: int, first_number: int) -> None:
        if window < 1:
            raise ValueError("the window must be at least 1")
        self.window = window
        self.first_number = first_number & 0xFFFF
        self._open = False
        self._ever_opened = False
        self._close_reason = ""
        self._inbox: deque[ServerPacket] = deque()
        self._next_number = self.first_number
        self._wakeup: Callable[[], None] | None = None

    def get_next_packet(self) -> ServerPacket | None:
        return self._inbox.popleft() if self._inbox else None

    def response_available(self) -> bool:
        return bool(self._inbox)

    def connection_open(self) -> bool:
        return self._open

    def handle_closed_connection(self) -> str:
        return self._close_reason or "connection closed"

    def get_response_info(self, packet: ServerPacket) -> ResponseInfo:
        return chaos_response_info(packet)

    def set_wakeup(self, callback: Callable[[], None] | None) -> None:
        self._wakeup = callback

    def _number(self, request: Request[object]) -> int:
        """Give ``request`` the next packet number (ConnectionLostError when closed)."""
        if not self._open:
            raise ConnectionLostError(self._close_reason or "not connected")
        self._next_number = (self._next_number + 1) % MOD
        request.packet_number = self._next_number
        return self._next_number

    def _opening(self, kind: str) -> None:
        if self._ever_opened:
            raise ConnectionLostError(f"a {kind} transport opens only once")
        self._open = self._ever_opened = True

    def _wake(self) -> None:
        if self._wakeup is not None:
            self._wakeup()

    def _close(self, reason: str) -> bool:
        """Mark the connection closed; False if it already was."""
        if not self._open:
            return False
        self._open = False
        self._close_reason = reason
        self._wake()
        return True
