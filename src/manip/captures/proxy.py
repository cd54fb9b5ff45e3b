"""A transparent recording proxy between a client and a server: ``manip-capture record``.

It has no NCP of its own and changes nothing on the wire:

* **TCP link** (:class:`TcpProxy`): each client TCP connection gets its own connection to the upstream
  server.  Bytes are forwarded as they arrive, before anything else is done with them; a copy is cut
  into frames (2-byte big-endian length, clause ``link.tcp.framing``) and each frame recorded.  If a
  length is impossible the stream's framing is lost: the proxy records a ``framing-lost`` event and
  keeps forwarding (the receiving end will drop the connection itself).  A half-close is passed on.
* **CHUDP** (:class:`ChudpRelay`): one datagram is one frame.  Each client endpoint gets its own UDP
  socket towards the server, so the server sees one endpoint per client and its replies come back to
  the right client; the datagrams themselves are not rewritten (the Chaos addresses in trailers are the
  real ones, which is what CHUDP peers learn from).

Every client connection (TCP) or client endpoint (CHUDP) is one link of the capture.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass
from typing import Any, Final, Literal
from urllib.parse import urlsplit

from manip.codecs.framing import MAX_BODY, MIN_BODY
from manip.codecs.packet import Direction

from .recorder import CaptureError, Recorder

log = logging.getLogger("manip.captures")

READ_SIZE: Final = 65536
ProxyScheme = Literal["tcp", "chudp"]


@dataclass(frozen=True)
class Endpoint:
    """A proxy end: ``tcp://HOST:PORT`` or ``chudp://HOST:PORT`` (link parameters are ignored)."""

    scheme: ProxyScheme
    host: str
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.scheme}://{host}:{self.port}"


def parse_endpoint(url: str) -> Endpoint:
    """Parse a proxy end; CaptureError says what is wrong."""
    split = urlsplit(url if "://" in url else f"tcp://{url}")
    if split.scheme not in ("tcp", "chudp"):
        raise CaptureError(f"{url!r}: the proxy speaks tcp:// and chudp:// only")
    try:
        port = split.port
    except ValueError as exc:
        raise CaptureError(f"{url!r}: bad port: {exc}") from None
    if split.hostname is None or port is None:
        raise CaptureError(f"{url!r} must give HOST:PORT")
    return Endpoint(split.scheme, split.hostname, port)  # type: ignore[arg-type]


class TcpFrameCutter:
    """Cuts a TCP-link byte stream into whole frames (prefix included); sans I/O."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.lost: str | None = None
        """Why the framing was lost (then :meth:`feed` returns nothing more)."""

    def feed(self, data: bytes) -> list[bytes]:
        if self.lost is not None:
            return []
        buf = self._buf
        buf += data
        frames: list[bytes] = []
        pos = 0
        while len(buf) - pos >= 2:
            length = buf[pos] << 8 | buf[pos + 1]
            if length & 1 or not MIN_BODY <= length <= MAX_BODY:
                self.lost = f"impossible frame length {length} (must be even, {MIN_BODY}..{MAX_BODY})"
                buf.clear()
                return frames
            end = pos + 2 + length
            if end > len(buf):
                break
            frames.append(bytes(buf[pos:end]))
            pos = end
        del buf[:pos]
        return frames

    @property
    def pending(self) -> int:
        return len(self._buf)


class TcpProxy:
    """Listen for clients, connect each to ``upstream``, forward and record (module docstring)."""

    def __init__(self, recorder: Recorder, upstream: Endpoint, *, connect_timeout: float = 10.0) -> None:
        self.recorder = recorder
        self.upstream = upstream
        self.connect_timeout = connect_timeout
        self.server: asyncio.Server | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self, host: str, port: int) -> Endpoint:
        """Start listening; returns the bound end (port 0 replaced by the real one)."""
        self.server = await asyncio.start_server(self._accepted, host, port)
        bound = self.server.sockets[0].getsockname()
        return Endpoint("tcp", host, int(bound[1]))

    async def aclose(self) -> None:
        if self.server is not None:
            self.server.close()
        for task in list(self._tasks):
            task.cancel()
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
        if self.server is not None:
            await self.server.wait_closed()

    async def _accepted(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._tasks.add(task)
        peer = writer.get_extra_info("peername")
        name = f"{peer[0]}:{peer[1]} -> {self.upstream}" if peer else str(self.upstream)
        link = self.recorder.open_link("tcp", name=name)
        reason = "closed"
        try:
            try:
                async with asyncio.timeout(self.connect_timeout):
                    up_reader, up_writer = await asyncio.open_connection(
                        self.upstream.host, self.upstream.port
                    )
            except (OSError, TimeoutError) as exc:
                reason = f"cannot reach upstream {self.upstream}: {exc or 'timed out'}"
                log.warning("%s: %s", name, reason)
                return
            try:
                results = await asyncio.gather(
                    self._pump(link, "c2s", reader, up_writer),
                    self._pump(link, "s2c", up_reader, writer),
                    return_exceptions=True,
                )
                errors = [r for r in results if isinstance(r, BaseException)]
                reason = f"error: {errors[0]}" if errors else "both directions ended"
            finally:
                up_writer.close()
        except asyncio.CancelledError:  # aclose(): end quietly (start_server logs a cancelled handler)
            reason = "proxy stopping"
        finally:
            writer.close()
            if not self.recorder.closed:
                self.recorder.close_link(link, reason)
            if task is not None:
                self._tasks.discard(task)

    async def _pump(
        self, link: int, direction: Direction, reader: asyncio.StreamReader, writer: asyncio.StreamWriter
    ) -> None:
        cutter = TcpFrameCutter()
        recorder = self.recorder
        reported = False
        while True:
            data = await reader.read(READ_SIZE)
            if not data:
                break
            writer.write(data)  # forward first: the proxy must not delay the session
            t = time.time_ns()
            if recorder.closed:
                continue
            for frame in cutter.feed(data):
                recorder.frame(link, direction, frame, t)
            if cutter.lost is not None and not reported:
                reported = True
                recorder.framing_lost(link, direction, cutter.lost, t)
            await writer.drain()
        if cutter.pending and not recorder.closed:
            recorder.framing_lost(link, direction, f"stream ended inside a frame ({cutter.pending} bytes)")
        if writer.can_write_eof():
            with contextlib.suppress(OSError):
                writer.write_eof()


class _Upstream(asyncio.DatagramProtocol):
    """The socket one CHUDP client's datagrams go to the server from."""

    def __init__(self, relay: ChudpRelay, client: tuple[str, int], link: int) -> None:
        self.relay = relay
        self.client = client
        self.link = link
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.relay._from_server(self, data)

    def error_received(self, exc: Exception) -> None:
        log.debug("chudp relay: upstream error for %s: %s", self.client, exc)


