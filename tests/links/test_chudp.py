"""The driver over CHUDP: two drivers on loopback, and byte-for-byte against hand-made datagrams."""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Coroutine
from typing import Any

import pytest

from manip.codecs.framing import decode_chudp, encode_chudp
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, ChaosServer, NcpConfig, open_connection, start_server
from manip.links.chudp import ChudpLink, bind_chudp
from manip.spec.constants import ChaosOp

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)

# Notes section 8, vector 1: RFC "PUMA" from 0401 index 0A01 to 0440, packet 1.
VECTOR_1 = bytes.fromhex("01010000 0100 0004 0120 0000 0101 0a01 0001 0000 5550 414d 0120 0101 5a1a")
# Vector 2: the OPN answering it from 0440 index 5E02, packet 1, ack 1, receipt 1, window 5.
VECTOR_2 = bytes.fromhex("01010000 0200 0004 0101 0a01 0120 5e02 0001 0001 0001 0005 0101 0120 91ae")


def run(coro: Coroutine[Any, Any, None], timeout: float = 10.0) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


def words(datagram: bytes) -> list[int]:
    body = datagram[4:]
    return list(struct.unpack(f">{len(body) // 2}H", body))


def ones_sum(values: list[int]) -> int:
    """RFC 1071 sum, written out here so the test does not trust the codec it checks."""
    total = 0
    for w in values:
        total += w
        total = (total & 0xFFFF) + (total >> 16)
    return total


def with_checksum(datagram: bytes) -> bytes:
    """Recompute the trailer checksum of a (possibly doctored) CHUDP datagram."""
    w = words(datagram)[:-1]
    return datagram[:-2] + struct.pack(">H", ~ones_sum(w) & 0xFFFF)


def forge(
    opcode: int, data: bytes, packet_no: int, *, nbytes: int | None = None, dest_index: int = 0
) -> bytes:
    """A datagram from 0401 index 0A01 to 0440 with any opcode, data length and count, checksum right."""
    padded = data + b"\0" * (len(data) & 1)
    data_words = struct.unpack(f"<{len(padded) // 2}H", padded)
    count = len(data) if nbytes is None else nbytes
    ws = [opcode << 8, count, 0o440, dest_index, 0o401, 0x0A01, packet_no, 1, *data_words, 0o440, 0o401, 0]
    return with_checksum(b"\x01\x01\x00\x00" + struct.pack(f">{len(ws)}H", *ws))


async def echo(conn: ChaosConnection) -> None:
    async for packet in conn:
        await conn.send(packet.data[::-1], packet.opcode)


def chudp_link(server: ChaosServer) -> ChudpLink:
    (link,) = server.node.links
    assert isinstance(link, ChudpLink)
    return link


