"""The reference server's asyncio driver over manip's TCP link, talked to by a raw links client.

Each test runs a server on an ephemeral loopback port and a client made of :func:`open_connection` and
the message codecs, so what is checked is what goes over the wire.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Coroutine
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from manip.arm.kinematics import READY, forward
from manip.codecs.messages import (
    AsyncResponse,
    ErrorReply,
    Reply,
    ServerMessage,
    decode_server_packet,
    encode_request,
)
from manip.codecs.pdp11float import pack_f
from manip.links import (
    ChaosConnection,
    ConnectionClosed,
    ConnectionRefused,
    NcpConfig,
    open_connection,
)
from manip.links.address import DEFAULT_SERVER_ADDR
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.driver import BUSY_REASON, ReferenceServer, serve
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition, ServerOp

FAST = NcpConfig(retransmit_interval=0.1, ack_delay=0.01)
POWERED = ServerConfig(powered_at_open=True)
GOAL = (10.0, -80.0, 100.0, 20.0, 30.0, 40.0)
MOVE_SECONDS = 1.2
"""Simulated duration of a move from READY to GOAL (the arm's shortest segment)."""


def run(coro: Coroutine[Any, Any, None], timeout: float = 15.0) -> None:
    """Run one test coroutine, bounded so that a hang fails instead of stalling."""

    async def bounded() -> None:
        async with asyncio.timeout(timeout):
            await coro

    asyncio.run(bounded())


def local(**kwargs: Any) -> Any:
    """A server on a free loopback port with fast NCP timers."""
    kwargs.setdefault("options", FAST)
    return serve("tcp://127.0.0.1:0", **kwargs)


class Raw:
    """A bare client: sends requests by spec name or raw opcode, decodes every packet it receives."""

    def __init__(self, conn: ChaosConnection, initial: ServerMessage) -> None:
        self.conn = conn
        self.initial = initial
        self.asyncs: list[ServerMessage] = []

    _me = 0o401

    @classmethod
    async def open(cls, url: str, *, first_packet_no: int = 1) -> Raw:
        options = NcpConfig(retransmit_interval=0.1, ack_delay=0.01, first_packet_no=first_packet_no)
        # Each client its own Chaos address: two clients on one address clash if their random
        # connection indices happen to be equal (the server then refuses the second one for that).
        # Never the server's own: a packet from its own address is refused as laid out wrong.
        cls._me = cls._me + 1 if cls._me < 0o477 else 0o402
        if cls._me == DEFAULT_SERVER_ADDR:
            cls._me += 1
        sep = "&" if "?" in url else "?"
        conn = await open_connection(f"{url}{sep}me={cls._me:o}", options=options, timeout=5.0)
        packet = await asyncio.wait_for(conn.receive(), 5.0)
        return cls(conn, decode_server_packet(packet.opcode, packet.data))

    async def receive(self, op: int | None = None, timeout: float = 5.0) -> ServerMessage:
        packet = await asyncio.wait_for(self.conn.receive(), timeout)
        return decode_server_packet(
            packet.opcode, packet.data, op if packet.opcode == ServerOp.RESPONSE else None
        )

    async def raw(self, opcode: int, data: bytes) -> tuple[int, ServerMessage]:
        """Send one packet; its number and the answer to it (asynchronous packets are set aside)."""
        number = await self.conn.send(data, opcode)
        known = opcode if opcode in SPEC.requests else None
        while True:
            msg = await self.receive(known)
            if isinstance(msg, AsyncResponse) or (
                isinstance(msg, ErrorReply) and msg.opcode >= ServerOp.ASYNCHRONOUS_ERROR
            ):
                self.asyncs.append(msg)
                continue
            return number, msg

    async def request(self, name: str, data: bytes | None = None, **values: Any) -> tuple[int, ServerMessage]:
        op = SPEC.request(name)
        return await self.raw(op.opcode, encode_request(name, **values) if data is None else data)

    async def reply(self, name: str, **values: Any) -> Reply:
        number, msg = await self.request(name, **values)
        assert isinstance(msg, Reply), msg
        assert msg.request_number == number
        return msg

    async def close(self) -> None:
        await self.conn.close()


def _tuple(value: object) -> tuple[object, ...]:
    assert isinstance(value, tuple)
    return value


def _error(msg: ServerMessage) -> tuple[str, str]:
    assert isinstance(msg, ErrorReply), msg
    return msg.error.severity, msg.error.code


async def _until_still(server: ReferenceServer, timeout: float = 5.0) -> None:
    """Wait until every session's arm is at rest."""
    async with asyncio.timeout(timeout):
        while any(s.arm.moving for s in server.sessions):
            await asyncio.sleep(0.01)


# ------------------------------------------------------------------------------ replies
def test_initial_response_echoes_the_rfc_packet_number() -> None:
    async def main() -> None:
        async with local() as server:
            assert server.address.startswith("tcp://127.0.0.1:") and not server.address.endswith(":0")
            for rfc in (0o1234, 0xFFF0):
                client = await Raw.open(server.address, first_packet_no=rfc)
                msg = client.initial
                assert isinstance(msg, Reply) and msg.request_number == rfc and msg.is_empty
                await client.close()
                await server.wait_idle()

    run(main())


def test_here_and_joint_angles_echo_request_numbers() -> None:
    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address, first_packet_no=0o777)
            here = await client.reply("here")
            assert here.request_number == 0o1000
            expected = forward(READY).to_floats()
            assert here.values["transform"] == pytest.approx(expected, abs=1e-3)
            angles = await client.reply("joint-angles")
            assert angles.request_number == 0o1001
            assert angles.values["joints"] == pytest.approx(READY, abs=1e-4)
            await client.close()

    run(main())