class ChudpRelay(asyncio.DatagramProtocol):
    """A CHUDP relay: datagrams from clients to ``upstream`` and back, each recorded (module docstring)."""

    def __init__(self, recorder: Recorder, upstream: Endpoint) -> None:
        self.recorder = recorder
        self.upstream = upstream
        self.transport: asyncio.DatagramTransport | None = None
        self._clients: dict[tuple[str, int], _Upstream] = {}
        self._opening: dict[tuple[str, int], list[bytes]] = {}

    async def start(self, host: str, port: int) -> Endpoint:
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(host, port))
        assert self.transport is not None
        return Endpoint("chudp", host, int(self.transport.get_extra_info("sockname")[1]))

    async def aclose(self) -> None:
        for up in self._clients.values():
            if up.transport is not None:
                up.transport.close()
            if not self.recorder.closed:
                self.recorder.close_link(up.link, "relay stopping")
        self._clients.clear()
        if self.transport is not None:
            self.transport.close()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: Any) -> None:
        client = (str(addr[0]), int(addr[1]))
        up = self._clients.get(client)
        if up is not None:
            self._to_server(up, data)
            return
        queue = self._opening.get(client)
        if queue is not None:  # its upstream socket is being made
            queue.append(data)
            return
        self._opening[client] = [data]
        asyncio.get_running_loop().create_task(self._open(client))

    async def _open(self, client: tuple[str, int]) -> None:
        loop = asyncio.get_running_loop()
        link = self.recorder.open_link("chudp", name=f"{client[0]}:{client[1]} -> {self.upstream}")
        try:
            _, up = await loop.create_datagram_endpoint(
                lambda: _Upstream(self, client, link), remote_addr=(self.upstream.host, self.upstream.port)
            )
        except OSError as exc:
            self._opening.pop(client, None)
            self.recorder.close_link(link, f"cannot reach upstream {self.upstream}: {exc}")
            return
        self._clients[client] = up
        for data in self._opening.pop(client, []):
            self._to_server(up, data)

    def _to_server(self, up: _Upstream, data: bytes) -> None:
        if up.transport is not None:
            up.transport.sendto(data)
        if not self.recorder.closed:
            self.recorder.frame(up.link, "c2s", data)

    def _from_server(self, up: _Upstream, data: bytes) -> None:
        if self.transport is not None:
            self.transport.sendto(data, up.client)
        if not self.recorder.closed:
            self.recorder.frame(up.link, "s2c", data)


async def start_proxy(
    recorder: Recorder, listen: Endpoint, upstream: Endpoint
) -> tuple[TcpProxy | ChudpRelay, Endpoint]:
    """Start the proxy for ``listen``'s scheme; returns it and the bound end."""
    if listen.scheme != upstream.scheme:
        raise CaptureError(
            f"cannot proxy {listen.scheme}:// to {upstream.scheme}://: use the same link on both sides"
        )
    proxy: TcpProxy | ChudpRelay = (
        TcpProxy(recorder, upstream) if listen.scheme == "tcp" else ChudpRelay(recorder, upstream)
    )
    try:
        bound = await proxy.start(listen.host, listen.port)
    except OSError as exc:
        raise CaptureError(f"cannot listen on {listen}: {exc}") from exc
    return proxy, bound
