"""The two calls an application needs: :func:`open_connection` and :func:`start_server`.

Both take one link address (:mod:`manip.links.address`).  The Chaos addresses in it are read the same
way on both sides: ``addr`` is the robot host's address (the server's own), ``me`` the client's.  So a
client and a server given the same URL agree on who is who.
"""

from __future__ import annotations

import asyncio
import ipaddress
import logging
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import replace
from types import TracebackType
from typing import Protocol

from manip.ncp import ConnectionRequested, NcpConfig

from .address import LinkAddress, parse_address
from .base import Link
from .chaos_connection import CLOSE_TIMEOUT, ChaosConnection
from .chaosd import connect_chaosd, serve_chaosd
from .chudp import Endpoint, bind_chudp
from .errors import ChaosError
from .guard import AccessList, LinkGuard, LinkLimits
from .ncp_driver import BUSY, AcceptPolicy, Node
from .tcp import connect_tcp, connect_unix, serve_tcp, serve_unix

log = logging.getLogger("manip.links")

Handler = Callable[[ChaosConnection], Awaitable[None]]
"""A server's per-connection coroutine; the connection is closed gracefully when it returns."""
LinkWrapper = Callable[[Link], Link]
"""Given each new link, returns the link the node should use (the same one, or a wrapper of it)."""


class Listening(Protocol):
    """What a server listens with (a :class:`~manip.links.listener.StreamListener`, an asyncio server)."""

    def close(self) -> None: ...

    async def wait_closed(self) -> None: ...


def _address(address: str | LinkAddress) -> LinkAddress:
    return parse_address(address) if isinstance(address, str) else address


def _local_for(host: str) -> tuple[str, int]:
    """Where a CHUDP client binds when ``local=`` is not given: loopback for a loopback peer."""
    v6 = ":" in host
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = False
    if loopback:
        return ("::1" if v6 else "127.0.0.1", 0)
    return ("::" if v6 else "0.0.0.0", 0)


async def _client_link(addr: LinkAddress, timeout: float | None, learn_peers: bool) -> tuple[Link, bool]:
    """The link a client dials; True when it should be the default route (a routing daemon)."""
    if addr.scheme == "tcp":
        return await connect_tcp(
            addr.host, addr.port, my_addr=addr.my_addr, peer_addr=addr.peer_addr, timeout=timeout
        ), False
    if addr.scheme == "chudp":
        host, port = addr.local or _local_for(addr.host)
        link = await bind_chudp(
            host,
            port,
            my_addr=addr.my_addr,
            peers={addr.peer_addr: (addr.host, addr.port)},
            learn_peers=learn_peers,
        )
        return link, False
    assert addr.path is not None
    if addr.scheme == "unix":
        return await connect_unix(
            addr.path, my_addr=addr.my_addr, peer_addr=addr.peer_addr, timeout=timeout
        ), False
    return await connect_chaosd(addr.path, my_addr=addr.my_addr, timeout=timeout), True


async def open_connection(
    address: str | LinkAddress,
    *,
    timeout: float | None = 10.0,
    contact: str | None = None,
    args: bytes | str = b"",
    options: NcpConfig | None = None,
    learn_peers: bool = False,
    wrap_link: LinkWrapper | None = None,
) -> ChaosConnection:
    """Make the link, send the RFC to the address's contact and wait for the OPN.

    The connection owns its link: closing it closes the link.  ``wrap_link`` may put a wrapper
    between the node and its link (a recording tap, :class:`manip.captures.TappedLink`).  Raises
    LinkError (no link), ConnectionRefused (CLS, with the server's reason), ConnectionLost (LOS),
    ConnectTimeout, or ConnectionAnswered / ConnectionForwarded for the rarer answers to an RFC."""
    addr = _address(address)
    loop = asyncio.get_running_loop()
    deadline = None if timeout is None else loop.time() + timeout
    node = Node(addr.my_addr, options)
    try:
        link, default = await _client_link(addr, timeout, learn_peers)
        node.attach(wrap_link(link) if wrap_link else link, hosts=[addr.peer_addr], default=default)
        remaining = None if deadline is None else max(0.0, deadline - loop.time())
        conn = await node.connect(addr.peer_addr, contact or addr.contact, args, timeout=remaining)
    except BaseException:
        await node.aclose()
        raise
    conn.owns_node = True
    return conn


class ChaosServer:
    """A listening node: one contact name on one link address, a handler task per connection.

    ``address`` is the address actually bound (port 0 replaced by the real port); ``guard`` applies
    the server's limits and access rules and counts what it refused (``guard.stats``)."""

    def __init__(
        self,
        node: Node,
        address: LinkAddress,
        contact: str,
        handler: Handler,
        server: Listening | None,
        guard: LinkGuard | None = None,
    ) -> None:
        self.node = node
        self.guard = guard or LinkGuard(LinkLimits.unlimited(), name=str(address))
        self.address = address
        self.contact = contact
        self._handler = handler
        self._server = server
        self._tasks: set[asyncio.Task[None]] = set()
        self._closed = asyncio.get_running_loop().create_future()

    def __repr__(self) -> str:
        return f"<ChaosServer {self.contact} at {self.address}>"

    @property
    def port(self) -> int:
        return self.address.port

    @property
    def connections(self) -> list[ChaosConnection]:
        return self.node.connections

    def _on_open(self, conn: ChaosConnection) -> None:
        task = asyncio.get_running_loop().create_task(
            self._run(conn), name=f"chaos-handler-{conn.conn_id:#x}"
        )
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _run(self, conn: ChaosConnection) -> None:
        try:
            await self._handler(conn)
        except asyncio.CancelledError:
            conn.abort("Server closing")
            raise
        except ChaosError as exc:
            log.debug("%s: handler ended by %r", self, exc)
        except Exception:
            log.exception("%s: handler failed", self)
            conn.abort("Server error")
        if not conn.ended:
            await conn.close(CLOSE_TIMEOUT)

    def close(self, reason: str = "Server closing") -> None:
        """Stop listening, abort every connection with ``reason`` and close the links."""
        if self._closed.done():
            return
        self._closed.set_result(None)
        if self._server is not None:
            self._server.close()
        self.guard.close()
        for task in list(self._tasks):
            task.cancel()
        self.node.close(reason)

    async def wait_closed(self) -> None:
        await self._closed
        if self._tasks:
            await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._server is not None:
            await self._server.wait_closed()
        await self.node.wait_closed()

    async def aclose(self, reason: str = "Server closing") -> None:
        self.close(reason)
        await self.wait_closed()

    async def serve_forever(self) -> None:
        """Wait until the server is closed."""
        await asyncio.shield(self._closed)

    async def __aenter__(self) -> ChaosServer:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.aclose()