def test_pipelined_requests_are_answered_in_order() -> None:
    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address)

            async def send_all() -> list[int]:  # while the replies are read: windows are 15 packets
                return [await client.conn.send(b"", SPEC.request("here").opcode) for _ in range(40)]

            sender = asyncio.create_task(send_all())
            got = [await client.receive() for _ in range(40)]
            numbers = await sender
            assert [m.request_number for m in got] == numbers
            await client.close()
            await server.wait_idle()
            assert server.stats.requests == 40 and server.stats.errors == 0

    run(main())


def test_describe_self_arrives_whole() -> None:
    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address)
            number, first = await client.request("describe-self")
            parts = [first]
            while not (isinstance(parts[-1], Reply) and parts[-1].is_empty):
                parts.append(await client.receive())
            assert len(parts) >= 3 and all(isinstance(p, Reply) and p.request_number == number for p in parts)
            text = b"".join(p.payload for p in parts if isinstance(p, Reply)).decode("latin-1")
            assert ":PROTOCOL-VERSION" in text
            await client.close()

    run(main())


# ------------------------------------------------------------------------------ motion
def test_segment_completed_is_sent_only_after_request_notifications() -> None:
    async def main() -> None:
        async with local(config=POWERED, time_scale=20.0) as server:
            client = await Raw.open(server.address)
            first = await client.reply("set-joint-angles", joints=GOAL)
            assert first.segment == 1
            await _until_still(server)
            await asyncio.sleep(0.05)  # a servo wake-up or two after the end
            assert client.asyncs == [] and client.conn.pending == 0
            assert (await client.reply("request-notifications", mask=2)).is_empty
            second = await client.reply("set-joint-angles", joints=READY)
            assert second.segment == 2
            note = await client.receive(timeout=3.0)  # sent by the servo, no request outstanding
            assert isinstance(note, AsyncResponse)
            assert (note.request_number, note.condition, note.word3) == (
                second.request_number,
                AsyncCondition.SEGMENT_COMPLETED,
                2,
            )
            assert server.stats.async_packets == 1
            await client.close()

    run(main())


def test_motion_without_power_is_refused() -> None:
    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address)
            _, msg = await client.request("set-joint-angles", joints=GOAL)
            assert _error(msg) == ("E", "NAP")
            assert server.stats.errors == 1 and server.stats.bad_inputs == 0
            await client.close()

    run(main())


def test_time_scale_makes_a_move_finish_sooner() -> None:
    async def move_seconds(scale: float) -> float:
        async with local(config=POWERED, time_scale=scale) as server:
            client = await Raw.open(server.address)
            await client.reply("request-notifications", mask=2)
            await client.reply("set-joint-angles", joints=GOAL)
            start = time.monotonic()
            note = await client.receive(timeout=5.0)
            assert isinstance(note, AsyncResponse) and note.condition == AsyncCondition.SEGMENT_COMPLETED
            elapsed = time.monotonic() - start
            await client.close()
            return elapsed

    async def main() -> None:
        real_time = await move_seconds(1.0)
        fast = await move_seconds(12.0)
        assert real_time >= MOVE_SECONDS - 0.05
        assert fast < MOVE_SECONDS / 2

    run(main())


