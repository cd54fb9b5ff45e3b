"""The blocking facade: a private event loop in a thread, the fake arm running in that loop."""

from __future__ import annotations

import asyncio
import logging
import threading
from collections.abc import Callable

import pytest

from manip.arm.transform import Transform
from manip.reference_client import (
    ClientOptions,
    ConnectionLostError,
    MemoryTransport,
    NonFatalError,
    RequestTimeout,
    connect,
)
from manip.reference_client.memory import SentRequest
from manip.spec.constants import RequestOp, ServerOp
from tests.support.fake_arm import GAUGES, HERE, JOINTS, FakeArm, error


def factory(
    fakes: list[FakeArm], setup: Callable[[FakeArm], None] = lambda fake: None
) -> Callable[[], MemoryTransport]:
    """Makes the transport and starts a fake arm, inside the connection's own loop."""

    def make() -> MemoryTransport:
        transport = MemoryTransport()
        fake = FakeArm(transport.peer)
        setup(fake)
        fakes.append(fake)
        asyncio.get_running_loop().create_task(fake.run())
        return transport

    return make


def complete_segments(fake: FakeArm) -> None:
    """After notifications are requested, report the current segment as completed."""

    def notifications(f: FakeArm, sent: SentRequest, _: object) -> None:
        f.peer.reply(sent.number)
        f.peer.segment_completed(sent.number, f.segment)

    fake.scripts[RequestOp.REQUEST_NOTIFICATIONS] = notifications


def test_blocking_calls() -> None:
    fakes: list[FakeArm] = []
    before = threading.active_count()
    with connect(factory(fakes, complete_segments)) as arm:
        assert arm.here().almost_equal(HERE, 1e-3)
        assert arm.joint_angles() == pytest.approx(JOINTS)
        assert arm.read_raw_gauges() == GAUGES
        assert arm.describe()["unique-name"] == "Trurl"
        segment = arm.move(Transform.trans(1.0, 2.0, 3.0))
        arm.wait_for_segment(segment, timeout=2.0)
        # the fake's description lists no 0257: the wait polled Joint angles (which stand still) instead
        assert arm.arm.waits_by_polling and arm.arm.notifications == 0
        arm.prepare_segment_wait()  # nothing more to ask for
        assert arm.arm.notifications == 0
        assert arm.request("wrist-version") == 0o17
        request = arm.make_request("hand", [0])
        assert arm.perform(request) is None
        assert threading.active_count() == before + 1
    assert arm.closed
    assert threading.active_count() == before
    assert [r.opcode for r in fakes[0].peer.received][-1] == RequestOp.HAND


def test_errors_cross_the_thread() -> None:
    fakes: list[FakeArm] = []

    def refuse_speed(fake: FakeArm) -> None:
        fake.scripts[RequestOp.SET_SPEED] = lambda f, s, _: f.peer.error(
            ServerOp.NON_FATAL_ERROR, s.number, error("BVA", "Speed out of range", severity="C")
        )
        fake.scripts[RequestOp.CALIBRATE] = lambda f, s, _: None  # never answered

    with connect(factory(fakes, refuse_speed), ClientOptions(timeout=0.05)) as arm:
        with pytest.raises(NonFatalError) as caught:
            arm.set_speed(0.5)
        assert caught.value.is_command_error
        with pytest.raises(RequestTimeout):
            arm.calibrate()
        arm.notify_trivial_errors = True
        assert arm.notify_trivial_errors


def test_listeners_run_in_the_loop_thread_and_may_not_block(caplog: pytest.LogCaptureFixture) -> None:
    fakes: list[FakeArm] = []
    threads: list[str] = []
    with connect(factory(fakes, complete_segments)) as arm:

        def listener(_: object) -> None:
            threads.append(threading.current_thread().name)
            arm.here()  # would deadlock: refused

        arm.add_async_listener(listener)
        with caplog.at_level(logging.ERROR, logger="manip.reference_client"):
            segment = arm.ready()
            arm.wait_for_segment(segment, timeout=2.0)
    assert threads == ["manip client (manipulator)"]
    assert "own event loop thread" in caplog.text


def test_failed_connect_stops_the_thread() -> None:
    before = threading.active_count()
    with pytest.raises(ConnectionLostError, match="refused"):
        connect(lambda: MemoryTransport(refuse="no"))
    assert threading.active_count() == before


def test_calls_after_the_server_closed() -> None:
    fakes: list[FakeArm] = []

    def hang_up(fake: FakeArm) -> None:
        fake.scripts[RequestOp.KILL_POWER] = lambda f, s, _: f.peer.close("operator hung up")

    with connect(factory(fakes, hang_up)) as arm:
        with pytest.raises(ConnectionLostError, match="operator hung up"):
            arm.kill_power()
        with pytest.raises(ConnectionLostError):
            arm.here()
        assert arm.closed
