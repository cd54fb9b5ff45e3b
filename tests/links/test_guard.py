"""A server's guard on its links: access rules (TCP, CHUDP, Chaos addresses), frame and idle timeouts,
the link limit, and accept failures that pause instead of spinning, each counted and logged sparingly."""

from __future__ import annotations

import asyncio
import errno
import ipaddress
import logging
import socket
from collections.abc import Coroutine
from typing import Any

import pytest

from manip.codecs.framing import decode_tcp, encode_tcp
from manip.codecs.packet import Packet
from manip.links import (
    AccessError,
    AccessList,
    ChaosConnection,
    ChaosError,
    ChaosServer,
    ConnectionRefused,
    ConnectTimeout,
    LinkGuard,
    LinkLimits,
    NcpConfig,
    open_connection,
    start_server,
)
from manip.links.chaosd import ChaosdLink
from manip.links.guard import RateLimitedLog
from manip.links.listener import StreamListener, bind_stream
from manip.links.stream import StreamLink
from manip.links.tcp import TcpLink
from manip.spec.constants import ChaosOp

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)
RFC_PUMA = Packet(ChaosOp.RFC, 0o440, 0, 0o401, 0x4242, 1, 0, b"PUMA")


def run(coro: Coroutine[Any, Any, None], timeout: float = 10.0) -> None:
    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


async def echo(conn: ChaosConnection) -> None:
    async for packet in conn:
        await conn.send(packet.data[::-1], packet.opcode)


async def round_trip(url: str, **kwargs: Any) -> None:
    async with await open_connection(url, options=FAST, timeout=3.0, **kwargs) as conn:
        await conn.send(b"ping")
        assert (await conn.receive()).data == b"gnip"


async def tcp_server(**kwargs: Any) -> tuple[ChaosServer, str]:
    server = await start_server("tcp://127.0.0.1:0", "PUMA", echo, options=FAST, **kwargs)
    return server, f"tcp://127.0.0.1:{server.port}"


def stream_links(server: ChaosServer) -> list[StreamLink]:
    return [link for link in server.node.links if isinstance(link, StreamLink)]


async def hung_up(reader: asyncio.StreamReader, within: float = 3.0) -> bool:
    """True once the server closed the connection (EOF or reset), within ``within`` seconds."""
    try:
        async with asyncio.timeout(within):
            while await reader.read(4096):
                pass
    except ConnectionResetError:
        pass
    return True


async def turned_away(port: int, host: str = "127.0.0.1") -> bool:
    """True if a TCP connection to ``port`` is reset at once (during the connect, or just after)."""
    try:
        reader, writer = await asyncio.open_connection(host, port)
    except ConnectionError:
        return True
    try:
        return await hung_up(reader, within=1.0)
    finally:
        writer.close()


async def wait_for(predicate: Any, within: float = 3.0) -> None:
    async with asyncio.timeout(within):
        while not predicate():
            await asyncio.sleep(0.005)


# ------------------------------------------------------------------------------ the rules


def test_access_rules_parse_ip_networks_and_octal_chaos_ranges() -> None:
    rules = ["127.0.0.1", "10.0.0.0/8", "::1", "[fe80::]/10", "chaos:0401", "CHAOS:400-477"]
    access = AccessList.parse(rules)
    assert access.restricts_ip and access.restricts_chaos
    assert access.networks[0] == ipaddress.ip_network("127.0.0.1/32")
    assert access.chaos_ranges == ((0o401, 0o401), (0o400, 0o477))
    for host in ("127.0.0.1", "10.200.3.4", "::1", "::ffff:10.1.2.3", "fe80::1%lo"):
        assert access.allows_ip(host), host
    for host in ("127.0.0.2", "11.0.0.1", "::2", "::ffff:11.1.2.3", "not-an-address", ""):
        assert not access.allows_ip(host), host
    assert access.allows_chaos(0o477) and access.allows_chaos(0o401)
    assert not access.allows_chaos(0o500) and not access.allows_chaos(0o377)
    assert str(access) == "127.0.0.1/32, 10.0.0.0/8, ::1/128, fe80::/10, chaos:0401, chaos:0400-0477"


def test_a_kind_of_rule_not_given_restricts_nothing() -> None:
    ip_only = AccessList.parse(["10.0.0.0/8"])
    assert ip_only.allows_chaos(0o402) and not ip_only.restricts_chaos
    chaos_only = AccessList.parse(["chaos:0401"])
    assert chaos_only.allows_ip("192.0.2.1") and not chaos_only.restricts_ip
    assert AccessList().allows_ip("192.0.2.1") and str(AccessList()) == "everyone"