async def start_server(
    address: str | LinkAddress,
    contact: str | None,
    handler: Handler,
    *,
    max_connections: int | None = None,
    busy_reason: str = BUSY,
    policy: AcceptPolicy | None = None,
    options: NcpConfig | None = None,
    learn_peers: bool = True,
    peers: Mapping[int, Endpoint] | None = None,
    wrap_link: LinkWrapper | None = None,
    limits: LinkLimits | None = None,
    allow: AccessList | None = None,
    chaosd_daemon: bool = False,
) -> ChaosServer:
    """Listen for ``contact`` (None: the address's) as Chaos host ``addr`` of ``address``.

    tcp:// listens on HOST:PORT (port 0: a free one, see ``ChaosServer.port``), unix:// on a socket
    file (which must not exist yet); chudp:// binds
    HOST:PORT and learns its clients (``learn_peers``) besides the configured ``peers``; chaosd://
    connects to the daemon, or with ``chaosd_daemon`` stands in for it: listens on its socket file
    (which must not exist yet) for hosts that dial it.  ``max_connections=1`` refuses a second client
    with ``busy_reason`` while one is connected: one Puma server is one robot.  ``wrap_link`` wraps
    every link the node gets (see :func:`open_connection`).

    ``limits`` bound the TCP links (default :class:`LinkLimits`: idle and half-sent links are closed,
    at most 256 at once) and ``allow`` says who may connect (default: everyone), by IP address for TCP
    and CHUDP peers and by Chaos address for RFCs; see :mod:`manip.links.guard`."""
    addr = _address(address)
    name = contact or addr.contact
    node = Node(addr.peer_addr, options)
    defects = options.defects if options is not None else None
    guard = LinkGuard(limits, allow, in_use=node.links_in_use, name=str(addr))

    def attach(link: Link, hosts: Iterable[int] = (), default: bool = False) -> Link:
        seen = wrap_link(link) if wrap_link else link
        node.attach(seen, hosts=hosts, default=default)
        return seen

    if guard.access.restricts_chaos:
        policy = _guarded(guard, policy)
    server: ChaosServer | None = None
    tcp: Listening | None = None
    try:
        if addr.scheme == "tcp":
            listener = await serve_tcp(
                addr.host,
                addr.port,
                my_addr=addr.peer_addr,
                on_link=lambda link: guard.track(link, attach(link)),
                guard=guard,
                defects=defects,
            )
            tcp = listener
            bound = replace(addr, port=int(listener.sockets[0].getsockname()[1]))
        elif addr.scheme == "unix":
            assert addr.path is not None
            tcp = await serve_unix(
                addr.path,
                my_addr=addr.peer_addr,
                on_link=lambda link: guard.track(link, attach(link)),
                guard=guard,
                defects=defects,
            )
            bound = addr
        elif addr.scheme == "chudp":
            admit = guard.admit_datagram if guard.access.restricts_ip else None
            link = await bind_chudp(
                addr.host,
                addr.port,
                my_addr=addr.peer_addr,
                peers=peers,
                learn_peers=learn_peers,
                admit=admit,
                defects=defects,
            )
            attach(link, hosts=list(link.peers))
            bound = replace(addr, port=link.local_address[1])
        elif chaosd_daemon:
            assert addr.path is not None
            tcp = await serve_chaosd(
                addr.path,
                my_addr=addr.peer_addr,
                on_link=lambda link: guard.track(link, attach(link)),
                guard=guard,
            )
            bound = addr
        else:
            assert addr.path is not None
            attach(await connect_chaosd(addr.path, my_addr=addr.peer_addr, defects=defects), default=True)
            bound = addr
        guard.name = str(bound)
        server = ChaosServer(node, bound, name, handler, tcp, guard)
        node.listen(
            name, server._on_open, policy=policy, max_connections=max_connections, busy_reason=busy_reason
        )
    except BaseException:
        if tcp is not None:
            tcp.close()
        guard.close()
        await node.aclose()
        raise
    return server


def _guarded(guard: LinkGuard, policy: AcceptPolicy | None) -> AcceptPolicy:
    """``policy`` behind the guard's Chaos address rules (a refused host never reaches ``policy``)."""

    def check(request: ConnectionRequested) -> str | None:
        refusal = guard.admit_rfc(request)
        if refusal is not None or policy is None:
            return refusal
        return policy(request)

    return check
