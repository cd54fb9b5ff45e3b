"""A listening stream socket with an accept loop of its own, so a server decides about each peer before
it costs more than a descriptor, and survives running out of descriptors.

asyncio's own accept loop (``loop.create_server``) does neither: every new connection becomes a
transport before the application hears of it, and when ``accept`` fails for want of descriptors it
hands a traceback to the loop's exception handler, once for every pending connection and every retry
(tens of thousands of lines in seconds), with no say for the application.  Here each accepted socket is
put to :meth:`LinkGuard.admit <manip.links.guard.LinkGuard.admit>` first (a peer that is refused or over
the limit is reset at once, before any transport exists), and a failed accept is counted, logged through
the guard's rate limit and, when descriptors or memory ran out, pauses accepting for the guard's back-off.

The listener works for any ``SOCK_STREAM`` socket: a TCP one from :func:`bind_stream`, or a unix one.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import struct
from collections.abc import Callable, Sequence
from typing import Any, Final

from .guard import Endpoint, LinkGuard
from .stream import StreamLink

log = logging.getLogger("manip.links")

BACKLOG: Final = 128
"""Connections the kernel queues for us to accept (the listen backlog)."""
ACCEPT_BATCH: Final = 64
"""Accepts per readiness callback before other work gets the loop again."""
_RESET: Final = struct.pack("ii", 1, 0)  # SO_LINGER on, 0 s: close with a reset, keep no TIME_WAIT


def _peer(addr: Any) -> Endpoint | None:
    """(host, port) of an accepted peer; None for a unix socket's, which has no address."""
    if isinstance(addr, tuple):
        return str(addr[0]), int(addr[1])
    return None


def _no_delay(sock: socket.socket) -> None:
    """Send small frames at once (TCP_NODELAY).  asyncio does this for the sockets it accepts, not for
    ours (their ``proto`` is 0): without it a reply queued behind one not yet acknowledged waits for
    the peer's delayed acknowledgement, some 40 ms, and a pipelining client crawls."""
    if sock.family in (socket.AF_INET, socket.AF_INET6):
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)


def _reset(sock: socket.socket) -> None:
    """Close an accepted socket at once: a reset, no lingering state."""
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
    sock.close()


async def bind_stream(host: str, port: int, backlog: int = BACKLOG) -> list[socket.socket]:
    """Listening TCP sockets for every address ``host`` resolves to (port 0: a free port each), as
    ``loop.create_server`` binds them.  Raises OSError naming the address that failed."""
    loop = asyncio.get_running_loop()
    infos = await loop.getaddrinfo(
        host or None, port, family=socket.AF_UNSPEC, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    )
    socks: list[socket.socket] = []
    try:
        for family, _type, _proto, _name, sockaddr in dict.fromkeys(infos):  # once per address
            sock = socket.create_server(sockaddr, family=family, backlog=backlog)
            socks.append(sock)
            sock.setblocking(False)
    except OSError:
        for sock in socks:
            sock.close()
        raise
    return socks


def bind_unix(path: str, backlog: int = BACKLOG) -> socket.socket:
    """A listening Unix-domain stream socket at ``path`` (which must not exist yet).  Raises OSError."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.bind(path)
        sock.listen(backlog)
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock


class StreamListener:
    """Accepts connections on ``sockets`` and makes each a link with ``make_link`` (which gets the link
    to its driver before any byte is read), asking ``guard`` first.  Create it inside a running loop;
    it starts accepting at once and owns the sockets (``close`` closes them)."""

    def __init__(
        self, sockets: Sequence[socket.socket], make_link: Callable[[], StreamLink], guard: LinkGuard
    ) -> None:
        self._loop = asyncio.get_running_loop()
        self._sockets = list(sockets)
        self._make_link = make_link
        self.guard = guard
        self._opening: set[asyncio.Task[None]] = set()
        self._pending = 0  # admitted sockets whose link is not made yet
        self._paused: asyncio.TimerHandle | None = None
        self._closed = False
        self._serve()

    def __repr__(self) -> str:
        names = ", ".join(str(sock.getsockname()) for sock in self._sockets) if not self._closed else "closed"
        return f"<StreamListener {names}>"

    @property
    def sockets(self) -> list[socket.socket]:
        """The listening sockets (read the bound port from ``getsockname()``)."""
        return list(self._sockets)

    @property
    def is_serving(self) -> bool:
        return not self._closed and self._paused is None

    def close(self) -> None:
        """Stop accepting and close the listening sockets; links not yet open are dropped."""
        if self._closed:
            return
        self._closed = True
        self._stop()
        if self._paused is not None:
            self._paused.cancel()
            self._paused = None
        for sock in self._sockets:
            sock.close()
        for task in self._opening:
            task.cancel()

    async def wait_closed(self) -> None:
        """Wait until the links that were being opened at the close are dropped."""
        if self._opening:
            await asyncio.gather(*self._opening, return_exceptions=True)

    # ---------------------------------------------------------------- internals

    def _serve(self) -> None:
        self._paused = None
        if not self._closed:
            for sock in self._sockets:
                self._loop.add_reader(sock.fileno(), self._accept, sock)

    def _stop(self) -> None:
        for sock in self._sockets:
            if sock.fileno() >= 0:
                self._loop.remove_reader(sock.fileno())

    def _accept(self, sock: socket.socket) -> None:
        for _ in range(ACCEPT_BATCH):
            try:
                conn, addr = sock.accept()
            except (BlockingIOError, InterruptedError):
                return  # nothing more waiting
            except ConnectionAbortedError:
                continue  # the peer gave up while queued
            except OSError as exc:
                pause = self.guard.accept_failed(exc, opening=self._pending)
                if pause > 0 and not self._closed:
                    self._stop()  # the socket stays readable: without this we would spin
                    self._paused = self._loop.call_later(pause, self._serve)
                return
            if not self.guard.admit(_peer(addr), opening=self._pending):
                _reset(conn)
                continue
            _no_delay(conn)
            self._pending += 1
            task = self._loop.create_task(self._open(conn))
            self._opening.add(task)
            task.add_done_callback(self._opening.discard)
            if self.guard.closing:
                return  # it displaced a link: accept more once that one's descriptor is free

    async def _open(self, conn: socket.socket) -> None:
        made: list[StreamLink] = []

        def factory() -> StreamLink:
            self._pending -= 1
            made.append(self._make_link())
            return made[0]

        try:
            await self._loop.connect_accepted_socket(factory, conn)
        except BaseException as exc:
            conn.close()
            if not made:
                self._pending -= 1
            if made:  # the driver has it: close it there too
                made[0].abort(f"could not be opened: {exc!r}")
            if not isinstance(exc, (OSError, asyncio.CancelledError)):
                log.error("accepting a connection failed: %r", exc)
            if isinstance(exc, asyncio.CancelledError):
                raise
