"""The driver over usim's chaosd unix socket, through the routing chaosd stand-in (links/chaosd_router)."""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from collections.abc import Coroutine, Iterator
from pathlib import Path
from typing import Any

import pytest

from manip.links import ChaosConnection, LinkError, NcpConfig, open_connection, start_server
from manip.links.chaosd import ChaosdLink, connect_chaosd
from tests.support.chaosd_router import chaosd_router

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)


def run(coro: Coroutine[Any, Any, None], timeout: float = 10.0) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


@pytest.fixture
def socket_dir() -> Iterator[Path]:
    """A short directory for the socket (unix socket paths are limited to about 100 bytes)."""
    path = Path(tempfile.mkdtemp(prefix="chaosd", dir="/tmp"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


def test_round_trip_through_a_chaosd_router() -> None:
    async def echo(conn: ChaosConnection) -> None:
        async for packet in conn:
            await conn.send(packet.data.upper())

    async def main() -> None:
        async with chaosd_router() as (path, router):
            server = await start_server(f"chaosd://{path}?addr=0440", "PUMA", echo, options=FAST)
            await router.name_silent(0o440)
            url = f"chaosd://{path}?addr=0440"
            async with server, await open_connection(url, options=FAST) as conn:
                for word in (b"puma", b"arm", b"x"):
                    await conn.send(word)
                    assert (await conn.receive()).data == word.upper()
            # usim's framing: big-endian length, 01 00, then little-endian words; the RFC first.
            rfc = router.frames[0]
            assert rfc[:4] == bytes([0, 26, 1, 0])
            assert rfc[4:8] == b"\x00\x01\x04\x00"  # opcode 1 in the high byte; nbytes 4
            assert rfc[8:12] == b"\x20\x01\x00\x00"  # to 0440, index 0
            assert rfc[12:14] == b"\x01\x01"  # from 0401
            assert rfc[20:24] == b"PUMA"  # data in natural order
            assert rfc[24:28] == b"\x20\x01\x01\x01"  # trailer: the daemon routes to 0440; from 0401

    run(main())


def test_chaosd_framing_loss_closes_the_link(socket_dir: Path) -> None:
    async def main() -> None:
        path = socket_dir / "bad"

        async def garbage(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            writer.write(b"\x00\x16\x02\x00" + bytes(22))  # header bytes 2-3 must be 01 00
            await reader.read()
            writer.close()

        daemon = await asyncio.start_unix_server(garbage, str(path))
        async with daemon:
            link = await connect_chaosd(str(path), my_addr=0o401)
            assert isinstance(link, ChaosdLink)
            await link.closed
            assert link.stats.bad == {"framing": 1}
            assert "framing lost" in str(link.close_reason)

    run(main())


def test_no_chaosd_daemon(socket_dir: Path) -> None:
    async def main() -> None:
        with pytest.raises(LinkError, match="chaosd"):
            await open_connection(f"chaosd://{socket_dir / 'absent'}", timeout=1)

    run(main())
