"""The client against the real reference server core (``ServerSession``), in memory on a virtual clock.

Every E.1 operation end to end, the notifications path, a fatal error with requests pending, a
connection dropped mid-request, flow control and packet numbers that wrap.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import pytest

from manip.arm.kinematics import PUMA600, forward
from manip.arm.transform import Transform
from manip.codecs.messages import AsyncResponse
from manip.reference_client import (
    NOTIFY_SEGMENTS,
    ClientOptions,
    ConnectionLostError,
    CoreTransport,
    FatalError,
    JointFreedError,
    ManipError,
    Manipulator,
    NonFatalError,
    aconnect,
)
from manip.reference_server import FaultSet, ServerConfig, ServerSession, State
from manip.spec.constants import AsyncCondition, RequestOp, ServerOp
from tests.support.fake_arm import run

READY = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)
TARGET = (20.0, -70.0, 100.0, 10.0, 30.0, -15.0)


@asynccontextmanager
async def reference(
    config: ServerConfig | None = None, options: ClientOptions | None = None, **kw: object
) -> AsyncIterator[tuple[Manipulator, CoreTransport, ServerSession]]:
    core = ServerSession(config)
    transport = CoreTransport(core, **kw)  # type: ignore[arg-type]
    async with aconnect(transport, options) as arm:
        yield arm, transport, core


def state_of(core: ServerSession) -> State:
    return core.state


def close_joints(a: tuple[float, ...], b: tuple[float, ...], tol: float = 1e-3) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


# ------------------------------------------------------------------ queries


def test_here_and_joint_angles_at_the_ready_position() -> None:
    async def main() -> None:
        async with reference() as (arm, _, core):
            joints = await arm.joint_angles()
            assert close_joints(joints, READY)
            assert (await arm.here()).almost_equal(forward(READY, PUMA600.geometry), 1e-2)
            assert core.state is State.READY

    run(main())


def test_describe_is_a_dict_from_the_alist() -> None:
    async def main() -> None:
        async with reference() as (arm, _, _core):
            info = await arm.describe()
            assert info["degrees-of-freedom"] == 6
            assert "Puma" in str(info["brand-name"])
            operations = info["operations"]
            assert isinstance(operations, list)
            assert set(range(RequestOp.DESCRIBE_SELF, RequestOp.SOLVE_BACKWARDS + 1)) <= set(operations)
            assert info["ready-position"] == list(READY)

    run(main())


def test_calibrate_configuration_and_hand_are_done() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, core):
            await arm.calibrate()
            await arm.set_configuration(lefty=True)
            assert core.arm.lefty
            await arm.set_configuration(lefty=False)
            assert not core.arm.lefty
            await arm.enable_power()  # the hand needs arm power
            await arm.open_hand()
            assert core.arm.hand_open
            await arm.close_hand()
            assert not core.arm.hand_open
            opcodes = [s.opcode for s in transport.sent]
            assert opcodes == [
                RequestOp.CALIBRATE,
                RequestOp.SET_CONFIGURATION,
                RequestOp.SET_CONFIGURATION,
                RequestOp.ENABLE_POWER,
                RequestOp.HAND,
                RequestOp.HAND,
            ]

    run(main())


# ------------------------------------------------------------------ power and motion


def test_motion_needs_power_and_kill_power_removes_it() -> None:
    async def main() -> None:
        async with reference() as (arm, _, _core):
            with pytest.raises(NonFatalError) as info:
                await arm.set_joint_angles(TARGET)
            assert (info.value.code, info.value.severity) == ("NAP", "E")
            assert info.value.meaning == "No arm power"
            await arm.enable_power()
            assert isinstance(await arm.set_joint_angles(TARGET), int)
            await arm.kill_power()
            with pytest.raises(NonFatalError, match="NAP"):
                await arm.ready()

    run(main())


def test_set_joint_angles_then_wait_for_the_segment() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            await arm.enable_power()
            segment = await arm.set_joint_angles(TARGET)
            await transport.run_until(arm.wait_for_segment(segment))
            assert arm.last_completed_segment == segment
            assert close_joints(await arm.joint_angles(), TARGET)
            ready = await arm.ready()
            assert ready == (segment + 1) & 0xFFFF
            await transport.run_until(arm.wait_for_segment(ready))
            assert close_joints(await arm.joint_angles(), READY)

    run(main())


@pytest.mark.parametrize("straight", [False, True])
def test_move_to_a_transform(straight: bool) -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            await arm.enable_power()
            await transport.run_until(arm.wait_for_segment(await arm.set_joint_angles(TARGET)))
            start = await arm.here()  # away from the ready position, where the wrist is near singular
            goal = Transform.trans(30.0, -20.0, -60.0) @ start
            segment = await (arm.straight_move(goal) if straight else arm.move(goal))
            await transport.run_until(arm.wait_for_segment(segment))
            assert (await arm.here()).almost_equal(goal, 1e-2)

    run(main())


@pytest.mark.parametrize("straight", [False, True])
def test_incremental_moves(straight: bool) -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            await arm.enable_power()
            await transport.run_until(arm.wait_for_segment(await arm.set_joint_angles(TARGET)))
            before = await arm.here()
            move = arm.incremental_straight_move if straight else arm.incremental_move
            segment = await move(dx=-15.0, dz=-40.0)
            await transport.run_until(arm.wait_for_segment(segment))
            after = await arm.here()
            dx, dy, dz = (float(v) for v in after.p - before.p)
            assert (round(dx, 2), round(dy, 2), round(dz, 2)) == (-15.0, 0.0, -40.0)

    run(main())


def test_set_speed_in_range_and_out_of_range() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, core):
            await arm.set_speed(0.25)
            assert core.arm.speed == pytest.approx(0.25, rel=1e-6)
            with pytest.raises(ValueError, match="speed factor"):
                await arm.set_speed(1.5)  # checked by the client, never sent
            assert transport.sent[-1].opcode == RequestOp.SET_SPEED
            sent = len(transport.sent)
            with pytest.raises(NonFatalError) as info:  # the server's check, bypassing the client's
                await arm.request("set-speed", fields={"factor": 1.5})
            assert len(transport.sent) == sent + 1
            assert (info.value.severity, info.value.code) == ("C", "BVA")
            assert core.arm.speed == pytest.approx(0.25, rel=1e-6)

    run(main())


def test_solve_forwards_and_backwards_round_trip() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            pose = await arm.solve_backwards(TARGET)
            assert pose.almost_equal(forward(TARGET, PUMA600.geometry), 1e-2)
            joints = await arm.solve_forwards(pose, TARGET)
            assert close_joints(joints, TARGET, 1e-2)
            assert [s.opcode for s in transport.sent] == [RequestOp.SOLVE_BACKWARDS, RequestOp.SOLVE_FORWARDS]

    run(main())


def test_free_joint_then_the_throw_away_request() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, core):
            await arm.enable_power()
            await arm.free_joint(3)
            assert state_of(core) is State.FREE_JOINT_WAIT
            with pytest.raises(JointFreedError):
                await arm.here()
            await arm.release_joint()
            assert state_of(core) is State.READY
            assert transport.sent[-1].opcode == RequestOp.HERE  # discarded by the server, answered done
            assert close_joints(await arm.joint_angles(), READY)

    run(main())


# ------------------------------------------------------------------ asynchronous responses


def test_notifications_reach_listeners_and_the_async_iterator() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            heard: list[AsyncResponse] = []
            arm.add_async_listener(heard.append)
            await arm.enable_power()
            await arm.request_notifications(NOTIFY_SEGMENTS)
            async with arm.async_responses() as stream:
                first = await arm.set_joint_angles(TARGET)
                second = await arm.ready()

                async def two() -> list[AsyncResponse]:
                    return [await anext(stream), await anext(stream)]

                got = await transport.run_until(two())
            assert [(r.condition, r.word3) for r in got] == [
                (AsyncCondition.SEGMENT_COMPLETED, first),
                (AsyncCondition.SEGMENT_COMPLETED, second),
            ]
            assert heard == got
            # the request number is the last request the server processed (the ready)
            assert got[1].request_number == transport.sent[-1].number

    run(main())


def test_no_segment_reports_without_notifications() -> None:
    async def main() -> None:
        async with reference() as (arm, transport, _core):
            heard: list[AsyncResponse] = []
            arm.add_async_listener(heard.append)
            await arm.enable_power()
            await arm.ready()
            await transport.advance(5.0)
            assert heard == []
            assert not any(p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE for p in transport.received)

    run(main())


# ------------------------------------------------------------------ numbering, flow control, failures


def test_packet_numbers_wrap_modulo_2_16() -> None:
    async def main() -> None:
        async with reference(first_number=0xFFFD, server_first_number=0xFFFF) as (arm, transport, _core):
            for _ in range(4):
                assert close_joints(await arm.joint_angles(), READY)
            assert [s.number for s in transport.sent] == [0xFFFE, 0xFFFF, 0, 1]
            numbers = [p.packet_number for p in transport.received]
            assert numbers == [0, 1, 2, 3, 4]  # the initial RESPONSE, then one reply per request
            echoed = [int.from_bytes(p.data[:2], "little") for p in transport.received]
            assert echoed == [0xFFFD, 0xFFFE, 0xFFFF, 0, 1]

    run(main())


def test_window_limits_requests_in_flight() -> None:
    async def main() -> None:
        async with reference(hold=True, window=2) as (arm, transport, _core):
            futures = [arm.send_request(arm.make_request("joint-angles")) for _ in range(3)]
            for _ in range(5):
                await asyncio.sleep(0)
            assert len(transport.held) == 2
            assert arm.process.queued and len(arm.process.queued) == 1
            transport.deliver_held()
            for _ in range(5):
                await asyncio.sleep(0)
            transport.deliver_held()
            results = await asyncio.gather(*futures)
            assert all(close_joints(r, READY) for r in results)

    run(main())


def test_a_fatal_error_fails_every_pending_request_at_once() -> None:
    async def main() -> None:
        config = ServerConfig(faults=FaultSet.parse(["calibrate-nzi"]))
        async with reference(config, hold=True) as (arm, transport, _core):
            errors: list[ManipError] = []
            arm.add_error_listener(errors.append)
            calibrate = arm.send_request(arm.make_request("calibrate"))
            here = arm.send_request(arm.make_request("here"))
            joints = arm.send_request(arm.make_request("joint-angles"))
            for _ in range(5):
                await asyncio.sleep(0)
            transport.deliver_held(1)  # the server answers calibrate with a fatal error and closes
            outcomes = await asyncio.gather(calibrate, here, joints, return_exceptions=True)
            assert all(isinstance(o, FatalError) for o in outcomes), outcomes
            fatal = outcomes[0]
            assert isinstance(fatal, FatalError)
            assert (fatal.code, fatal.severity) == ("NZI", "F")
            assert fatal.request_number == transport.sent[0].number
            assert any(isinstance(e, FatalError) for e in errors)
            assert arm.closed
            with pytest.raises(ConnectionLostError) as info:
                await arm.here()
            assert isinstance(info.value.__cause__, FatalError)

    run(main())


def test_connection_dropped_mid_request() -> None:
    async def main() -> None:
        async with reference(hold=True) as (arm, transport, _core):
            stream = arm.async_responses()
            pending = arm.send_request(arm.make_request("here"))
            for _ in range(5):
                await asyncio.sleep(0)
            assert transport.held
            transport.drop("link went down")
            with pytest.raises(ConnectionLostError, match="link went down"):
                await pending
            with pytest.raises(ConnectionLostError):
                await anext(stream)
            assert arm.closed

    run(main())


def test_trivial_errors_are_notified_when_asked() -> None:
    async def main() -> None:
        # no wrist: the wrist operations are answered C UIM (not implemented), a trivial error
        async with reference(options=ClientOptions(notify_trivial_errors=True)) as (arm, _, _core):
            notified: list[ManipError] = []
            arm.add_error_listener(notified.append)
            await arm.set_spring([1.0] * 6)  # answered: no exception
            assert [getattr(e, "code", None) for e in notified] == ["UIM"]
            with pytest.raises(NonFatalError, match="UIM"):  # a value was wanted: still raised
                await arm.read_forces()
            arm.notify_trivial_errors = False
            with pytest.raises(NonFatalError, match="UIM"):
                await arm.set_spring([1.0] * 6)

    run(main())