# ------------------------------------------------------------------------------ one robot
def test_second_connection_is_refused_with_a_reason() -> None:
    async def main() -> None:
        async with local() as server:
            first = await Raw.open(server.address)
            with pytest.raises(ConnectionRefused) as refusal:
                await Raw.open(server.address)
            assert BUSY_REASON in str(refusal.value)
            assert server.stats.refused == 1
            await first.reply("here")  # the first client is undisturbed
            await first.close()
            await server.wait_idle()
            again = await Raw.open(server.address)  # free again
            await again.close()
            assert server.stats.connections == 2

    run(main())


def test_another_contact_name_is_in_the_address() -> None:
    async def main() -> None:
        async with local(contact="ARM2") as server:
            assert server.address.endswith("?contact=ARM2")
            client = await Raw.open(server.address)
            await client.reply("here")
            await client.close()
            with pytest.raises(ConnectionRefused, match="No server"):
                await Raw.open(server.address.removesuffix("?contact=ARM2"))  # PUMA: nobody there

    run(main())


def test_max_clients_counts_every_address() -> None:
    async def main() -> None:
        async with local(extra_addresses=["tcp://127.0.0.1:0"], max_clients=2) as server:
            one, two = server.addresses
            assert one != two
            a = await Raw.open(one)
            b = await Raw.open(two)
            with pytest.raises(ConnectionRefused):
                await Raw.open(two)
            await a.close()
            await b.close()

    run(main())


def test_chudp_address_serves_the_same_robot() -> None:
    async def main() -> None:
        async with local(extra_addresses=["chudp://127.0.0.1:0?addr=440"]) as server:
            tcp, chudp = server.addresses
            assert chudp.startswith("chudp://127.0.0.1:") and "addr=0440" in chudp  # octal, as written
            client = await Raw.open(tcp)
            with pytest.raises(ConnectionRefused):  # one robot over every link
                await Raw.open(chudp)
            await client.close()
            await server.wait_idle()
            over_udp = await Raw.open(chudp)
            assert isinstance(over_udp.initial, Reply)
            await over_udp.reply("here")
            await over_udp.close()

    run(main())


def test_the_arm_stays_where_the_last_client_left_it() -> None:
    async def main() -> None:
        async with local(config=POWERED, time_scale=20.0) as server:
            client = await Raw.open(server.address)
            assert (await client.reply("set-joint-angles", joints=GOAL)).segment == 1
            await _until_still(server)
            await client.close()
            await server.wait_idle()
            assert server.joints == pytest.approx(GOAL)
            again = await Raw.open(server.address)
            angles = await again.reply("joint-angles")
            assert angles.values["joints"] == pytest.approx(GOAL, abs=1e-4)
            # the software state is the new connection's own: segment numbers start again at 1
            assert (await again.reply("set-joint-angles", joints=READY)).segment == 1
            await again.close()

    run(main())


# ------------------------------------------------------------------------------ bad input
def test_bad_input_is_answered_counted_and_survived() -> None:
    async def main() -> None:
        async with local(config=POWERED) as server:
            client = await Raw.open(server.address)
            _, msg = await client.raw(0o377, b"garbage")
            assert _error(msg) == ("C", "UOP")
            _, msg = await client.raw(0o230, b"")
            assert _error(msg) == ("C", "UOP")
            _, msg = await client.request("here", b"\x01\x02\x03")
            assert _error(msg) == ("C", "BDL")
            _, msg = await client.request("here", bytes(488))  # the largest packet there is
            assert _error(msg) == ("C", "BDL")
            reserved = b"".join(pack_f(x) for x in GOAL[:2]) + b"\x00\x80\x00\x00" + pack_f(0.0) * 3
            _, msg = await client.request("set-joint-angles", reserved)
            assert _error(msg) == ("C", "BFL")
            _, msg = await client.request("set-speed", factor=2.0)
            assert _error(msg)[0] == "C"
            # free joint: the next packet, whatever it is, is swallowed and answered done
            assert (await client.reply("free-joint", joint=2)).is_empty
            number, msg = await client.raw(0o377, b"\xff" * 300)
            assert isinstance(msg, Reply) and msg.is_empty and msg.request_number == number
            here = await client.reply("here")
            assert len(_tuple(here.values["transform"])) == 12
            stats = server.stats
            assert stats.bad_inputs == 6 and stats.errors == 6 and stats.discarded == 1
            assert stats.driver_errors == 0 and stats.fatal == 0
            await client.close()

    run(main())


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(
        st.tuples(st.integers(0o200, 0o377), st.binary(max_size=488)),
        min_size=1,
        max_size=25,
    )
)
def test_any_packets_get_one_answer_each_and_the_server_goes_on(packets: list[tuple[int, bytes]]) -> None:
    describe = SPEC.request("describe-self").opcode

    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address)
            for opcode, data in packets:
                number, msg = await client.raw(opcode, data)
                assert msg.request_number == number
                assert not (isinstance(msg, ErrorReply) and msg.fatal), msg
                if opcode == describe and isinstance(msg, Reply) and not msg.is_empty:
                    while not msg.is_empty:  # the rest of the text, then the terminator
                        msg = await client.receive()
                        assert isinstance(msg, Reply) and msg.request_number == number
            await client.reply("here")
            assert client.conn.pending == 0
            await client.close()
            assert server.stats.requests == len(packets) + 1
            assert server.stats.driver_errors == 0

    run(main())


