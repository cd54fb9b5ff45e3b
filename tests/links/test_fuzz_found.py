"""Defects of the links that the fuzz campaign and the soak found, each fixed and held here.

* TCP_NODELAY (found by the campaign's timing): the guarded listener accepts sockets itself, and
  asyncio sets TCP_NODELAY only on the sockets it accepts, so replies behind an unacknowledged one
  waited some 40 ms for the client's delayed acknowledgement and pipelined requests crawled (about 400
  fuzz inputs a second instead of over 1,000).
* Log lines a peer causes (found by the soak: 13,896 in an hour): a client that resets its link while
  the server still has replies for it made asyncio log ``socket.send() raised exception.`` for every
  write after the reset.
"""

from __future__ import annotations

import asyncio
import logging
import socket

import pytest

from manip.conformance.fuzz.batch import BatchRunner
from manip.conformance.fuzz.session import Allowance
from manip.links import open_connection, parse_address
from manip.reference_server.driver import ReferenceServer
from manip.spec.constants import RequestOp
from tests.support.servers import running_server


def _server_sockets(server: ReferenceServer) -> list[socket.socket]:
    socks = []
    for chaos_server in server.servers:
        for link in chaos_server.node.links:
            transport = getattr(link, "_transport", None)
            if transport is not None:
                socks.append(transport.get_extra_info("socket"))
    return socks


def test_an_accepted_tcp_link_has_nodelay(served: ReferenceServer) -> None:
    async def main() -> list[int]:
        conn = await open_connection(served.address)
        try:
            socks = _server_sockets(served)
            return [s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) for s in socks]
        finally:
            await conn.close()

    flags = asyncio.run(main())
    assert flags, "no accepted TCP link found"
    assert all(flags), flags


@pytest.mark.waits
def test_a_client_resetting_while_replies_are_due_logs_nothing(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> int:
        # In the test's own loop, at its own pace: the server has stopped before the log is read.
        async with running_server(time_scale=1.0) as server:
            runner = BatchRunner(parse_address(server.address), Allowance())
            for _ in range(10):
                link = await runner.link()
                conn = await runner.connect(link)
                for _ in range(300):  # describe self: nine packets each, so the replies pile up
                    await conn.request(RequestOp.DESCRIBE_SELF, b"", lazy=True)
                link.close(reset=True)
                await asyncio.sleep(0.2)
                conn.close()
            served = server.stats.requests
        return served

    with caplog.at_level(logging.WARNING, logger="asyncio"):
        served = asyncio.run(main())
    assert served > 100, "the requests reached the server"
    noise = [r.getMessage() for r in caplog.records if r.name == "asyncio"]
    assert not noise, f"{len(noise)} log lines, e.g. {noise[0]!r}"
