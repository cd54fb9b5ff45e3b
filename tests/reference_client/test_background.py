"""The background process against scripted servers: ordering, errors, loss, timeouts, asynchronous
responses, trivial errors and segments."""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from typing import Any

import pytest

from manip.arm.transform import Transform
from manip.codecs.messages import AsyncResponse, encode_async, encode_reply
from manip.reference_client import (
    NOTIFY_SEGMENTS,
    AsynchronousError,
    AsynchronousWarning,
    AsyncResponseStream,
    ClientOptions,
    ConnectionLostError,
    FatalError,
    GuardTrippedError,
    ManipError,
    MemoryTransport,
    NonFatalError,
    OutOfSequenceReason,
    OutOfSequenceResponse,
    RequestState,
    RequestTimeout,
    aconnect,
)
from manip.reference_client.memory import MemoryPeer, SentRequest
from manip.spec.constants import RequestOp, ServerOp
from tests.support.fake_arm import FORCES, JOINTS, FakeArm, error, manual, run, session

TARGET = Transform.trans(300.0, 100.0, -50.0)


async def settle(rounds: int = 20) -> None:
    """Let the background process and the peer run until nothing is left to do."""
    for _ in range(rounds):
        await asyncio.sleep(0)


async def take(peer: MemoryPeer, count: int) -> list[SentRequest]:
    out = []
    for _ in range(count):
        sent = await peer.receive()
        assert sent is not None
        out.append(sent)
    return out


def errors_of(arm_errors: list[ManipError], kind: type[ManipError]) -> list[ManipError]:
    return [e for e in arm_errors if isinstance(e, kind)]


# ----------------------------------------------------------------------------------- ordering


def test_responses_out_of_order() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            peer = fake.peer
            tasks = [
                asyncio.create_task(arm.read_forces()),
                asyncio.create_task(arm.ready()),
                asyncio.create_task(arm.calibrate()),
            ]
            forces, ready, calibrate = await take(peer, 3)
            assert [s.opcode for s in (forces, ready, calibrate)] == [0o240, 0o214, 0o203]
            assert [s.number for s in (forces, ready, calibrate)] == [2, 3, 4]  # after the RFC's 1
            peer.reply(calibrate.number)
            peer.send(ServerOp.RESPONSE, encode_reply("ready", ready.number, segment=9))
            peer.send(ServerOp.RESPONSE, encode_reply("read-forces", forces.number, forces=FORCES))
            assert await asyncio.gather(*tasks) == [pytest.approx(FORCES), 9, None]

    run(main())


def test_duplicate_and_unknown_responses_are_reported_and_the_connection_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            reported: list[ManipError] = []
            arm.add_error_listener(reported.append)
            peer = fake.peer
            task = asyncio.create_task(arm.calibrate())
            (sent,) = await take(peer, 1)
            peer.reply(sent.number)
            peer.reply(sent.number)  # duplicate
            peer.send(0o207, sent.number.to_bytes(2, "little"))  # unknown response opcode
            peer.reply(0o4000)  # answers nothing
            peer.send(ServerOp.RESPONSE, b"\x05")  # no request number
            assert await task is None
            await settle()
            reasons = [e.reason for e in errors_of(reported, OutOfSequenceResponse)]
            assert reasons == [
                OutOfSequenceReason.DUPLICATE,
                OutOfSequenceReason.UNKNOWN_OPCODE,
                OutOfSequenceReason.UNMATCHED,
                OutOfSequenceReason.MALFORMED,
            ]
            follow = asyncio.create_task(arm.kill_power())
            (again,) = await take(peer, 1)
            peer.reply(again.number)
            assert await follow is None
            assert arm.process.transport.returned == 7  # with the initial RESPONSE

    with caplog.at_level(logging.WARNING, logger="manip.reference_client"):
        run(main())
    assert sum("out-of-sequence" in r.getMessage() for r in caplog.records) == 4


