"""The driver itself on an in-memory link: routing, the timer, and surviving whatever a peer sends."""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Coroutine
from dataclasses import replace
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from manip.codecs.packet import MAX_DATA, Packet
from manip.links import (
    ChaosConnection,
    ChaosError,
    ConnectionClosed,
    ConnectionLost,
    Link,
    LinkError,
    NcpConfig,
    Node,
    open_connection,
    start_server,
)
from manip.links.chudp import ChudpLink
from manip.links.tcp import TcpLink
from manip.spec.constants import ChaosOp

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)
CLIENT, SERVER = 0o401, 0o440


def run(coro: Coroutine[Any, Any, None], timeout: float = 10.0) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


class PipeLink(Link):
    """Half of an in-memory point-to-point link; packets reach the other half on the next loop turn."""

    kind = "pipe"

    def __init__(self, my_addr: int, peer_addr: int) -> None:
        super().__init__(my_addr=my_addr, peer_addr=peer_addr)
        self.other: PipeLink | None = None
        self.sent: list[Packet] = []

    @classmethod
    def pair(cls, a: int, b: int) -> tuple[PipeLink, PipeLink]:
        left, right = cls(a, b), cls(b, a)
        left.other, right.other = right, left
        return left, right

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        if self.is_closed or self.other is None:
            return self._drop("closed", packet)
        self.stats.frames_out += 1
        self.sent.append(packet)
        asyncio.get_running_loop().call_soon(self.other.inject, packet)
        return True

    def inject(self, packet: Packet) -> None:
        if not self.is_closed:
            self._deliver(packet)

    def close(self) -> None:
        """Like a transport: what was sent before the close still arrives, then the far end closes."""
        self._set_closed("closed locally")
        other = self.other
        if other is not None and not other.is_closed:
            asyncio.get_running_loop().call_soon(other._set_closed, "closed by the peer")


async def echo(conn: ChaosConnection) -> None:
    try:
        async for packet in conn:
            await conn.send(packet.data[::-1])
    except ChaosError:
        pass  # a LOS, a broken link: the tests look at the connection itself


def pair(options: NcpConfig = FAST) -> tuple[Node, Node, PipeLink, PipeLink]:
    """A client node and a server node (listening on PUMA with ``echo``) joined by a pipe."""
    client, server = Node(CLIENT, options), Node(SERVER, options)
    c_link, s_link = PipeLink.pair(CLIENT, SERVER)
    client.attach(c_link)
    server.attach(s_link)
    tasks: set[asyncio.Task[None]] = set()

    def on_open(conn: ChaosConnection) -> None:
        task = asyncio.get_running_loop().create_task(echo(conn))
        tasks.add(task)
        task.add_done_callback(tasks.discard)

    server.listen("PUMA", on_open)
    return client, server, c_link, s_link


async def round_trip(client: Node, data: bytes = b"ping") -> None:
    conn = await client.connect(SERVER, "PUMA", timeout=5)
    await conn.send(data)
    assert (await conn.receive()).data == data[::-1]
    await conn.close()


def test_clients_sharing_an_address_draw_their_indices_from_both_bytes() -> None:
    """Two clients with the default address clash only if their indices do: both bytes are random."""

    async def main() -> None:
        firsts = set()
        for _ in range(40):
            node = Node(CLIENT, FAST)
            firsts.add(node.ncp.connect(0.0, SERVER, "PUMA"))
            node.close()
        assert len({index & 0xFF for index in firsts}) > 1  # the slot too, not just the uniquizer
        assert len({index >> 8 for index in firsts}) > 1
        assert all(index & 0xFF for index in firsts)  # slot 0 is never used

    run(main())


def test_pipe_round_trip_and_routes() -> None:
    async def main() -> None:
        client, server, c_link, s_link = pair()
        await round_trip(client)
        assert client.stats.no_route == 0 and server.stats.no_route == 0
        assert client.stats.packets_out == c_link.stats.frames_out
        assert not client.connections and not server.connections
        with pytest.raises(LinkError, match="no route"):
            await client.connect(0o3040, "PUMA")
        client.close()
        await client.wait_closed()
        await s_link.closed
        assert c_link.is_closed and not server.links

    run(main())


def test_timer_without_ack_delay() -> None:
    """With ack_delay 0 the timer cannot skip re-arming; everything still flows."""

    async def main() -> None:
        client, server, _, _ = pair(NcpConfig(ack_delay=0.0, retransmit_interval=0.05))
        for i in range(20):
            await round_trip(client, b"%d" % i)
        client.close()
        server.close()

    run(main())


def test_lost_packets_are_retransmitted_by_the_timer() -> None:
    async def main() -> None:
        client, server, c_link, _ = pair()
        conn = await client.connect(SERVER, "PUMA", timeout=5)
        real_send = c_link.send
        dropped: list[Packet] = []

        def lossy(packet: Packet, next_hop: int | None = None) -> bool:
            if packet.opcode == ChaosOp.DAT and not dropped:
                dropped.append(packet)  # the first transmission vanishes
                return True
            return real_send(packet, next_hop)

        c_link.send = lossy  # type: ignore[method-assign]
        await conn.send(b"again")
        assert (await conn.receive()).data == b"niaga"
        assert dropped and client.ncp.stats.retransmissions >= 1
        await conn.close()
        client.close()
        server.close()

    run(main())