@pytest.mark.parametrize(
    ("rule", "message"),
    [
        ("robot.example", "neither an IP address"),
        ("10.0.0.1/8", "host bits set"),
        ("chaos:0409", "not an octal Chaos address"),
        ("chaos:", "not an octal Chaos address"),
        ("chaos:0477-0400", "ends before it starts"),
        ("chaos:1000000", "outside the 16-bit"),
    ],
)
def test_bad_rules_say_what_is_wrong(rule: str, message: str) -> None:
    with pytest.raises(AccessError, match=message) as info:
        AccessList.parse([rule])
    assert repr(rule) in str(info.value)


@pytest.mark.parametrize(
    "kwargs",
    [{"frame_timeout": 0}, {"idle_timeout": -1.0}, {"idle_timeout": float("inf")}, {"max_links": 0}],
)
def test_limits_must_be_positive(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        LinkLimits(**kwargs)


def test_rate_limited_log_counts_what_it_holds_back(caplog: pytest.LogCaptureFixture) -> None:
    logger = logging.getLogger("test.ratelimit")

    def messages() -> list[str]:
        return [r.getMessage() for r in caplog.records]

    async def main() -> None:
        limiter = RateLimitedLog(logger, interval=0.2, burst=2)
        for i in range(10):
            limiter.log("pings", logging.WARNING, "ping %d", i)
        limiter.log("pongs", logging.INFO, "pong")
        assert messages() == ["ping 0", "ping 1", "pong"]
        await asyncio.sleep(0.3)  # the interval ends: one line for the eight held back
        assert messages()[3:] == ["8 more pings in the last 0.2 s (not logged one by one)"]
        assert caplog.records[-1].levelno == logging.WARNING
        limiter.log("pings", logging.WARNING, "ping while they keep coming")  # only counted
        await asyncio.sleep(0.3)
        assert messages()[4:] == ["1 more pings in the last 0.2 s (not logged one by one)"]
        await asyncio.sleep(0.3)  # a quiet interval: the next one is logged as it comes
        limiter.log("pings", logging.WARNING, "ping again")
        limiter.log("pings", logging.WARNING, "one too many", burst=1)
        assert messages()[5:] == ["ping again"]
        limiter.close()  # reports what it held
        assert messages()[6:] == ["1 more pings in the last 0.2 s (not logged one by one)"]

    with caplog.at_level(logging.INFO, logger="test.ratelimit"):
        run(main())


# ------------------------------------------------------------------------------ access


def test_tcp_peer_outside_the_rules_is_closed_at_once(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        server, url = await tcp_server(allow=AccessList.parse(["10.0.0.0/8"]))
        async with server:
            assert await turned_away(server.port)  # before it sent a byte
            with pytest.raises(ChaosError):
                await open_connection(url, options=FAST, timeout=1.0)
            assert server.guard.stats.refused == {"address": 2}
            assert server.guard.stats.accepted == 0 and not server.node.stats.links_attached
        allowed, url = await tcp_server(allow=AccessList.parse(["10.0.0.0/8", "127.0.0.0/8"]))
        async with allowed:
            await round_trip(url)
            assert allowed.guard.stats.accepted == 1 and not allowed.guard.stats.refused

    with caplog.at_level(logging.WARNING, logger="manip.links"):
        run(main())
    refusals = [r for r in caplog.records if "refused TCP peer 127.0.0.1:" in r.getMessage()]
    assert len(refusals) == 2 and all(r.exc_info is None for r in caplog.records)


def test_ipv6_tcp_peers_are_checked_too() -> None:
    if not socket.has_ipv6:
        pytest.skip("no IPv6 on this machine")

    async def main() -> None:
        for rules, admitted in ((["::1"], True), (["127.0.0.1"], False)):
            try:
                server = await start_server(
                    "tcp://[::1]:0", "PUMA", echo, options=FAST, allow=AccessList.parse(rules)
                )
            except ChaosError:
                pytest.skip("cannot listen on ::1")
            async with server:
                url = f"tcp://[::1]:{server.port}"
                if admitted:
                    await round_trip(url)
                else:
                    with pytest.raises(ChaosError):
                        await open_connection(url, options=FAST, timeout=1.0)
                assert server.guard.stats.refused["address"] == (0 if admitted else 1)

    run(main())


def test_chudp_datagrams_from_outside_are_dropped_and_counted() -> None:
    async def main() -> None:
        outside = AccessList.parse(["10.0.0.0/8"])
        url = "chudp://127.0.0.1:0?addr=0440"
        server = await start_server(url, "PUMA", echo, options=FAST, allow=outside)
        async with server:
            url = f"chudp://127.0.0.1:{server.port}?addr=0440&me=0401"
            with pytest.raises(ConnectTimeout):
                await open_connection(url, options=FAST, timeout=0.5)
            (link,) = server.node.links
            assert link.stats.frames_in == 0 and link.stats.bytes_in > 0
            refused = server.guard.stats.refused["datagram"]
            assert refused >= 2  # the RFC and its retransmissions, every one
            assert server.node.stats.packets_in == 0
        server = await start_server(
            "chudp://127.0.0.1:0?addr=0440", "PUMA", echo, options=FAST, allow=AccessList.parse(["127.0.0.1"])
        )
        async with server:
            await round_trip(f"chudp://127.0.0.1:{server.port}?addr=0440&me=0401")
            assert not server.guard.stats.refused

    run(main())


@pytest.mark.parametrize("scheme", ["tcp", "chudp"])
def test_rfc_from_a_chaos_host_outside_is_refused_with_a_reason(
    scheme: str, caplog: pytest.LogCaptureFixture
) -> None:
    async def main() -> None:
        allow = AccessList.parse(["chaos:0401", "chaos:0410-0417"])
        url = f"{scheme}://127.0.0.1:0?addr=0440"
        server = await start_server(url, "PUMA", echo, options=FAST, allow=allow)
        async with server:
            base = f"{scheme}://127.0.0.1:{server.port}?addr=0440"
            with pytest.raises(ConnectionRefused) as info:
                await open_connection(f"{base}&me=0402", options=FAST, timeout=3.0)
            assert info.value.reason == "Access refused: Chaos host 0402 not allowed"
            await round_trip(f"{base}&me=0401")
            await round_trip(f"{base}&me=0413")
            with pytest.raises(ConnectionRefused, match="Chaos host 0420 not allowed"):
                await open_connection(f"{base}&me=0420", options=FAST, timeout=3.0)
            assert server.guard.stats.refused == {"chaos-host": 2}

    with caplog.at_level(logging.WARNING, logger="manip.links"):
        run(main())
    lines = [r.getMessage() for r in caplog.records if "refused RFC" in r.getMessage()]
    assert len(lines) == 2 and "from 0402/" in lines[0] and "not allowed" in lines[0]


def test_chaos_rules_come_before_the_servers_own_policy() -> None:
    seen: list[int] = []

    def policy(request: Any) -> str | None:
        seen.append(request.peer_host)
        return None

    async def main() -> None:
        server, url = await tcp_server(allow=AccessList.parse(["chaos:0401"]), policy=policy)
        async with server:
            with pytest.raises(ConnectionRefused, match="Access refused"):
                await open_connection(f"{url}?me=0402", options=FAST, timeout=3.0)
            await round_trip(url)
        assert seen == [0o401]

    run(main())


# ------------------------------------------------------------------------------ timeouts


def test_silent_and_half_sent_links_are_closed_after_the_frame_timeout(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        limits = LinkLimits(frame_timeout=0.3, idle_timeout=None)
        server, url = await tcp_server(limits=limits)
        async with server:
            loop = asyncio.get_running_loop()
            opened = loop.time()
            silent = await asyncio.open_connection("127.0.0.1", server.port)
            half = await asyncio.open_connection("127.0.0.1", server.port)
            frame = encode_tcp(RFC_PUMA, hw_dest=0o440, hw_src=0o401)
            half[1].write(frame[:2] + frame[2:10])  # the length and part of the frame
            # One that sends a whole frame (an RFC for a contact nobody serves) then half of the next.
            later = await asyncio.open_connection("127.0.0.1", server.port)
            nobody = Packet(ChaosOp.RFC, 0o440, 0, 0o401, 0x4343, 1, 0, b"NOBODY")
            later[1].write(encode_tcp(nobody, hw_dest=0o440, hw_src=0o401))
            reply = await asyncio.wait_for(later[0].readexactly(2), 3.0)
            await later[0].readexactly(int.from_bytes(reply, "big"))
            await asyncio.sleep(0.2)
            partial_started = loop.time()
            later[1].write(frame[:5])
            await round_trip(url)  # a client in the middle of it all is served
            for reader, _ in (silent, half):
                assert await hung_up(reader)
            assert 0.25 < loop.time() - opened < 1.5
            assert await hung_up(later[0])
            assert loop.time() - partial_started >= 0.25
            for _, writer in (silent, half, later):
                writer.close()
            await wait_for(lambda: sum(server.guard.stats.idle_closed.values()) == 3)
            assert server.guard.stats.idle_closed == {"no frame": 2, "partial frame": 1}
            assert len(stream_links(server)) == 0

    with caplog.at_level(logging.INFO, logger="manip.links"):
        run(main())
    closed = [r.getMessage() for r in caplog.records if "closed: no complete frame" in r.getMessage()]
    assert len(closed) == 3
    assert sum("within 0.3 s of opening" in line for line in closed) == 2
    assert sum("within 0.3 s of its first byte" in line for line in closed) == 1
    assert all(line.startswith("tcp:127.0.0.1:") for line in closed)  # each names its peer


def test_a_link_without_a_chaos_connection_is_closed_after_the_idle_timeout() -> None:
    async def main() -> None:
        limits = LinkLimits(frame_timeout=None, idle_timeout=0.4)
        server, url = await tcp_server(limits=limits)
        async with server:
            loop = asyncio.get_running_loop()
            # A client holding a connection open but saying nothing stays, however long.
            conn = await open_connection(url, options=FAST)
            # A raw link that opens a connection, closes it (CLS), and stays: closed after the timeout.
            reader, writer = await asyncio.open_connection("127.0.0.1", server.port)
            writer.write(encode_tcp(RFC_PUMA, hw_dest=0o440, hw_src=0o401))
            head = await asyncio.wait_for(reader.readexactly(2), 3.0)
            opn = decode_tcp(head + await reader.readexactly(int.from_bytes(head, "big")))
            assert opn.opcode == ChaosOp.OPN
            await asyncio.sleep(0.6)  # longer than the timeout, while the connection is open
            assert server.guard.stats.idle_closed == {}
            cls = Packet(ChaosOp.CLS, 0o440, opn.src_index, 0o401, 0x4242, 2, 0, b"bye")
            writer.write(encode_tcp(cls, hw_dest=0o440, hw_src=0o401))
            ended = loop.time()
            assert await hung_up(reader, within=3.0)
            assert loop.time() - ended >= 0.35
            assert server.guard.stats.idle_closed == {"no connection": 1}
            writer.close()
            await asyncio.sleep(0.5)
            await conn.send(b"still")  # the quiet client was never touched
            assert (await conn.receive()).data == b"llits"
            await conn.close()

    run(main())


# ------------------------------------------------------------------------------ the link limit


def test_over_the_limit_a_new_link_displaces_the_oldest_idle_one() -> None:
    async def main() -> None:
        server, url = await tcp_server(limits=LinkLimits(max_links=3))
        async with server:
            idle = [await asyncio.open_connection("127.0.0.1", server.port) for _ in range(3)]
            await wait_for(lambda: server.guard.links == 3)
            # A fourth link, a real client: the oldest idle link makes room.
            async with await open_connection(url, options=FAST, timeout=3.0) as conn:
                assert await hung_up(idle[0][0])
                assert server.guard.stats.over_limit == {"displaced": 1}
                later = []
                for victim in (idle[1], idle[2]):  # each newcomer displaces the oldest idle one
                    later.append(await asyncio.open_connection("127.0.0.1", server.port))
                    assert await hung_up(victim[0])
                later.append(await asyncio.open_connection("127.0.0.1", server.port))
                assert await hung_up(later[0][0])  # the client, older but in use, is passed over
                assert server.guard.stats.over_limit == {"displaced": 4}
                assert server.guard.links == 3 and not server.guard.stats.over_limit["refused"]
                await conn.send(b"still")
                assert (await conn.receive()).data == b"llits"
            for _, writer in [*idle, *later]:
                writer.close()

    run(main())


def test_over_the_limit_with_every_link_in_use_the_new_one_is_closed_at_once() -> None:
    async def main() -> None:
        server, url = await tcp_server(limits=LinkLimits(max_links=2))
        async with server:
            first = await open_connection(url, options=FAST)
            second = await open_connection(url, options=FAST)
            assert await turned_away(server.port)
            assert server.guard.stats.over_limit == {"refused": 1} and server.guard.links == 2
            await second.close()
            await wait_for(lambda: server.guard.links == 1)
            await round_trip(url)  # room again
            await first.send(b"ok")
            assert (await first.receive()).data == b"ko"
            await first.close()

    run(main())


# ------------------------------------------------------------------------------ accept failures


class _OutOfDescriptors(socket.socket):
    """A listening socket whose accepts fail as when the process has no descriptor left."""

    accepts = 0

    def accept(self) -> tuple[socket.socket, Any]:
        type(self).accepts += 1
        raise OSError(errno.EMFILE, "Too many open files")


def test_out_of_descriptors_pauses_accepting_and_logs_once(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        sock = _OutOfDescriptors(socket.AF_INET, socket.SOCK_STREAM)
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        sock.setblocking(False)
        guard = LinkGuard(LinkLimits(accept_backoff=0.1, log_interval=5.0))
        listener = StreamListener([sock], lambda: TcpLink(my_addr=0o440), guard)
        client = socket.create_connection(sock.getsockname())  # makes the socket readable, forever
        try:
            await asyncio.sleep(0.05)
            assert _OutOfDescriptors.accepts == 1 and not listener.is_serving  # one try, then a pause
            await asyncio.sleep(0.5)
            assert 3 <= _OutOfDescriptors.accepts <= 7  # about one try per back-off, no spinning
            assert guard.stats.accept_errors == _OutOfDescriptors.accepts
        finally:
            client.close()
            listener.close()
            await listener.wait_closed()
            guard.close()

    _OutOfDescriptors.accepts = 0
    with caplog.at_level(logging.DEBUG, logger="manip.links"):
        run(main())
    messages = [r.getMessage() for r in caplog.records if r.name == "manip.links"]
    first = "server: accepting a TCP connection failed: Too many open files; accepting again in 0.1 s"
    assert messages[0] == first and len(messages) == 2
    assert messages[1].startswith(f"{_OutOfDescriptors.accepts - 1} more accept failures")
    assert all(r.exc_info is None for r in caplog.records)


def test_out_of_descriptors_lowers_the_limit_and_makes_room() -> None:
    async def main() -> None:
        sockets = await bind_stream("127.0.0.1", 0)
        guard = LinkGuard(LinkLimits(max_links=None, frame_timeout=None, idle_timeout=None))
        made: list[TcpLink] = []

        def make() -> TcpLink:
            link = TcpLink(my_addr=0o440)
            made.append(link)
            guard.track(link)
            return link

        listener = StreamListener(sockets, make, guard)
        port = sockets[0].getsockname()[1]
        peers = [await asyncio.open_connection("127.0.0.1", port) for _ in range(20)]
        await wait_for(lambda: guard.links == 20)
        pause = guard.accept_failed(OSError(errno.EMFILE, "Too many open files"))
        assert pause == guard.limits.accept_backoff
        assert guard.ceiling == 4 and guard.max_links == 4
        assert guard.links == 3 and guard.stats.over_limit == {"displaced": 17}
        await wait_for(lambda: all(link.is_closed for link in made[:17]))
        assert not any(link.is_closed for link in made[17:])
        listener.close()
        await listener.wait_closed()
        guard.close()
        for _, writer in peers:
            writer.close()
        for link in made:
            link.close()

    run(main())


def test_unix_socket_peers_are_not_held_to_the_ip_rules(tmp_path: Any) -> None:
    async def main() -> None:
        path = str(tmp_path / "listen.sock")
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.bind(path)
        sock.listen(8)
        sock.setblocking(False)
        guard = LinkGuard(LinkLimits(max_links=1), AccessList.parse(["10.0.0.0/8"]))
        made: list[ChaosdLink] = []  # any stream link: TcpLink names itself by an IP peer

        def make() -> ChaosdLink:
            made.append(ChaosdLink(my_addr=0o440))
            guard.track(made[-1])
            return made[-1]

        listener = StreamListener([sock], make, guard)
        first = await asyncio.open_unix_connection(path)
        await wait_for(lambda: guard.links == 1)
        second = await asyncio.open_unix_connection(path)  # over the limit: the idle first makes room
        assert await hung_up(first[0])
        assert guard.stats.accepted == 2 and not guard.stats.refused
        assert guard.stats.over_limit == {"displaced": 1}
        listener.close()
        await listener.wait_closed()
        guard.close()
        for _, writer in (first, second):
            writer.close()
        for link in made:
            link.close()

    run(main())