def test_asynchronous_response_in_the_middle_of_a_multi_packet_response() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            peer = fake.peer
            stream = arm.async_responses()
            task = asyncio.create_task(arm.request("describe-self", extractor="text"))
            (sent,) = await take(peer, 1)
            peer.reply(sent.number, b"((:brand-name . ")
            peer.segment_completed(sent.number, 4)
            peer.guard_hit(sent.number, 2, stop=False)
            peer.reply(sent.number, b'"X"))')
            peer.reply(sent.number)
            assert await task == '((:brand-name . "X"))'
            first = await anext(stream)
            second = await anext(stream)
            assert (first.condition_name, first.word3) == ("segment-completed", 4)
            assert (second.condition_name, second.word2, second.word3) == ("guard-hit", 2, 2)
            assert arm.last_completed_segment == 4
            stream.close()

    run(main())


def test_transmit_window_is_respected() -> None:
    async def main() -> None:
        async with session(manual, window=2) as (arm, fake):
            peer = fake.peer
            tasks = [asyncio.create_task(arm.calibrate()) for _ in range(5)]
            await settle()
            assert peer.pending_requests() == 2 and len(arm.process.queued) == 3
            (first,) = await take(peer, 1)
            await settle()
            assert peer.pending_requests() == 2 and len(arm.process.queued) == 2
            for sent in [first, *await take(peer, 4)]:
                peer.reply(sent.number)
            assert await asyncio.gather(*tasks) == [None] * 5

    run(main())


# ----------------------------------------------------------------------------------- errors


def test_non_fatal_error_raises_in_the_caller_only() -> None:
    async def main() -> None:
        async with session() as (arm, fake):

            def refuse(f: FakeArm, sent: SentRequest, _: object) -> None:
                f.peer.error(ServerOp.NON_FATAL_ERROR, sent.number, error("NAP", "No arm power"))

            fake.scripts[RequestOp.MOVE] = refuse
            with pytest.raises(NonFatalError) as caught:
                await arm.move(TARGET)
            assert caught.value.code == "NAP" and caught.value.request is not None
            assert caught.value.request.state is RequestState.FAILED
            assert await arm.joint_angles() == pytest.approx(JOINTS)

    run(main())


def test_fatal_error_fails_pending_and_queued_requests_at_once() -> None:
    async def main() -> None:
        async with session(manual, window=2) as (arm, fake):
            reported: list[ManipError] = []
            closed: list[ManipError] = []
            arm.add_error_listener(reported.append)
            arm.add_close_listener(closed.append)
            peer = fake.peer
            tasks = [asyncio.create_task(arm.calibrate()) for _ in range(4)]
            await settle()
            assert len(arm.process.queued) == 2 and peer.pending_requests() == 2  # two sent, two queued
            peer.error(ServerOp.FATAL_ERROR, 3, error("PAN", "Panic button pressed", severity="F"))
            peer.close("CLS after fatal error")
            results = await asyncio.gather(*tasks, return_exceptions=True)
            assert all(isinstance(r, FatalError) and r.code == "PAN" for r in results)
            assert {r.request.state for r in results if isinstance(r, FatalError) and r.request} == {
                RequestState.FAILED
            }
            assert [type(e) for e in reported] == [FatalError] and closed == reported
            with pytest.raises(ConnectionLostError) as later:
                await arm.here()
            assert isinstance(later.value.__cause__, FatalError)
            assert arm.closed

    run(main())


def test_connection_dropped_mid_request() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            peer = fake.peer
            answered = asyncio.create_task(arm.calibrate())
            dropped = asyncio.create_task(arm.here())
            first, _ = await take(peer, 2)
            peer.reply(first.number)  # arrives before the close: still delivered
            peer.close("network went down")
            assert await answered is None
            with pytest.raises(ConnectionLostError, match="network went down"):
                await dropped
            with pytest.raises(ConnectionLostError, match="network went down"):
                await arm.here()

    run(main())


