"""A routing stand-in for usim's chaosd daemon, in the process: hosts dial its Unix socket and it hands
each frame to the host its trailer's destination names.

usim's chaosd is the one neighbour of every host on its socket, so a host's frames carry their final
destination in the trailer (:mod:`manip.links.chaosd`).  The router reads each frame by its 4-byte
header (``len >> 8, len & 0xFF, 1, 0``; :mod:`manip.codecs.framing`) and learns the sending host's
address from the trailer's source; it forwards the frame, untouched, to the host that last sent from
the trailer's destination.  Several connections may come from one address (a client's several links):
the last one heard from gets its packets, the others when it closes.  A host that speaks only when
spoken to (a server) is named up front with :meth:`ChaosdRouter.name_silent`.

What it cannot route it drops and counts (:attr:`ChaosdRouter.dropped`, by reason): a destination no
host has sent from, a frame to a host whose socket holds more than :data:`OUTBOUND_LIMIT` unsent bytes
(it stopped reading).  A header that is not the framing's loses the frame boundaries: that connection is
closed and counted.  The trailer is read low byte first, as the framing lays it out; a frame laid out in
the other order reaches the host whose address reads the same either way (such as the default client
address, 0401), which then judges the frame, or is dropped as unroutable.

The router only moves bytes on the running event loop, so it runs in virtual time
(:class:`~manip.links.virtual_clock.VirtualClockLoop`) as the hosts do.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections import Counter
from typing import Final

from .listener import bind_unix

__all__ = ["JOIN_TIMEOUT", "OUTBOUND_LIMIT", "ChaosdRouter"]

HEADER: Final = 4
TRAILER: Final = 6
OUTBOUND_LIMIT: Final = 256 * 1024
"""Unsent bytes a host's socket may hold; frames for it past that are dropped (``congested``)."""
JOIN_TIMEOUT: Final = 5.0
"""Seconds :meth:`ChaosdRouter.name_silent` waits for the hosts it names to connect."""


class _Host(asyncio.Protocol):
    """One connection to the router."""

    def __init__(self, router: ChaosdRouter) -> None:
        self.router = router
        self.transport: asyncio.Transport | None = None
        self.buffer = bytearray()
        self.spoke = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.router._hosts.append(self)
        self.router._joined.set()

    def data_received(self, data: bytes) -> None:
        self.buffer += data
        while len(self.buffer) >= HEADER:
            if self.buffer[2:4] != b"\x01\x00" or (self.buffer[0] << 8 | self.buffer[1]) < TRAILER:
                self.router.dropped["framing lost"] += 1
                self.buffer.clear()
                if self.transport is not None:
                    self.transport.close()
                return
            size = HEADER + (self.buffer[0] << 8 | self.buffer[1])
            if len(self.buffer) < size:
                return
            frame = bytes(self.buffer[:size])
            del self.buffer[:size]
            self.router._route(self, frame)

    def connection_lost(self, exc: Exception | None) -> None:
        self.router._forget(self)

    def send(self, frame: bytes) -> bool:
        t = self.transport
        if t is None or t.is_closing() or t.get_write_buffer_size() > OUTBOUND_LIMIT:
            return False
        t.write(frame)
        return True


class ChaosdRouter:
    """``async with ChaosdRouter(path) as router:`` a chaosd stand-in listening on the socket file
    ``path`` (which must not exist yet; module docstring); it keeps the first ``keep`` frames it is sent
    (:attr:`frames`, whether routed or not)."""

    def __init__(self, path: str, *, keep: int = 0) -> None:
        self.path = path
        self.keep = keep
        self.frames: list[bytes] = []
        """The first :attr:`keep` frames hosts sent, in the order they came."""
        self.dropped: Counter[str] = Counter()
        """Frames not delivered, by reason (``unroutable``, ``congested``, ``framing lost``)."""
        self.forwarded = 0
        self._hosts: list[_Host] = []
        self._routes: dict[int, list[_Host]] = {}
        self._server: asyncio.Server | None = None
        self._joined = asyncio.Event()
        """Set when a host connects."""

    async def __aenter__(self) -> ChaosdRouter:
        loop = asyncio.get_running_loop()
        self._server = await loop.create_unix_server(lambda: _Host(self), sock=bind_unix(self.path))
        return self

    async def __aexit__(self, *exc: object) -> None:
        if self._server is not None:
            self._server.close()
        for host in list(self._hosts):
            if host.transport is not None:
                host.transport.close()
        if self._server is not None:
            with contextlib.suppress(Exception):
                await self._server.wait_closed()

    @property
    def connected(self) -> int:
        """Hosts connected now."""
        return len(self._hosts)

    async def name_silent(self, address: int, *, hosts: int = 1, timeout: float = JOIN_TIMEOUT) -> None:
        """The hosts connected now that have sent nothing are at ``address`` (a daemon told its hosts'
        addresses; every other address is learnt from the frames), once at least ``hosts`` are (a host
        whose dial has returned may not be accepted yet); :class:`TimeoutError` if fewer have connected
        within ``timeout`` seconds.  A dial that returned is accepted in turns of the loop, before a
        virtual clock jumps."""
        try:
            async with asyncio.timeout(timeout):
                while self.connected < hosts:
                    self._joined.clear()
                    await self._joined.wait()
        except TimeoutError:
            raise TimeoutError(
                f"chaosd router at {self.path}: {self.connected} of {hosts} host(s) connected"
                f" within {timeout} s"
            ) from None
        for host in self._hosts:
            if not host.spoke:
                self._learn(address, host)

    def _learn(self, address: int, host: _Host) -> None:
        hosts = self._routes.setdefault(address, [])
        if hosts[-1:] != [host]:
            with contextlib.suppress(ValueError):
                hosts.remove(host)
            hosts.append(host)

    def _route(self, sender: _Host, frame: bytes) -> None:
        dest = int.from_bytes(frame[-6:-4], "little")
        source = int.from_bytes(frame[-4:-2], "little")
        sender.spoke = True
        if len(self.frames) < self.keep:
            self.frames.append(frame)
        self._learn(source, sender)
        to = [h for h in self._routes.get(dest, []) if h is not sender]
        if not to:
            self.dropped["unroutable"] += 1
        elif to[-1].send(frame):
            self.forwarded += 1
        else:
            self.dropped["congested"] += 1

    def _forget(self, host: _Host) -> None:
        with contextlib.suppress(ValueError):
            self._hosts.remove(host)
        for hosts in self._routes.values():
            with contextlib.suppress(ValueError):
                hosts.remove(host)
