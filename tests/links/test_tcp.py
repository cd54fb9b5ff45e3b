"""The asyncio driver over manip's TCP link: round trips, back-pressure, refusals, closes, failures."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any

import pytest

from manip.codecs.errors import DecodeError
from manip.codecs.framing import TcpFrameDecoder, decode_tcp, encode_tcp
from manip.codecs.packet import Packet
from manip.links import (
    ChaosConnection,
    ChaosServer,
    ConnectionAnswered,
    ConnectionBroken,
    ConnectionClosed,
    ConnectionForwarded,
    ConnectionLost,
    ConnectionRefused,
    ConnectTimeout,
    LinkError,
    NcpConfig,
    open_connection,
    start_server,
)
from manip.links.stream import StreamLink
from manip.spec.constants import ChaosOp

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)


def run(coro: Coroutine[Any, Any, None], timeout: float = 10.0) -> None:
    """Run one test coroutine on a fresh loop, bounded so a hang fails instead of stalling."""

    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


async def serve(
    handler: Callable[[ChaosConnection], Awaitable[None]], **kwargs: Any
) -> tuple[ChaosServer, str]:
    kwargs.setdefault("options", FAST)
    server = await start_server("tcp://127.0.0.1:0", "PUMA", handler, **kwargs)
    return server, f"tcp://127.0.0.1:{server.port}"


async def echo(conn: ChaosConnection) -> None:
    async for packet in conn:
        await conn.send(packet.data[::-1], packet.opcode)


def server_links(server: ChaosServer) -> list[StreamLink]:
    return [link for link in server.node.links if isinstance(link, StreamLink)]


# ------------------------------------------------------------------------------ data both ways


def test_round_trip_many_packets_both_ways() -> None:
    seen_by_server: list[Packet] = []

    async def handler(conn: ChaosConnection) -> None:
        assert conn.rfc_args == b"hello arm"
        assert conn.rfc is not None and conn.rfc.opcode == ChaosOp.RFC
        for i in range(3):  # the server speaks first, too
            await conn.send(b"greeting %d" % i)
        async for packet in conn:
            seen_by_server.append(packet)
            await conn.send(packet.data[::-1], 0o300)

    async def main() -> None:
        server, url = await serve(handler)
        async with server:
            conn = await open_connection(url, args=b"hello arm", options=FAST)
            async with conn:
                assert conn.peer[0] == 0o440 and conn.peer[1] != 0
                greetings = [await conn.receive() for _ in range(3)]
                assert [g.data for g in greetings] == [b"greeting 0", b"greeting 1", b"greeting 2"]
                sent, got = [], []
                for i in range(300):
                    data = bytes([i % 256]) * (1 + i % 488)
                    sent.append(await conn.send(data))
                    reply = await conn.receive()
                    assert reply.data == data[::-1] and reply.opcode == 0o300
                    assert reply.src_host == 0o440 and reply.dest_host == 0o401
                    got.append(reply)
                # Chaos packet numbers: consecutive on both sides (mod 2^16), acks follow ours.
                assert sent == [(sent[0] + k) & 0xFFFF for k in range(300)]
                numbers = [p.packet_no for p in greetings + got]
                assert numbers == [(numbers[0] + k) & 0xFFFF for k in range(303)]
                assert [p.packet_no for p in seen_by_server] == sent
                assert all(r.ack_no == s for r, s in zip(got, sent, strict=True))
                assert conn.stats.packets_sent == 300 and conn.stats.packets_received == 303
            assert isinstance(conn.end_reason, ConnectionClosed) and not conn.end_reason.by_peer
            assert conn.node.is_closed

    run(main())


def test_window_back_pressure() -> None:
    """send() waits while the peer's window is full, i.e. until the peer's user reads."""
    may_read = asyncio.Event

    async def main() -> None:
        go = may_read()
        got: list[bytes] = []

        async def slow_reader(conn: ChaosConnection) -> None:
            await go.wait()
            async for packet in conn:
                got.append(packet.data)

        server, url = await serve(slow_reader, options=NcpConfig(window=4, ack_delay=0.01))
        async with server:
            async with await open_connection(url, options=FAST) as conn:
                for i in range(4):
                    await conn.send(b"%d" % i)
                assert not conn.can_send() and conn.window_space() == 0
                blocked = asyncio.ensure_future(conn.send(b"4"))
                await asyncio.sleep(0.3)  # the server's NCP has everything; its user has read nothing
                assert not blocked.done()
                go.set()
                await blocked
                assert conn.stats.send_waits >= 1
            assert got == [b"0", b"1", b"2", b"3", b"4"]

    run(main())


# ------------------------------------------------------------------------------ refusals


def test_refused_without_listener_for_the_contact() -> None:
    async def main() -> None:
        server, url = await serve(echo)
        async with server:
            with pytest.raises(ConnectionRefused, match="No server for this contact name"):
                await open_connection(url + "?contact=COUGAR", options=FAST)

    run(main())


def test_no_tcp_listener_is_a_link_error() -> None:
    async def main() -> None:
        probe = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = probe.sockets[0].getsockname()[1]
        probe.close()
        await probe.wait_closed()
        with pytest.raises(LinkError, match="cannot reach"):
            await open_connection(f"tcp://127.0.0.1:{port}", timeout=2)

    run(main())


def test_second_connection_refused_while_one_is_open() -> None:
    async def main() -> None:
        server, url = await serve(echo, max_connections=1, busy_reason="Puma busy")
        async with server:
            first = await open_connection(url, options=FAST)
            with pytest.raises(ConnectionRefused, match="Puma busy") as info:
                await open_connection(url, options=FAST)
            assert info.value.reason == "Puma busy"
            await first.send(b"still here")
            assert (await first.receive()).data == b"ereh llits"
            await first.close()
            await asyncio.sleep(0)  # let the server's handler finish
            async with await open_connection(url, options=FAST) as again:  # free once the first is gone
                await again.send(b"ab")
                assert (await again.receive()).data == b"ba"

    run(main())


def test_rfc_unanswered_times_out() -> None:
    async def main() -> None:
        async def mute(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            await reader.read()
            writer.close()

        tcp = await asyncio.start_server(mute, "127.0.0.1", 0)
        port = tcp.sockets[0].getsockname()[1]
        async with tcp:
            with pytest.raises(ConnectTimeout):
                await open_connection(f"tcp://127.0.0.1:{port}", timeout=0.3, options=FAST)
            with pytest.raises(TimeoutError):  # ConnectTimeout is a TimeoutError too
                await open_connection(f"tcp://127.0.0.1:{port}", timeout=0.2, options=FAST)

    run(main())


@pytest.mark.parametrize(
    ("opcode", "ack_no", "data", "error", "match"),
    [
        pytest.param(ChaosOp.LOS, 0, b"Go away", ConnectionLost, "Go away", id="LOS"),
        pytest.param(ChaosOp.CLS, 0, b"Not today", ConnectionRefused, "Not today", id="CLS"),
        pytest.param(ChaosOp.ANS, 0, b"42", ConnectionAnswered, "simple answer of 2 bytes", id="ANS"),
        pytest.param(ChaosOp.FWD, 0o3040, b"PUMA2", ConnectionForwarded, "PUMA2.*3040", id="FWD"),
    ],
)
def test_rfc_answers_other_than_opn(
    opcode: int, ack_no: int, data: bytes, error: type[Exception], match: str
) -> None:
    """A peer NCP (hand-made here) answering the RFC with LOS, CLS, ANS or FWD: each its exception."""

    async def main() -> None:
        async def answering(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            decoder = TcpFrameDecoder()
            while chunk := await reader.read(4096):
                for rfc in decoder.feed(chunk):
                    assert isinstance(rfc, Packet) and rfc.data == b"PUMA"
                    answer = Packet(opcode, rfc.src_host, rfc.src_index, 0o440, 0, 0, ack_no, data)
                    writer.write(encode_tcp(answer))
            writer.close()

        tcp = await asyncio.start_server(answering, "127.0.0.1", 0)
        port = tcp.sockets[0].getsockname()[1]
        async with tcp:
            with pytest.raises(error, match=match) as info:
                await open_connection(f"tcp://127.0.0.1:{port}", timeout=3, options=FAST)
            if isinstance(info.value, ConnectionAnswered):
                assert info.value.data == b"42"
            if isinstance(info.value, ConnectionForwarded):
                assert (info.value.host, info.value.contact) == (0o3040, "PUMA2")

    run(main())


def test_send_checks_and_single_reader() -> None:
    async def main() -> None:
        server, url = await serve(echo)
        async with server, await open_connection(url, options=FAST) as conn:
            with pytest.raises(ValueError, match="0200-0377"):
                await conn.send(b"x", ChaosOp.EOF)
            with pytest.raises(ValueError, match="more than 488"):
                await conn.send(bytes(489))
            reader = asyncio.ensure_future(conn.receive())
            await asyncio.sleep(0)
            with pytest.raises(RuntimeError, match="already waiting"):
                await conn.receive()
            await conn.send(bytes(488))
            assert (await reader).data == bytes(488)
            assert conn.receive_nowait() is None

    run(main())


def test_close_fails_a_send_waiting_for_the_window() -> None:
    async def main() -> None:
        async def never_reads(conn: ChaosConnection) -> None:
            await asyncio.sleep(30)

        server, url = await serve(never_reads, options=NcpConfig(window=2))
        async with server:
            conn = await open_connection(url, options=FAST)
            await conn.send(b"1")
            await conn.send(b"2")
            blocked = asyncio.ensure_future(conn.send(b"3"))
            await asyncio.sleep(0.01)
            closing = asyncio.ensure_future(conn.close(timeout=0.2))
            with pytest.raises(ConnectionClosed, match="closing"):
                await blocked
            await closing  # the peer never reads our EOF: the close times out into an abort
            assert conn.end_reason is not None and "Close timed out" in conn.end_reason.reason

    run(main())


# ------------------------------------------------------------------------------ ends


def test_graceful_close_seen_by_the_server() -> None:
    async def main() -> None:
        ended: asyncio.Future[tuple[list[bytes], BaseException]] = asyncio.get_running_loop().create_future()

        async def collector(conn: ChaosConnection) -> None:
            got = []
            try:
                while True:
                    got.append((await conn.receive()).data)
            except ConnectionClosed as exc:
                ended.set_result((got, exc))

        server, url = await serve(collector)
        async with server:
            conn = await open_connection(url, options=FAST)
            for i in range(20):
                await conn.send(b"%d" % i)
            await conn.close()
            got, exc = await ended
            assert got == [b"%d" % i for i in range(20)]
            assert isinstance(exc, ConnectionClosed) and exc.reason == "EOF" and exc.by_peer
            assert conn.ended and not conn.end_reason.by_peer  # type: ignore[union-attr]
            with pytest.raises(ConnectionClosed):
                await conn.send(b"too late")

    run(main())


def test_server_closes_after_sending() -> None:
    async def main() -> None:
        async def talker(conn: ChaosConnection) -> None:
            for i in range(5):
                await conn.send(b"line %d" % i)
            # returning closes gracefully: EOF after the data, then CLS

        server, url = await serve(talker)
        async with server, await open_connection(url, options=FAST) as conn:
            lines = [p.data async for p in conn]
            assert lines == [b"line %d" % i for i in range(5)]
            with pytest.raises(ConnectionClosed, match="EOF"):
                await conn.receive()

    run(main())


def test_abort_seen_by_the_peer_with_its_reason() -> None:
    async def main() -> None:
        ended: asyncio.Future[BaseException] = asyncio.get_running_loop().create_future()

        async def waiter(conn: ChaosConnection) -> None:
            try:
                await conn.receive()
            except ConnectionClosed as exc:
                ended.set_result(exc)

        server, url = await serve(waiter)
        async with server:
            conn = await open_connection(url, options=FAST)
            conn.abort("Emergency stop")
            exc = await ended
            assert isinstance(exc, ConnectionClosed) and exc.reason == "Emergency stop" and exc.by_peer
            assert isinstance(conn.end_reason, ConnectionClosed)
            assert conn.end_reason.reason == "aborted: Emergency stop"

    run(main())


def test_server_abort_seen_by_the_client() -> None:
    async def main() -> None:
        async def rude(conn: ChaosConnection) -> None:
            await conn.send(b"bye")
            conn.abort("Power failure")

        server, url = await serve(rude)
        async with server:
            conn = await open_connection(url, options=FAST)
            with pytest.raises(ConnectionClosed, match="Power failure"):
                while True:  # the data may or may not beat the CLS; the CLS ends it either way
                    await conn.receive()
            await conn.close()

    run(main())


def test_silent_peer_is_broken() -> None:
    """The server stops reading its socket: after broken_after the client's connection is broken."""

    async def main() -> None:
        started = asyncio.Event()

        async def idle(conn: ChaosConnection) -> None:
            started.set()  # the server's NCP has our STS: it has nothing left to retransmit
            await asyncio.sleep(30)

        server, url = await serve(idle)
        async with server:
            options = NcpConfig(broken_after=0.5, retransmit_interval=0.1, ack_delay=0.01)
            conn = await open_connection(url, options=options)
            await started.wait()
            for link in server_links(server):
                link.pause_reading()
            loop = asyncio.get_running_loop()
            start = loop.time()
            with pytest.raises(ConnectionBroken, match="No packet from the peer"):
                await conn.receive()
            assert 0.3 < loop.time() - start < 2.0
            with pytest.raises(ConnectionBroken):
                await conn.send(b"x")
            await conn.close()

    run(main())


