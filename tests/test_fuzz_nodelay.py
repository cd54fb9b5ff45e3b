"""The server's TCP links send small frames at once (TCP_NODELAY).

Found by the fuzz campaign's timing: the guarded listener accepts sockets itself, and asyncio sets
TCP_NODELAY only on the sockets it accepts, so replies behind an unacknowledged one waited some 40 ms
for the client's delayed acknowledgement and pipelined requests crawled (about 400 fuzz inputs a
second instead of over 1,000).
"""

from __future__ import annotations

import asyncio
import socket

from manip.links import open_connection
from manip.reference_server import ServerConfig
from manip.reference_server.driver import serve


def _server_sockets(server: object) -> list[socket.socket]:
    socks = []
    for chaos_server in server.servers:  # type: ignore[attr-defined]
        for link in chaos_server.node.links:
            transport = getattr(link, "_transport", None)
            if transport is not None:
                socks.append(transport.get_extra_info("socket"))
    return socks


def test_an_accepted_tcp_link_has_nodelay() -> None:
    async def main() -> list[int]:
        async with serve("tcp://127.0.0.1:0", ServerConfig()) as server:
            conn = await open_connection(server.address)
            try:
                socks = _server_sockets(server)
                return [s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) for s in socks]
            finally:
                await conn.close()

    flags = asyncio.run(main())
    assert flags, "no accepted TCP link found"
    assert all(flags), flags