def test_asynchronous_errors_and_warnings_go_to_listeners_and_the_log(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            reported: list[ManipError] = []
            arm.add_error_listener(reported.append)

            def broken(_: ManipError) -> None:
                raise RuntimeError("listener bug")

            arm.add_error_listener(broken)
            fake.peer.error(ServerOp.ASYNCHRONOUS_ERROR, 1, error("AWA", "Arm motion was aborted"))
            fake.peer.error(ServerOp.ASYNCHRONOUS_WARNING, 1, error("CTO", "slow wrist", severity="W"))
            await settle()
            assert [type(e) for e in reported] == [AsynchronousError, AsynchronousWarning]
            assert reported[0].rendered == "fake: E AWA Arm motion was aborted"
            assert not arm.closed

    with caplog.at_level(logging.WARNING, logger="manip.reference_client"):
        run(main())
    text = caplog.text
    assert "AWA" in text and "CTO" in text and "listener" in text


# ----------------------------------------------------------------------------------- timeouts


def test_server_that_never_answers_times_out_and_a_late_reply_is_reported() -> None:
    async def main() -> None:
        options = ClientOptions(timeout=0.05)
        async with session(manual, options) as (arm, fake):
            reported: list[ManipError] = []
            arm.add_error_listener(reported.append)
            with pytest.raises(RequestTimeout) as caught:
                await arm.here()
            assert isinstance(caught.value, TimeoutError) and caught.value.timeout == 0.05
            (sent,) = await take(fake.peer, 1)
            fake.peer.reply(sent.number)
            await settle()
            (late,) = reported
            assert isinstance(late, OutOfSequenceResponse) and late.reason is OutOfSequenceReason.LATE
            task = asyncio.create_task(arm.calibrate(timeout=None))
            (next_sent,) = await take(fake.peer, 1)
            fake.peer.reply(next_sent.number)
            assert await task is None

    run(main())


def test_queued_request_times_out_without_being_sent() -> None:
    async def main() -> None:
        async with session(manual, window=1) as (arm, fake):
            blocker = asyncio.create_task(arm.calibrate(timeout=None))
            await settle()
            with pytest.raises(RequestTimeout):
                await arm.here(timeout=0.02)
            assert fake.peer.pending_requests() == 1
            (sent,) = await take(fake.peer, 1)
            fake.peer.reply(sent.number)
            assert await blocker is None
            await settle()
            assert fake.peer.pending_requests() == 0  # the timed-out Here never went out

    run(main())


def test_cancelled_requests() -> None:
    async def main() -> None:
        async with session(manual, window=1) as (arm, fake):
            reported: list[ManipError] = []
            arm.add_error_listener(reported.append)
            sent_task = asyncio.create_task(arm.calibrate(timeout=None))
            queued_task = asyncio.create_task(arm.here(timeout=None))
            await settle()
            sent_task.cancel()
            queued_task.cancel()
            await asyncio.gather(sent_task, queued_task, return_exceptions=True)
            (sent,) = await take(fake.peer, 1)
            fake.peer.reply(sent.number)
            await settle()
            assert fake.peer.pending_requests() == 0
            assert [e.reason for e in reported] == [OutOfSequenceReason.LATE]

    run(main())


# ----------------------------------------------------------------------------------- trivial errors


def _unimplemented(f: FakeArm, sent: SentRequest, _: object) -> None:
    f.peer.error(ServerOp.NON_FATAL_ERROR, sent.number, error("UIM", "Not implemented on this arm"))


def test_notify_trivial_errors() -> None:
    async def main() -> None:
        async with session(options=ClientOptions(notify_trivial_errors=True)) as (arm, fake):
            reported: list[ManipError] = []
            arm.add_error_listener(reported.append)
            fake.scripts[RequestOp.SET_CONFIGURATION] = _unimplemented
            fake.scripts[RequestOp.HERE] = _unimplemented
            fake.scripts[RequestOp.KILL_POWER] = lambda f, s, _: f.peer.error(
                ServerOp.NON_FATAL_ERROR, s.number, error("NAP", "No arm power")
            )
            assert arm.notify_trivial_errors
            assert await arm.set_configuration(True) is None  # trivial: notified, not raised
            assert [e.code for e in reported] == ["UIM"]
            with pytest.raises(NonFatalError, match="UIM"):
                await arm.here()  # a data request has nothing to return: raised
            with pytest.raises(NonFatalError, match="NAP"):
                await arm.kill_power()  # not trivial
            arm.notify_trivial_errors = False
            assert not arm.notify_trivial_errors
            with pytest.raises(NonFatalError, match="UIM"):
                await arm.set_configuration(True)
            assert len(reported) == 1

    run(main())


def test_trivial_error_policy_is_configurable() -> None:
    from manip.reference_client import TrivialErrors

    async def main() -> None:
        options = ClientOptions(
            notify_trivial_errors=True, trivial_errors=TrivialErrors(codes=frozenset({"NAP"}))
        )
        async with session(options=options) as (arm, fake):
            fake.scripts[RequestOp.HAND] = lambda f, s, _: f.peer.error(
                ServerOp.NON_FATAL_ERROR, s.number, error("NAP", "No arm power")
            )
            fake.scripts[RequestOp.SET_CONFIGURATION] = _unimplemented
            assert await arm.close_hand() is None
            with pytest.raises(NonFatalError, match="UIM"):
                await arm.set_configuration(False)

    run(main())


# ----------------------------------------------------------------------------------- segments


def test_wait_for_segment_asks_for_notifications_and_waits() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            segment = await arm.move(TARGET)
            waiter = asyncio.create_task(arm.wait_for_segment(segment))
            await settle()
            assert [r.opcode for r in fake.peer.received] == [RequestOp.MOVE, RequestOp.REQUEST_NOTIFICATIONS]
            assert fake.peer.received[1].data == NOTIFY_SEGMENTS.to_bytes(2, "little")
            assert arm.notifications == NOTIFY_SEGMENTS and not waiter.done()
            fake.peer.segment_completed(3, segment)
            await waiter
            await arm.wait_for_segment(segment)  # already done: returns at once, nothing sent
            assert len(fake.peer.received) == 2

    run(main())


def test_a_later_segment_completes_earlier_ones_modulo_2_16() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            await arm.request_notifications(NOTIFY_SEGMENTS)
            waiters = [asyncio.create_task(arm.wait_for_segment(n)) for n in (0xFFFE, 0xFFFF, 0, 1)]
            await settle()
            fake.peer.segment_completed(1, 0)
            await settle()
            assert [w.done() for w in waiters] == [True, True, True, False]
            fake.peer.segment_completed(1, 1)
            await asyncio.gather(*waiters)
            assert [r.opcode for r in fake.peer.received] == [RequestOp.REQUEST_NOTIFICATIONS]

    run(main())


def test_the_guides_asynchronous_layout_is_read_by_its_length() -> None:
    # E.3: "The first word of the response is a code indicating the condition", then two words
    async def main() -> None:
        async with session() as (arm, fake):
            await arm.request_notifications(NOTIFY_SEGMENTS)
            seen: list[AsyncResponse] = []
            arm.add_async_listener(seen.append)
            waiter = asyncio.create_task(arm.wait_for_segment(9))
            await settle()
            fake.peer.send(
                ServerOp.ASYNCHRONOUS_RESPONSE, encode_async(0, 2, 0, 9, async_has_request_number=False)
            )
            await waiter
            fake.peer.guard_hit(3, 4, stop=False)  # manip's layout on the same connection
            await settle()
            assert seen == [AsyncResponse(None, 2, 0, 9), AsyncResponse(3, 1, 2, 4)]
            assert seen[0].layout == "guide" and seen[1].layout == "numbered"

    run(main())


def test_segment_waiters_fail_on_abort_guard_stop_close_and_timeout() -> None:
    async def main() -> None:
        async with session() as (arm, fake):
            await arm.request_notifications(NOTIFY_SEGMENTS)
            aborted = asyncio.create_task(arm.wait_for_segment(5))
            await settle()
            fake.peer.error(ServerOp.ASYNCHRONOUS_ERROR, 2, error("AWA", "Arm motion was aborted"))
            with pytest.raises(AsynchronousError, match="AWA"):
                await aborted

            guarded = asyncio.create_task(arm.wait_for_segment(6))
            await settle()
            fake.peer.guard_hit(2, 4, stop=False)  # continue: nothing happens
            await settle()
            assert not guarded.done()
            fake.peer.guard_hit(2, 4, stop=True)
            with pytest.raises(GuardTrippedError) as tripped:
                await guarded
            assert tripped.value.guard == 4

            with pytest.raises(RequestTimeout, match="segment 7"):
                await arm.wait_for_segment(7, timeout=0.02)

            lost = asyncio.create_task(arm.wait_for_segment(8))
            await settle()
            fake.peer.close("gone")
            with pytest.raises(ConnectionLostError, match="gone"):
                await lost
            with pytest.raises(ConnectionLostError):
                await arm.wait_for_segment(9)

    run(main())


# ----------------------------------------------------------------------------------- streams and closing


def test_async_response_stream_ends_on_close_and_raises_on_loss() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            stream = arm.async_responses()
            fake.peer.segment_completed(1, 1)
            fake.peer.close("link down")
            got = [r async for r in _until_error(stream)]
            assert [r.word3 for r in got[:-1]] == [1] and isinstance(got[-1], ConnectionLostError)

        async with session(manual) as (arm, fake):
            stream = arm.async_responses()
            fake.peer.segment_completed(1, 2)
            await settle()
            await arm.aclose()
            assert [r.word3 async for r in stream] == [2]

    run(main())


async def _until_error(stream: AsyncResponseStream) -> AsyncIterator[AsyncResponse | ManipError]:
    try:
        async for item in stream:
            yield item
    except ManipError as exc:
        yield exc


def test_user_close_fails_waiting_requests() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            task = asyncio.create_task(arm.here(timeout=None))
            await take(fake.peer, 1)
            await arm.aclose()
            with pytest.raises(ConnectionLostError, match="closed by the user"):
                await task
            assert arm.process.closed_by_user
            assert await fake.peer.receive() is None  # the peer saw the disconnect

    run(main())


# ----------------------------------------------------------------------------------- connecting


def test_connect_failures() -> None:
    async def refused() -> None:
        with pytest.raises(ConnectionLostError, match="refused: busy"):
            await aconnect(MemoryTransport(refuse="busy"))

    async def silent() -> None:
        with pytest.raises(ConnectionLostError, match="no initial RESPONSE"):
            await aconnect(MemoryTransport, ClientOptions(connect_timeout=0.02))

    async def fatal() -> None:
        transport = MemoryTransport()

        async def server() -> None:
            await transport.peer.wait_connected()
            transport.peer.error(ServerOp.FATAL_ERROR, 1, error("BUG", "Server busy", severity="F"))
            transport.peer.close()

        task = asyncio.create_task(server())
        with pytest.raises(FatalError, match="Server busy"):
            await aconnect(transport)
        await task

    async def closed_before_response() -> None:
        transport = MemoryTransport()

        async def server() -> None:
            await transport.peer.wait_connected()
            transport.peer.close("no robot here")

        task = asyncio.create_task(server())
        with pytest.raises(ConnectionLostError, match="no robot here"):
            await aconnect(transport)
        await task

    for case in (refused, silent, fatal, closed_before_response):
        run(case())


def test_initial_response_number_is_not_checked() -> None:
    async def main() -> None:
        async with session(lambda peer: FakeArm(peer, initial_number=0o123456)) as (arm, _):
            assert await arm.joint_angles() == pytest.approx(JOINTS)

    run(main())


def test_packet_numbers_wrap_modulo_2_16() -> None:
    async def main() -> None:
        async with session(first_number=0xFFFE) as (arm, fake):
            for _ in range(3):
                await arm.calibrate()
            assert [r.number for r in fake.peer.received] == [0xFFFF, 0, 1]

    run(main())


class _BrokenTransport(MemoryTransport):
    """Fails to send the request after the first."""

    async def send_user_request(self, request: Any) -> None:
        if self.peer.received or self.peer.pending_requests():
            raise RuntimeError("driver bug")
        await super().send_user_request(request)


def test_a_failing_transport_fails_every_request_instead_of_hanging(caplog: pytest.LogCaptureFixture) -> None:
    async def main() -> None:
        transport = _BrokenTransport()
        fake = FakeArm(transport.peer, auto_reply=False)
        server = asyncio.create_task(fake.run())
        arm = await aconnect(transport)
        first = asyncio.create_task(arm.here(timeout=None))
        second = asyncio.create_task(arm.calibrate(timeout=None))
        results = await asyncio.gather(first, second, return_exceptions=True)
        assert all(isinstance(r, ConnectionLostError) and "driver bug" in str(r) for r in results)
        assert arm.closed and not transport.connection_open()
        await server

    with caplog.at_level(logging.ERROR, logger="manip.reference_client"):
        run(main())
    assert "background process failed" in caplog.text


def test_cancelling_the_background_task_fails_waiting_requests() -> None:
    async def main() -> None:
        async with session(manual) as (arm, fake):
            waiting = asyncio.create_task(arm.here(timeout=None))
            await take(fake.peer, 1)
            background = [t for t in asyncio.all_tasks() if t.get_name().startswith("manip background")]
            assert len(background) == 1
            background[0].cancel()
            with pytest.raises(ConnectionLostError, match="cancelled"):
                await waiting

    run(main())