def test_killed_link_breaks_the_connection() -> None:
    async def main() -> None:
        async def idle(conn: ChaosConnection) -> None:
            await asyncio.sleep(30)

        server, url = await serve(idle)
        async with server:
            conn = await open_connection(url, options=NcpConfig(broken_after=5.0))
            for link in server_links(server):
                link.abort("test kills the link")
            with pytest.raises(ConnectionBroken, match="closed"):
                await conn.receive()
            assert conn.node.is_closed or not conn.node.links

    run(main())


# ------------------------------------------------------------------------------ bad input


def test_framing_garbage_closes_only_that_link() -> None:
    async def main() -> None:
        server, url = await serve(echo)
        async with server:
            good = await open_connection(url, options=FAST)
            await good.send(b"before")
            assert (await good.receive()).data == b"erofeb"

            port = server.port
            # A frame with a valid length but a corrupt checksum is skipped; the stream goes on.
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            frame = bytearray(encode_tcp(Packet(ChaosOp.RFC, 0o440, 0, 0o401, 0x4242, 1, 0, b"PUMA")))
            frame[-1] ^= 0xFF
            writer.write(bytes(frame))
            await writer.drain()
            while len(server_links(server)) < 2:
                await asyncio.sleep(0.001)
            (link,) = [link for link in server_links(server) if link.peer_addr is None]
            while not link.stats.bad:
                await asyncio.sleep(0.001)
            assert not link.is_closed
            # Then a length that cannot be a frame: the stream's framing is lost and it is closed.
            writer.write(b"\x00\x03garbage")
            await writer.drain()
            assert await asyncio.wait_for(reader.read(), 5) == b""  # the server hung up
            writer.close()
            await link.closed
            assert link.stats.bad == {"checksum": 1, "framing": 1}
            assert "framing lost" in str(link.close_reason)

            assert server.node.stats.links_closed == 1 and len(server_links(server)) == 1
            assert server.node.link_stats().bad == {"checksum": 1, "framing": 1}

            await good.send(b"after")  # the other link never noticed
            assert (await good.receive()).data == b"retfa"
            await good.close()

    run(main())