def test_garbled_frames_end_only_their_link() -> None:
    async def main() -> None:
        async with local() as server:
            host, port = server.address.removeprefix("tcp://").rsplit(":", 1)
            reader, writer = await asyncio.open_connection(host, int(port))
            writer.write(b"\xff\xff" + bytes(64))  # a frame longer than any Chaos packet
            await writer.drain()
            assert await asyncio.wait_for(reader.read(), 5.0) == b""  # the server dropped the stream
            writer.close()
            assert server.bad_frames >= 1
            client = await Raw.open(server.address)  # and goes on serving
            await client.reply("here")
            await client.close()
            assert server.stats.driver_errors == 0

    run(main())


def test_a_fatal_error_closes_the_connection_and_the_server_goes_on() -> None:
    async def main() -> None:
        config = ServerConfig(faults=FaultSet.parse(["calibrate-nzi=2,3"]))
        async with local(config=config) as server:
            client = await Raw.open(server.address)
            number, msg = await client.request("calibrate")
            assert isinstance(msg, ErrorReply) and msg.fatal and msg.request_number == number
            assert msg.error.code == "NZI"
            with pytest.raises(ConnectionClosed):
                await client.receive(timeout=5.0)
            await client.close()
            await server.wait_idle()
            assert server.stats.fatal == 1
            again = await Raw.open(server.address)
            await again.reply("here")
            await again.close()

    run(main())


def test_a_client_vanishing_mid_move_leaves_the_arm_stopped() -> None:
    async def main() -> None:
        async with local(config=POWERED) as server:
            client = await Raw.open(server.address)
            await client.reply("set-joint-angles", joints=GOAL)
            await asyncio.sleep(0.3)  # part of the way (the move takes 1.2 s)
            client.conn.abort("gone")
            await server.wait_idle()
            stopped = server.joints
            assert stopped != pytest.approx(READY) and stopped != pytest.approx(GOAL)
            await asyncio.sleep(0.1)
            assert server.joints == stopped

    run(main())


# ------------------------------------------------------------------------------ logs and servo
def test_one_info_line_per_request(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger="manip.reference_server")

    async def main() -> None:
        async with local() as server:
            client = await Raw.open(server.address)
            here_no, _ = await client.request("here")
            bad_no, _ = await client.raw(0o377, b"")
            await client.close()
            await server.wait_idle()
            lines = [r.getMessage() for r in caplog.records if f"#{here_no} " in r.getMessage()]
            assert len(lines) == 1 and lines[0].endswith("here (0201): 48 data bytes")
            lines = [r.getMessage() for r in caplog.records if f"#{bad_no} " in r.getMessage()]
            assert len(lines) == 1 and "UOP" in lines[0] and "unknown (0377)" in lines[0]

    run(main())


def test_the_servo_runs_at_the_tick_rate_while_a_client_is_connected() -> None:
    async def main() -> None:
        async with local() as server:
            assert server.servo_period == pytest.approx(0.016)
            client = await Raw.open(server.address)
            await asyncio.sleep(0.5)
            ticks = server.stats.ticks
            assert 15 <= ticks <= 40  # 31 expected; the machine may be busy
            assert len(server.tick_lateness) == ticks
            await client.close()
            await server.wait_idle()
            await asyncio.sleep(0.1)
            assert server.stats.ticks <= ticks + 2  # idle: no client, no servo

    run(main())


def test_bad_arguments_are_refused() -> None:
    async def main() -> None:
        with pytest.raises(ValueError, match="time_scale"):
            async with local(time_scale=0.0):
                pass
        with pytest.raises(ValueError, match="max_clients"):
            async with local(max_clients=0):
                pass

    run(main())
