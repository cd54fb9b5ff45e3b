"""The client over real Chaos connections (``manip.links``, loopback, ephemeral ports): the reference
server's asyncio driver (the ``served`` fixture, in a thread), and scripted links servers for the
failures; the scripts here are shared with the command-line tests.
"""

from __future__ import annotations

import asyncio

import pytest

import manip
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error
from manip.links import (
    ChaosConnection,
    ChaosError,
    ConnectionBroken,
    ConnectionClosed,
    ConnectionRefused,
    LinkError,
)
from manip.links import ConnectionLost as Los
from manip.reference_client import (
    NOTIFY_SEGMENTS,
    ClientOptions,
    ConnectionLostError,
    FatalError,
    NcpTransport,
    RequestTimeout,
    aconnect,
)
from manip.reference_client.ncp_transport import describe_chaos_end
from manip.reference_server import WorldCondition
from manip.reference_server.driver import ReferenceServer
from manip.spec.constants import ServerOp
from tests.support.fake_arm import run
from tests.support.scripted import READY, TARGET, never_answers, reply_done, segment_reporter, send_initial
from tests.support.servers import ServerOptions, free_port, scripted_server

# ------------------------------------------------------------------ the reference server


def test_async_with_aconnect_url(served: ReferenceServer) -> None:
    async def main() -> None:
        async with manip.aconnect(served.address) as arm:
            assert isinstance(arm.process.transport, NcpTransport)
            request = arm.make_request("joint-angles")
            joints = await arm.send_request(request)
            assert joints == pytest.approx(READY, abs=1e-3)
            assert request.packet_number == 2  # the NCP's number: the RFC was 1
            info = await arm.describe()
            assert info["degrees-of-freedom"] == 6
            await arm.enable_power()
            await arm.request_notifications(NOTIFY_SEGMENTS)
            segment = await arm.set_joint_angles(TARGET)
            await arm.wait_for_segment(segment, timeout=5.0)
            assert await arm.joint_angles() == pytest.approx(TARGET, abs=1e-3)
            pose = await arm.here()
            assert await arm.solve_forwards(pose, TARGET) == pytest.approx(TARGET, abs=1e-2)
        assert arm.closed
        transport = arm.process.transport
        assert isinstance(transport, NcpTransport)
        conn = transport.connection
        assert conn is not None and conn.ended

    run(main())


def test_blocking_connect_url(served: ReferenceServer) -> None:
    with manip.connect(served.address) as arm:
        assert arm.joint_angles() == pytest.approx(READY, abs=1e-3)
        arm.enable_power()
        arm.set_speed(0.5)
        pose = arm.here()
        assert arm.solve_backwards(READY).almost_equal(pose, 1e-2)
    assert arm.closed


@pytest.mark.parametrize("served", [ServerOptions(link="chudp")], indirect=True)
def test_chudp_url(served: ReferenceServer) -> None:
    async def main() -> None:
        url = served.address
        assert url.startswith("chudp://")
        async with aconnect(url) as arm:
            assert await arm.joint_angles() == pytest.approx(READY, abs=1e-3)

    run(main())


@pytest.mark.parametrize("served", [ServerOptions(contact="ARM")], indirect=True)
def test_contact_option_and_url_parameter(served: ReferenceServer) -> None:
    async def main() -> None:
        assert served.address.endswith("?contact=ARM")  # the server's address names its contact
        url = served.address.partition("?")[0]
        with pytest.raises(ConnectionLostError, match="contact PUMA") as info:
            await aconnect(url)
        assert isinstance(info.value.__cause__, ConnectionRefused)
        async with aconnect(url, contact="ARM") as arm:
            assert len(await arm.joint_angles()) == 6
        async with aconnect(url, ClientOptions(contact="ARM")) as arm:
            assert len(await arm.joint_angles()) == 6
        async with aconnect(f"{url}?contact=ARM") as arm:
            assert len(await arm.joint_angles()) == 6

    run(main())


def test_cannot_connect_to_a_free_port() -> None:
    async def main() -> None:
        with pytest.raises(ConnectionLostError, match="cannot connect") as info:
            await aconnect(f"tcp://127.0.0.1:{free_port()}", ClientOptions(connect_timeout=2.0))
        assert isinstance(info.value.__cause__, LinkError)

    run(main())