def _ones_sum(body: bytes | bytearray) -> int:
    """RFC 1071 sum of MSB-first words, written out so the test does not trust the codec."""
    total = 0
    for i in range(0, len(body), 2):
        total += body[i] << 8 | body[i + 1]
        total = (total & 0xFFFF) + (total >> 16)
    return total


async def _read_frame(reader: asyncio.StreamReader, timeout: float = 3.0) -> bytes:
    head = await asyncio.wait_for(reader.readexactly(2), timeout)
    return head + await asyncio.wait_for(reader.readexactly(int.from_bytes(head, "big")), timeout)


def test_illegal_opcode_frame_draws_los_and_garbled_frames_are_still_dropped() -> None:
    """A sound frame with an illegal opcode reaches the NCP, which answers LOS; garbled frames do not."""

    async def main() -> None:
        server, _url = await serve(echo)
        async with server:
            reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
            illegal = Packet(0o177, 0o440, 0x1234, 0o401, 0x0A01, 7, 6, b"xy")
            writer.write(encode_tcp(illegal))  # the encoder lets an illegal opcode through, on purpose
            los = decode_tcp(await _read_frame(reader))
            assert los.opcode == ChaosOp.LOS and los.data == b"Illegal opcode 177"
            assert (los.dest_host, los.dest_index, los.src_host, los.src_index) == (
                0o401,
                0x0A01,
                0o440,
                0x1234,
            )
            assert (los.packet_no, los.ack_no) == (7, 6)
            (link,) = server_links(server)
            assert link.stats.illegal == {"opcode": 1} and not link.stats.bad

            # Garbled: the same frame with a corrupt checksum; an opcode-0 frame whose count (489) is
            # beyond the frame.  Both are counted and dropped without an answer; the stream goes on.
            corrupt = bytearray(encode_tcp(illegal.with_(packet_no=8)))
            corrupt[-1] ^= 0xFF
            beyond = bytearray(encode_tcp(illegal.with_(opcode=0, packet_no=9)))
            beyond[4:6] = (489).to_bytes(2, "big")
            beyond[-2:] = (~_ones_sum(beyond[2:-2]) & 0xFFFF).to_bytes(2, "big")
            with pytest.raises(DecodeError) as garbled:
                decode_tcp(bytes(beyond), strict=False)
            assert garbled.value.clause == "chaos.opcode.legal"  # checksum fine: only the count is off
            writer.write(bytes(corrupt) + bytes(beyond) + encode_tcp(illegal.with_(packet_no=10)))
            los = decode_tcp(await _read_frame(reader))
            assert los.packet_no == 10  # nothing answered the two garbled frames
            assert link.stats.bad == {"checksum": 1, "opcode": 1}
            assert link.stats.illegal == {"opcode": 2} and not link.is_closed
            assert server.node.link_stats().illegal == {"opcode": 2}
            assert server.node.ncp.stats.los_sent == 2
            writer.close()

    run(main())


