"""The routing chaosd stand-in (manip.links.chaosd_router): frames go to the host their trailer names,
learnt from the frames' sources; what it cannot route it drops and counts."""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any

import pytest

from manip.codecs.framing import decode_chaosd, encode_chaosd
from manip.codecs.packet import Packet
from manip.spec.constants import ChaosOp
from tests.support.chaosd_router import chaosd_router

Host = tuple[asyncio.StreamReader, asyncio.StreamWriter]


def run(coro: Coroutine[Any, Any, None]) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(10):
            await coro

    asyncio.run(bounded())


def frame(source: int, dest: int, data: bytes) -> bytes:
    return encode_chaosd(Packet(ChaosOp.DAT, dest, 1, source, 2, 3, 0, data))


async def received(host: Host) -> Packet:
    reader = host[0]
    header = await reader.readexactly(4)
    return decode_chaosd(header + await reader.readexactly(header[0] << 8 | header[1]))


async def settled(router: Any, count: int) -> None:
    """Wait (turns of the loop) until the router has taken ``count`` frames."""
    while len(router.frames) < count:
        await asyncio.sleep(0)


def test_frames_go_to_the_host_the_trailer_names() -> None:
    async def main() -> None:
        async with chaosd_router() as (path, router):
            server = await asyncio.open_unix_connection(str(path))
            await router.name_silent(0o440)
            a1, b = (
                await asyncio.open_unix_connection(str(path)),
                await asyncio.open_unix_connection(str(path)),
            )
            a1[1].write(frame(0o401, 0o440, b"from a"))
            b[1].write(frame(0o402, 0o440, b"from b"))
            assert {(await received(server)).data for _ in range(2)} == {b"from a", b"from b"}
            server[1].write(frame(0o440, 0o402, b"to b") + frame(0o440, 0o401, b"to a"))
            assert (await received(b)).data == b"to b"
            assert (await received(a1)).data == b"to a"
            # A second connection from 0401 heard from last gets 0401's packets, the first once it closes.
            a2 = await asyncio.open_unix_connection(str(path))
            a2[1].write(frame(0o401, 0o440, b"from a again"))
            assert (await received(server)).data == b"from a again"
            server[1].write(frame(0o440, 0o401, b"to a2"))
            assert (await received(a2)).data == b"to a2"
            a2[1].close()
            await a2[1].wait_closed()
            while router.connected > 3:
                await asyncio.sleep(0)
            server[1].write(frame(0o440, 0o401, b"to a1"))
            assert (await received(a1)).data == b"to a1"
            assert router.forwarded == 7 and not router.dropped
            for _, w in (server, a1, b):
                w.close()
                await w.wait_closed()

    run(main())


def test_what_cannot_be_routed_is_dropped_and_counted() -> None:
    async def main() -> None:
        async with chaosd_router() as (path, router):
            a = await asyncio.open_unix_connection(str(path))
            a[1].write(frame(0o401, 0o777, b"to nobody"))  # no host has sent from 0777
            await settled(router, 1)
            assert router.dropped == {"unroutable": 1} and router.forwarded == 0
            a[1].write(b"\x00\x16\x02\x00" + bytes(22))  # header bytes 2-3 must be 01 00
            assert await a[0].read() == b""  # the router closed the connection
            assert router.dropped == {"unroutable": 1, "framing lost": 1}
            a[1].close()

    run(main())


def test_naming_hosts_that_never_connect_times_out() -> None:
    async def main() -> None:
        async with chaosd_router() as (path, router):
            server = await asyncio.open_unix_connection(str(path))
            with pytest.raises(TimeoutError, match="1 of 2 host"):
                await router.name_silent(0o440, hosts=2, timeout=0.05)
            await router.name_silent(0o440, timeout=0.05)  # the one connected is named
            server[1].close()
            await server[1].wait_closed()

    run(main())
