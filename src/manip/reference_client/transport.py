"""The operations a communication protocol provides to the background process (the 1985 guide, Part I §3.1).

The 1985 guide's methods were polled by a Lisp Machine process waiting on a predicate.  Here the same
operations are plain methods; the one addition, :meth:`ManipTransport.set_wakeup`, replaces the
process wait: the transport calls the callback whenever a predicate may have changed (a packet
arrived, the transmit window opened, the connection closed), and the background process re-checks.

Rules every transport keeps (the background process relies on them):

* all methods are called from the event loop's thread, and the wake-up callback must be called there
  too (use ``loop.call_soon_threadsafe`` from another thread);
* ``send_user_request`` sets ``request.packet_number`` before it returns: the number the server will
  put in the first data word of its reply;
* packets that arrived before the connection closed stay readable: ``get_next_packet`` keeps
  returning them after ``connection_open()`` turns false, so a fatal error followed at once by CLS is
  seen as the fatal error;
* ``handle_closed_connection`` is called once, after the last packet was read, and returns why the
  connection closed (CLS text, LOS reason, "broken", ...).  A transport may also have a
  ``close_cause`` attribute (an exception or None): it becomes the ``__cause__`` of the
  ConnectionLostError errors.

Implementations: :class:`~manip.reference_client.ncp_transport.NcpTransport` (Chaos over
``manip.links``), :class:`~manip.reference_client.core_transport.CoreTransport` (a sans-I/O server core
in memory), :class:`~manip.reference_client.memory.MemoryTransport` (scripted test peers).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

from manip.reference_client.packets import ResponseInfo, ServerPacket
from manip.reference_client.request import Request


@runtime_checkable
class ManipTransport(Protocol):
    """What the background process needs from a communication protocol."""

    def may_transmit(self) -> bool:
        """True when sending a request now will not block (the flow-control window has room)."""
        ...

    def get_next_packet(self) -> ServerPacket | None:
        """The next packet from the server, in order, or None."""
        ...

    def return_packet(self, packet: ServerPacket) -> None:
        """The background process is done with ``packet`` (a transport may acknowledge it here)."""
        ...

    def response_available(self) -> bool:
        """True when ``get_next_packet`` would return a packet."""
        ...

    def connection_open(self) -> bool:
        """True while the connection to the server is open."""
        ...

    def handle_closed_connection(self) -> str:
        """Clean up after the connection closed; return the reason, for the user."""
        ...

    async def send_user_request(self, request: Request[Any]) -> None:
        """Send ``request.opcode`` with ``request.data``; set ``request.packet_number``."""
        ...

    def get_response_info(self, packet: ServerPacket) -> ResponseInfo:
        """Response code, request number, data offset and data byte count of ``packet``; raise
        ``manip.codecs.errors.DecodeError`` when the packet cannot carry them."""
        ...

    async def set_up_communications(self) -> None:
        """Open the connection; raise ``ConnectionLostError`` when it cannot be opened."""
        ...

    async def disconnect(self) -> None:
        """Close the connection (idempotent)."""
        ...

    def set_wakeup(self, callback: Callable[[], None] | None) -> None:
        """Call ``callback`` (in the loop thread) whenever a packet arrives, the window opens or the
        connection closes."""
        ...