def test_stranger_on_another_link_cannot_hijack_a_connection() -> None:
    """Packets naming a connection that lives on another TCP link are dropped, and an RFC reusing a
    live connection's (host, index) on another link is refused."""

    async def main() -> None:
        server, url = await serve(echo)
        async with server:
            conn = await open_connection(url, options=FAST)
            host, index = 0o401, conn.conn_id
            server_index = conn.peer[1]
            reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
            spoof = Packet(ChaosOp.CLS, 0o440, server_index, host, index, data=b"spoofed")
            rfc = Packet(ChaosOp.RFC, 0o440, 0, host, index, 1, 0, b"PUMA")
            writer.write(encode_tcp(spoof) + encode_tcp(rfc))
            await writer.drain()
            decoder = TcpFrameDecoder()
            (reply,) = decoder.feed(await asyncio.wait_for(reader.read(4096), 5))
            assert isinstance(reply, Packet) and reply.opcode == ChaosOp.CLS
            assert b"in use on another link" in reply.data
            assert server.node.stats.wrong_link == 1 and server.node.stats.refused_conflicts == 1
            writer.close()
            await conn.send(b"ok")
            assert (await conn.receive()).data == b"ko"
            await conn.close()

    run(main())


def test_server_bound_port_and_close_aborts_clients() -> None:
    async def main() -> None:
        server, url = await serve(echo)
        assert server.port > 0 and str(server.port) in str(server.address)
        conn = await open_connection(url, options=FAST)
        assert len(server.connections) == 1
        await server.aclose("Server going down")
        with pytest.raises(ConnectionClosed, match="Server going down"):
            await conn.receive()
        await conn.close()
        with pytest.raises(LinkError):
            await open_connection(url, timeout=1)

    run(main())