def test_node_close_aborts_connections_with_the_reason() -> None:
    async def main() -> None:
        client, server, _, _ = pair()
        conn = await client.connect(SERVER, "PUMA", timeout=5)
        (server_conn,) = server.connections
        server.close("Shutting down for the night")
        with pytest.raises(ConnectionClosed, match="Shutting down"):
            await conn.receive()
        assert isinstance(server_conn.end_reason, ConnectionClosed)
        client.close()

    run(main())


packets = st.builds(
    Packet,
    opcode=st.one_of(st.integers(0, 0o17), st.integers(0o200, 0o377), st.integers(0, 255)),
    dest_host=st.sampled_from([SERVER, 0, 0o3040]),
    dest_index=st.integers(0, 0xFFFF),
    src_host=st.sampled_from([CLIENT, 0o3050]),
    src_index=st.integers(0, 0xFFFF),
    packet_no=st.integers(0, 0xFFFF),
    ack_no=st.integers(0, 0xFFFF),
    data=st.binary(max_size=MAX_DATA),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(packets, max_size=25), st.data())
def test_survives_anything_a_peer_sends(junk: list[Packet], data: st.DataObject) -> None:
    """Random packets, some aimed at a live connection, never escape as errors; the node keeps serving."""

    async def main() -> None:
        client, server, _, s_link = pair()
        victim = await client.connect(SERVER, "PUMA", timeout=5)
        (server_conn,) = server.connections
        aimed = data.draw(st.lists(st.sampled_from([True, False]), min_size=len(junk), max_size=len(junk)))
        for packet, at_victim in zip(junk, aimed, strict=True):
            if at_victim:
                packet = packet.with_(dest_index=server_conn.conn_id, src_index=victim.conn_id)
            s_link.inject(packet)
            await asyncio.sleep(0)
        await asyncio.sleep(0.02)
        assert server.stats.core_errors == 0 and client.stats.core_errors == 0
        await round_trip(client, b"still alive")
        victim.abort()
        client.close()
        server.close()

    run(main())


def test_los_from_the_peer_ends_the_connection() -> None:
    async def main() -> None:
        client, server, _, s_link = pair()
        conn = await client.connect(SERVER, "PUMA", timeout=5)
        (server_conn,) = server.connections
        s_link.inject(Packet(ChaosOp.LOS, SERVER, server_conn.conn_id, CLIENT, conn.conn_id, data=b"Gone"))
        await asyncio.sleep(0)
        with pytest.raises(ConnectionLost, match="Gone"):
            await server_conn.receive()
        client.close()
        server.close()

    run(main())


def test_ipv6_loopback_tcp() -> None:
    if not socket.has_ipv6:
        pytest.skip("no IPv6")
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe:
            probe.bind(("::1", 0))
    except OSError:
        pytest.skip("no IPv6 loopback")

    async def main() -> None:
        async with await start_server("tcp://[::1]:0", "PUMA", echo, options=FAST) as server:
            assert str(server.address).startswith("tcp://[::1]:")
            async with await open_connection(f"tcp://[::1]:{server.port}", options=FAST) as conn:
                await conn.send(b"six")
                assert (await conn.receive()).data == b"xis"

    run(main())


class FakeTransport:
    """Just enough of a transport for feeding a stream link by hand."""

    def __init__(self, link: TcpLink) -> None:
        self.link = link
        self.closing = False

    def get_extra_info(self, name: str, default: Any = None) -> Any:
        return ("127.0.0.1", 1) if name == "peername" else default

    def get_write_buffer_size(self) -> int:
        return 0

    def write(self, data: bytes) -> None:
        pass

    def close(self) -> None:
        self.abort()

    def abort(self) -> None:
        if not self.closing:
            self.closing = True
            asyncio.get_running_loop().call_soon(self.link.connection_lost, None)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=600), max_size=8))
def test_stream_link_survives_random_bytes(chunks: list[bytes]) -> None:
    async def main() -> None:
        link = TcpLink(my_addr=SERVER)
        got: list[Packet] = []
        link.set_receiver(lambda _link, packet: got.append(packet))
        link.connection_made(FakeTransport(link))  # type: ignore[arg-type]
        for chunk in chunks:
            if link.is_closed:
                break
            link.data_received(chunk)
        await asyncio.sleep(0)
        assert link.stats.frames_in == len(got)
        if link.is_closed:
            assert link.stats.bad["framing"] == 1

    run(main())


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=600), max_size=8))
def test_chudp_link_survives_random_datagrams(datagrams: list[bytes]) -> None:
    async def main() -> None:
        link = ChudpLink(my_addr=SERVER, learn_peers=True)
        got: list[Packet] = []
        link.set_receiver(lambda _link, packet: got.append(packet))
        for datagram in datagrams:
            link.datagram_received(datagram, ("127.0.0.1", 4242))
        assert link.stats.frames_in + link.stats.bad_total == len(datagrams)
        assert link.stats.frames_in == len(got)

    run(main())


def test_breaking_after_shrinks_the_probe_interval_with_the_timer() -> None:
    assert NcpConfig.breaking_after(90) == replace(NcpConfig(), broken_after=90)  # 90 s: unchanged
    short = NcpConfig.breaking_after(3)
    assert short.broken_after == 3 and short.probe_interval == 1.0  # three probes before giving up
    for bad in (0, -1, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="broken_after"):
            NcpConfig.breaking_after(bad)