class RawUdp:
    """A bare UDP socket on loopback, standing in for klh10 or simh."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)

    async def send(self, data: bytes, port: int) -> None:
        await asyncio.get_running_loop().sock_sendto(self.sock, data, ("127.0.0.1", port))

    async def recv(self) -> bytes:
        data, _ = await asyncio.get_running_loop().sock_recvfrom(self.sock, 2048)
        return data

    def close(self) -> None:
        self.sock.close()


# ------------------------------------------------------------------------------ two drivers


def test_round_trip_between_two_drivers() -> None:
    async def main() -> None:
        server = await start_server("chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST)
        async with server:
            url = f"chudp://127.0.0.1:{server.port}?addr=0440&me=0401"
            async with await open_connection(url, options=FAST, args=b"v1") as conn:
                numbers = []
                for i in range(100):
                    data = bytes(range(i % 200, i % 200 + 1 + i % 50))
                    numbers.append(await conn.send(data))
                    reply = await conn.receive()
                    assert reply.data == data[::-1]
                    assert reply.trailer is not None
                    assert (reply.trailer.source, reply.trailer.dest) == (0o440, 0o401)
                assert numbers == [(numbers[0] + k) & 0xFFFF for k in range(100)]
                client_link = conn.node.links[0]
                assert isinstance(client_link, ChudpLink) and client_link.stats.bad_total == 0
            link = chudp_link(server)
            assert link.peers_learned == 1 and 0o401 in link.peers
            assert link.stats.frames_in >= 100 and link.stats.bad_total == 0

    run(main())


# ------------------------------------------------------------------------------ byte for byte


def test_vector_1_draws_the_expected_opn() -> None:
    async def main() -> None:
        options = NcpConfig(window=5, retransmit_interval=0.2, ack_delay=0.01)
        server = await start_server("chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=options)
        raw = RawUdp()
        try:
            await raw.send(VECTOR_1, server.port)
            opn = await raw.recv()
            assert len(opn) == len(VECTOR_2) == 30
            got, want = words(opn), words(VECTOR_2)
            assert opn[:4] == b"\x01\x01\x00\x00"
            index = got[5]
            assert index != 0 and index & 0xFF != 0
            # Everything but our local index (and so the checksum) is vector 2.
            assert got[:5] == want[:5] and got[6:-1] == want[6:-1]
            assert ones_sum(got) == 0xFFFF  # the checksum verifies
            assert with_checksum(opn[:14] + b"\x5e\x02" + opn[16:]) == VECTOR_2
            assert decode_chudp(opn).opcode == ChaosOp.OPN

            # Go on as the client would: STS (opens the server's window), then odd-length data.
            def send(p: Packet) -> bytes:
                return encode_chudp(p, hw_dest=0o440, hw_src=0o401)

            await raw.send(
                send(Packet(ChaosOp.STS, 0o440, index, 0o401, 0x0A01, 2, 1, b"\1\0\5\0")), server.port
            )
            await raw.send(send(Packet(ChaosOp.DAT, 0o440, index, 0o401, 0x0A01, 2, 1, b"ABC")), server.port)
            while True:
                reply = await raw.recv()
                if reply[4] == ChaosOp.DAT:
                    break
            # "CBA", pair-swapped on the wire: 42 43 00 41; ack 2 = our data packet read by the handler.
            assert reply[4:8] == b"\x80\x00\x00\x03" and reply[20:24] == b"\x42\x43\x00\x41"
            p = decode_chudp(reply)
            assert (p.dest_host, p.dest_index, p.src_index, p.packet_no) == (0o401, 0x0A01, index, 2)
            assert p.ack_no == 2
        finally:
            raw.close()
            await server.aclose()

    run(main())


@pytest.mark.parametrize(
    ("datagram", "reason"),
    [
        pytest.param(VECTOR_1[:-1] + bytes([VECTOR_1[-1] ^ 0x40]), "checksum", id="corrupt-checksum"),
        pytest.param(VECTOR_1[:21], "short", id="truncated"),
        pytest.param(VECTOR_1[:4], "short", id="header-only"),
        pytest.param(b"\x02" + VECTOR_1[1:], "version", id="version-2"),
        pytest.param(b"\x01\x02" + VECTOR_1[2:], "function", id="function-2"),
        pytest.param(
            with_checksum(VECTOR_1[:6] + b"\x00\x10" + VECTOR_1[8:]), "nbytes", id="nbytes-beyond-datagram"
        ),
        pytest.param(
            forge(0o42, b"PUMA", 1)[:-1] + bytes([forge(0o42, b"PUMA", 1)[-1] ^ 0x40]),
            "checksum",
            id="illegal-opcode-bad-checksum",
        ),
        pytest.param(forge(0, b"PUMA", 1, nbytes=6), "opcode", id="illegal-opcode-nbytes-beyond"),
        pytest.param(forge(ChaosOp.DAT, b"PUMA", 1, nbytes=489), "oversize", id="oversize-count-only"),
        pytest.param(with_checksum(VECTOR_1[:5] + b"\x01" + VECTOR_1[6:]), "header", id="unused-byte-set"),
    ],
)
def test_bad_datagrams_are_counted_and_dropped(datagram: bytes, reason: str) -> None:
    async def main() -> None:
        server = await start_server("chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST)
        raw = RawUdp()
        try:
            await raw.send(datagram, server.port)
            await raw.send(datagram, server.port)
            await raw.send(VECTOR_1, server.port)  # and the node still answers a good RFC
            opn = await raw.recv()
            assert opn[4] == ChaosOp.OPN and ones_sum(words(opn)) == 0xFFFF
            link = chudp_link(server)
            assert link.stats.bad == {reason: 2}
            assert link.stats.frames_in == 1
        finally:
            raw.close()
            await server.aclose()

    run(main())


def test_illegal_packets_draw_los_but_never_a_los_for_a_los() -> None:
    """Sound datagrams with an illegal opcode or more than 488 data bytes reach the NCP, which answers
    with LOS, except an oversized LOS or CLS, which is answered by nothing."""

    async def main() -> None:
        server = await start_server("chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST)
        raw = RawUdp()
        try:
            await raw.send(forge(0o42, b"PUMA", 3, dest_index=0x1234), server.port)
            los = decode_chudp(await raw.recv())
            assert los.opcode == ChaosOp.LOS and los.data == b"Illegal opcode 042"
            assert (los.dest_host, los.dest_index, los.src_index, los.packet_no) == (0o401, 0x0A01, 0x1234, 3)
            assert los.trailer is not None and (los.trailer.dest, los.trailer.source) == (0o401, 0o440)

            oversize = forge(ChaosOp.DAT, bytes(range(245)) * 2, 4, dest_index=0x1234)
            assert len(oversize) == 4 + 16 + 490 + 6
            await raw.send(oversize, server.port)
            los = decode_chudp(await raw.recv())
            assert los.data == b"Illegal byte count 490 (at most 488)" and los.packet_no == 4

            # Never a LOS in answer to a LOS (nor a CLS); garbage is dropped.  The last datagram's LOS
            # must then be the next thing to arrive.
            await raw.send(forge(ChaosOp.LOS, bytes(490), 5, dest_index=0x1234), server.port)
            await raw.send(forge(ChaosOp.CLS, bytes(501), 6, dest_index=0x1234), server.port)
            await raw.send(forge(0o177, b"x", 7, nbytes=3), server.port)
            await raw.send(forge(0o177, b"x", 8), server.port)
            los = decode_chudp(await asyncio.wait_for(raw.recv(), 3))
            assert los.data == b"Illegal opcode 177" and los.packet_no == 8

            link = chudp_link(server)
            assert link.stats.illegal == {"opcode": 2, "oversize": 3}
            assert link.stats.bad == {"opcode": 1}
            assert link.stats.frames_in == 5
            assert server.node.ncp.stats.los_sent == 3

            await raw.send(VECTOR_1, server.port)  # the node still opens connections
            assert (await raw.recv())[4] == ChaosOp.OPN
        finally:
            raw.close()
            await server.aclose()

    run(main())


def test_illegal_packet_from_an_unknown_peer_is_not_answered() -> None:
    async def main() -> None:
        server = await start_server(
            "chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST, learn_peers=False
        )
        raw = RawUdp()
        try:
            await raw.send(forge(0o177, b"x", 1), server.port)
            await raw.send(forge(ChaosOp.DAT, bytes(490), 2), server.port)
            link = chudp_link(server)
            while link.stats.bad_total < 2:
                await asyncio.sleep(0.005)
            assert link.stats.bad == {"unknown_peer": 2} and not link.stats.illegal
            assert link.stats.frames_out == 0
        finally:
            raw.close()
            await server.aclose()

    run(main())


def test_unknown_sender_dropped_unless_learning() -> None:
    async def main() -> None:
        server = await start_server(
            "chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST, learn_peers=False
        )
        raw = RawUdp()
        try:
            await raw.send(VECTOR_1, server.port)
            link = chudp_link(server)
            while not link.stats.bad:
                await asyncio.sleep(0.001)
            assert link.stats.bad == {"unknown_peer": 1} and link.stats.frames_in == 0
            # Configure the peer and it is heard.
            link.add_peer(0o401, raw.sock.getsockname())
            await raw.send(VECTOR_1, server.port)
            assert (await raw.recv())[4] == ChaosOp.OPN
        finally:
            raw.close()
            await server.aclose()

    run(main())


def test_link_counts_output_it_cannot_route() -> None:
    async def main() -> None:
        link = await bind_chudp(my_addr=0o401, peers={0o440: ("localhost", 9)})
        try:
            assert link.peers[0o440] == ("127.0.0.1", 9)  # resolved once, numerically
            assert not link.send(Packet(ChaosOp.DAT, 0o3040, 1, 0o401, 1))
            assert link.stats.dropped == {"no_peer": 1}
        finally:
            link.close()
            await link.closed
        assert not link.send(Packet(ChaosOp.DAT, 0o440, 1, 0o401, 1))
        assert link.stats.dropped["closed"] == 1

    run(main())