def test_poller_wakeup() -> None:
    """The polling style of the reference client: a wake-up callback, then re-check the predicates."""

    async def main() -> None:
        go = asyncio.Event()

        async def slow_echo(conn: ChaosConnection) -> None:
            await go.wait()
            await echo(conn)

        server, url = await serve(slow_echo, options=NcpConfig(window=2, ack_delay=0.01))
        async with server, await open_connection(url, options=FAST) as conn:
            woken = asyncio.Event()
            conn.set_wakeup(woken.set)
            await conn.send(b"ab")
            await conn.send(b"cd")
            assert not conn.can_send() and conn.pending == 0
            woken.clear()
            go.set()
            while not conn.can_send() or conn.pending < 2:  # window reopened and both echoes arrived
                await woken.wait()
                woken.clear()
            first, second = conn.receive_nowait(), conn.receive_nowait()
            assert first is not None and second is not None
            assert (first.data, second.data) == (b"ba", b"dc") and conn.pending == 0
            woken.clear()
            conn.abort("done")
            await woken.wait()  # the end wakes the poller too
            assert conn.ended

    run(main())


def test_each_watched_connection_is_woken_when_its_own_window_opens() -> None:
    """Two watched connections on one server node, both with full send windows: the peer's
    acknowledgements on one wake that one's poller and only it (the node re-checks a window only where
    it can have opened, so this holds the narrowing to what it must still do)."""

    async def main() -> None:
        accepted: list[ChaosConnection] = []
        done = asyncio.Event()

        async def hold(conn: ChaosConnection) -> None:
            accepted.append(conn)
            await done.wait()

        server, url = await serve(hold)
        clients = [await open_connection(url, options=NcpConfig(window=2, ack_delay=0.01)) for _ in range(2)]
        async with server:
            while len(accepted) < 2:
                await asyncio.sleep(0.01)
            woken = [asyncio.Event(), asyncio.Event()]
            for conn, event in zip(accepted, woken, strict=True):
                conn.set_wakeup(event.set)
                await conn.send(b"1")
                await conn.send(b"2")  # the client's window of 2 is full: nothing is read yet
                assert not conn.can_send()
            for event in woken:
                event.clear()
            for k in (1, 0):  # the second client reads first
                for _ in range(2):
                    await clients[k].receive()  # reading acknowledges
                await asyncio.wait_for(woken[k].wait(), 2)  # promptly: a timer would be later
                assert accepted[k].can_send()
                if k == 1:
                    assert not woken[0].is_set() and not accepted[0].can_send()
            done.set()
            for client in clients:
                await client.close()

    run(main())