@pytest.mark.parametrize("served", [ServerOptions(faults=(WorldCondition.CALIBRATE_NZI,))], indirect=True)
def test_a_fatal_error_fails_the_pipelined_requests_and_aborts(served: ReferenceServer) -> None:
    async def main() -> None:
        async with aconnect(served.address) as arm:
            futures = [
                arm.send_request(arm.make_request(name)) for name in ("calibrate", "here", "joint-angles")
            ]
            outcomes = await asyncio.gather(*futures, return_exceptions=True)
            assert all(isinstance(o, FatalError) for o in outcomes), outcomes
            assert {o.code for o in outcomes if isinstance(o, FatalError)} == {"NZI"}
            assert arm.closed
            with pytest.raises(ConnectionLostError):
                await arm.here()

    run(main())


# ------------------------------------------------------------------ scripted servers


def test_connection_dropped_mid_request() -> None:
    async def unplugged(conn: ChaosConnection) -> None:
        await send_initial(conn)
        await conn.receive()
        conn.abort("robot unplugged")

    async def main() -> None:
        async with scripted_server(unplugged) as url, aconnect(url) as arm:
            with pytest.raises(ConnectionLostError, match="robot unplugged") as info:
                await arm.here()
            assert isinstance(info.value.__cause__, ChaosError)
            assert arm.closed

    run(main())


def test_a_server_that_never_answers_times_out() -> None:
    async def main() -> None:
        async with scripted_server(never_answers) as url, aconnect(url, ClientOptions(timeout=0.2)) as arm:
            with pytest.raises(RequestTimeout):
                await arm.here()
            assert not arm.closed  # a timeout gives up one request, not the connection

    run(main())


def test_asynchronous_responses_over_tcp() -> None:
    async def main() -> None:
        async with scripted_server(segment_reporter) as url, aconnect(url) as arm:
            async with arm.async_responses() as stream:
                await arm.request_notifications(NOTIFY_SEGMENTS)
                got = [await anext(stream), await anext(stream)]
            assert [r.word3 for r in got] == [7, 8]
            await arm.wait_for_segment(8)  # already completed: returns at once

    run(main())


def test_graceful_close_sends_eof_and_a_fatal_error_aborts() -> None:
    endings: list[str] = []

    async def recorder(conn: ChaosConnection, fatal: bool) -> None:
        await send_initial(conn)
        request = await conn.receive()
        if fatal:
            error = ErrorMessage("test", "F", "XYZ", "gave up")
            await conn.send(
                encode_error(ServerOp.FATAL_ERROR, request.packet_no, error), ServerOp.FATAL_ERROR
            )
        else:
            await reply_done(conn, request.packet_no)
        try:
            while True:
                await conn.receive()
        except ChaosError as exc:
            endings.append(str(exc))

    async def main() -> None:
        for fatal in (False, True):

            async def handler(conn: ChaosConnection, fatal: bool = fatal) -> None:
                await recorder(conn, fatal)

            async with scripted_server(handler) as url:
                transport = NcpTransport(url)
                async with aconnect(transport) as arm:
                    if fatal:
                        with pytest.raises(FatalError, match="XYZ"):
                            await arm.calibrate()
                    else:
                        await arm.calibrate()
                await transport.disconnect()  # again: nothing happens
                for _ in range(100):
                    if len(endings) == (2 if fatal else 1):
                        break
                    await asyncio.sleep(0.01)
        assert endings[0] == "EOF"
        assert "fatal error" in endings[1]

    run(main())


def test_links_errors_read_as_who_ended_the_connection() -> None:
    assert describe_chaos_end(ConnectionClosed("EOF", by_peer=True)) == "closed by the server (EOF)"
    assert describe_chaos_end(ConnectionClosed("bye", by_peer=False)) == "closed here (bye)"
    assert describe_chaos_end(Los("unknown connection")) == "lost (LOS: unknown connection)"
    assert describe_chaos_end(ConnectionBroken("silent for 90 s")) == "broken (silent for 90 s)"
