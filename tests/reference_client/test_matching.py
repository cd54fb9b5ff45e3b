"""The sans-I/O matching core: packets in, events out, no I/O and no asyncio."""

from __future__ import annotations

import struct
from typing import Any

import pytest

from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_error, encode_reply, encode_terminator, segment_completed
from manip.reference_client import (
    CHAOS_MANIPULATOR,
    GENERIC,
    NOTIFY_TRIVIAL_ERRORS,
    ConnectionLostError,
    FatalError,
    MatchingCore,
    NonFatalError,
    OutOfSequenceReason,
    Phase,
    Request,
    RequestState,
    ResponseContext,
    ResponseDataError,
    ResponseType,
    ServerPacket,
    TrivialErrors,
    chaos_response_info,
    default_registry,
)
from manip.reference_client.events import (
    AsyncErrorReceived,
    AsyncResponseReceived,
    ConnectionEnded,
    Event,
    FatalErrorReceived,
    InitialResponse,
    OutOfSequence,
    PacketKept,
    RequestAnswered,
    RequestFailed,
    TrivialErrorNotified,
    WarningReceived,
)
from manip.reference_client.extractors import extract_done, extract_segment, extract_text
from manip.spec.constants import ServerOp

REGISTRY = default_registry()


def make_core(**options: Any) -> MatchingCore:
    core = MatchingCore(REGISTRY, (CHAOS_MANIPULATOR, GENERIC), **options)
    events = feed(core, ServerOp.RESPONSE, encode_terminator(1))
    assert events == [InitialResponse(1)]
    return core


def feed(core: MatchingCore, opcode: int, data: bytes) -> list[Event]:
    packet = ServerPacket(opcode, data)
    try:
        info = chaos_response_info(packet)
    except ValueError as exc:
        return core.malformed(packet, exc)
    return core.receive(packet, info)


def send(core: MatchingCore, name: str, number: int, **kw: Any) -> Request[Any]:
    code = REGISTRY.request_code(name)
    extractor = kw.pop("extractor", REGISTRY.resolve_extractor(code.default_extractor))
    request: Request[Any] = Request(code, b"", kw.pop("response_type", code.response_type), extractor, **kw)
    request.packet_number = number
    assert core.sent(request) == [] or request.response_type is ResponseType.NONE
    return request


def err(code: str = "NAP", severity: str = "E", message: str = "No arm power") -> ErrorMessage:
    return ErrorMessage("motion", severity, code, message)


def one(events: list[Event]) -> Event:
    assert len(events) == 1, events
    return events[0]


def reason(event: Event) -> OutOfSequenceReason:
    assert isinstance(event, OutOfSequence), event
    return event.error.reason


# ----------------------------------------------------------------------------------- connecting


def test_initial_response_with_any_number_is_accepted_and_not_matched() -> None:
    core = MatchingCore(REGISTRY, (GENERIC,))
    assert core.phase is Phase.AWAITING_INITIAL and not core.ready
    events = feed(core, ServerOp.RESPONSE, encode_terminator(0o177777))
    assert events == [InitialResponse(0o177777)] and core.ready


def test_initial_response_is_not_taken_as_a_reply_even_when_a_request_has_that_number() -> None:
    core = MatchingCore(REGISTRY, (GENERIC,))
    request = send(core, "calibrate", 2)
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2))) == InitialResponse(2)
    assert request.state is RequestState.SENT
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2))) == RequestAnswered(request, None)


def test_fatal_error_instead_of_the_initial_response() -> None:
    core = MatchingCore(REGISTRY, (GENERIC,))
    events = feed(core, ServerOp.FATAL_ERROR, encode_error(ServerOp.FATAL_ERROR, 1, err("BUG", "F", "busy")))
    assert isinstance(one(events), FatalErrorReceived)
    assert core.phase is Phase.FAILED


def test_without_initial_response_the_core_starts_open() -> None:
    assert MatchingCore(REGISTRY, (GENERIC,), expect_initial_response=False).ready


# ----------------------------------------------------------------------------------- matching


def test_responses_out_of_order_are_matched_by_request_number() -> None:
    core = make_core()
    here = send(core, "read-forces", 2)
    move = send(core, "move", 3)
    calib = send(core, "calibrate", 4)
    e1 = one(feed(core, ServerOp.RESPONSE, encode_reply("move", 3, segment=7)))
    e2 = one(feed(core, ServerOp.RESPONSE, encode_terminator(4)))
    e3 = one(feed(core, ServerOp.RESPONSE, encode_reply("read-forces", 2, forces=(1.0,) * 6)))
    assert e1 == RequestAnswered(move, 7)
    assert e2 == RequestAnswered(calib, None)
    assert e3 == RequestAnswered(here, (1.0,) * 6)
    assert not core.pending


def test_the_chaos_ack_field_is_not_used_for_matching() -> None:
    core = make_core()
    request = send(core, "calibrate", 5)
    packet = ServerPacket(ServerOp.RESPONSE, encode_terminator(5), packet_number=9, ack_number=4)
    assert one(core.receive(packet, chaos_response_info(packet))) == RequestAnswered(request, None)


def test_duplicate_response_is_reported_not_raised() -> None:
    core = make_core()
    request = send(core, "calibrate", 2)
    feed(core, ServerOp.RESPONSE, encode_terminator(2))
    assert request.state is RequestState.ANSWERED
    event = one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))
    assert reason(event) is OutOfSequenceReason.DUPLICATE
    assert isinstance(event, OutOfSequence) and event.error.request_number == 2


def test_a_second_reply_after_an_error_reply_is_a_duplicate() -> None:
    core = make_core()
    send(core, "calibrate", 2)
    feed(core, ServerOp.NON_FATAL_ERROR, encode_error(ServerOp.NON_FATAL_ERROR, 2, err()))
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))) is OutOfSequenceReason.DUPLICATE


def test_response_to_no_request_is_unmatched() -> None:
    core = make_core()
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(42)))) is OutOfSequenceReason.UNMATCHED
    event = one(feed(core, ServerOp.NON_FATAL_ERROR, encode_error(ServerOp.NON_FATAL_ERROR, 43, err())))
    assert reason(event) is OutOfSequenceReason.UNMATCHED


def test_unknown_response_opcode_is_reported() -> None:
    core = make_core()
    request = send(core, "calibrate", 2)
    event = one(feed(core, 0o206, encode_terminator(2)))
    assert reason(event) is OutOfSequenceReason.UNKNOWN_OPCODE
    assert request.state is RequestState.SENT  # untouched


def test_packet_without_a_request_number_is_malformed() -> None:
    core = make_core()
    assert reason(one(feed(core, ServerOp.RESPONSE, b"\x01"))) is OutOfSequenceReason.MALFORMED


def test_malformed_asynchronous_response_is_reported() -> None:
    core = make_core()
    assert reason(one(feed(core, ServerOp.ASYNCHRONOUS_RESPONSE, b"\x01\x00\x02\x00"))) is (
        OutOfSequenceReason.MALFORMED
    )


def test_reply_after_abandon_is_late() -> None:
    core = make_core()
    request = send(core, "calibrate", 2)
    failed = one(core.abandon(request, ConnectionLostError("test")))
    assert isinstance(failed, RequestFailed) and request.state is RequestState.FAILED
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))) is OutOfSequenceReason.LATE
    assert core.abandon(request, ConnectionLostError("again")) == []


def test_response_type_none_is_answered_when_sent_and_a_reply_is_unexpected() -> None:
    core = make_core()
    code = REGISTRY.request_code("calibrate")
    request: Request[Any] = Request(code, b"", ResponseType.NONE, None, packet_number=2)
    assert core.sent(request) == [RequestAnswered(request, None)]
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))) is OutOfSequenceReason.UNEXPECTED


def test_history_is_bounded() -> None:
    core = make_core(history=2)
    for n in (2, 3, 4):
        send(core, "calibrate", n)
        feed(core, ServerOp.RESPONSE, encode_terminator(n))
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))) is OutOfSequenceReason.UNMATCHED
    assert reason(one(feed(core, ServerOp.RESPONSE, encode_terminator(4)))) is OutOfSequenceReason.DUPLICATE


def test_sent_refuses_bad_requests() -> None:
    core = make_core()
    code = REGISTRY.request_code("calibrate")
    with pytest.raises(ValueError, match="packet number"):
        core.sent(Request(code))
    send(core, "calibrate", 7)
    with pytest.raises(ValueError, match="already pending"):
        core.sent(Request(code, packet_number=7))


# ----------------------------------------------------------------------------------- data


def test_bad_reply_data_fail_the_request_with_the_cause_chained() -> None:
    core = make_core()
    request = send(core, "move", 2)
    event = one(feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"\x01\x00\x02\x00"))
    assert isinstance(event, RequestFailed) and isinstance(event.error, ResponseDataError)
    assert event.error.__cause__ is not None and "segment" in str(event.error)
    assert request.error is event.error


def test_done_with_data_is_a_bad_reply() -> None:
    core = make_core()
    send(core, "calibrate", 2, extractor=extract_done)
    assert isinstance(one(feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"xx")), RequestFailed)


def test_no_extractor_means_the_data_do_not_matter() -> None:
    core = make_core()
    request = send(core, "here", 2, extractor=None)
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"anything")) == RequestAnswered(
        request, None
    )


# ----------------------------------------------------------------------------------- multi-packet


def test_multi_packet_response_is_collected_up_to_the_empty_packet() -> None:
    core = make_core()
    request = send(core, "describe-self", 2, extractor=extract_text)
    assert feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"((:a . 1)") == []
    assert feed(core, ServerOp.RESPONSE, encode_terminator(2) + b" (:b . 2))") == []
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2))) == RequestAnswered(
        request, "((:a . 1) (:b . 2))"
    )


def test_asynchronous_response_in_the_middle_of_a_multi_packet_response() -> None:
    core = make_core()
    request = send(core, "describe-self", 2, extractor=extract_text)
    feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"((:a . 1)")
    event = one(feed(core, ServerOp.ASYNCHRONOUS_RESPONSE, segment_completed(1, 5)))
    assert isinstance(event, AsyncResponseReceived) and event.response.word3 == 5
    warning = one(feed(core, ServerOp.ASYNCHRONOUS_WARNING, encode_error(0o205, 2, err("BUG", "W", "hot"))))
    assert isinstance(warning, WarningReceived)
    feed(core, ServerOp.RESPONSE, encode_terminator(2) + b")")
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2))) == RequestAnswered(request, "((:a . 1))")


def test_other_replies_interleaved_with_a_multi_packet_response() -> None:
    core = make_core()
    describe = send(core, "describe-self", 2, extractor=extract_text)
    move = send(core, "move", 3, extractor=extract_segment)
    feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"ab")
    assert one(feed(core, ServerOp.RESPONSE, encode_reply("move", 3, segment=1))) == RequestAnswered(move, 1)
    feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"cd")
    assert one(feed(core, ServerOp.RESPONSE, encode_terminator(2))) == RequestAnswered(describe, "abcd")


def test_non_fatal_error_in_the_middle_of_a_multi_packet_response_fails_it() -> None:
    core = make_core()
    request = send(core, "describe-self", 2)
    feed(core, ServerOp.RESPONSE, encode_terminator(2) + b"((:a")
    event = one(feed(core, ServerOp.NON_FATAL_ERROR, encode_error(0o202, 2, err("BUG", "BE", "oops"))))
    assert isinstance(event, RequestFailed) and isinstance(event.error, NonFatalError)
    assert event.error.is_bug and event.error.request is request


# ----------------------------------------------------------------------------------- errors


def test_non_fatal_error_keeps_its_parts() -> None:
    core = make_core()
    request = send(core, "calibrate", 2)
    message = ErrorMessage("calib", "E", "NZI", "No zero index found on joint(s) $.", (6,))
    event = one(feed(core, ServerOp.NON_FATAL_ERROR, encode_error(0o202, 2, message)))
    assert isinstance(event, RequestFailed)
    error = event.error
    assert isinstance(error, NonFatalError)
    assert (error.where, error.severity, error.code, error.arguments) == ("calib", "E", "NZI", (6,))
    assert error.message == "No zero index found on joint(s) 2 and 3."
    assert error.template == "No zero index found on joint(s) $."
    assert error.rendered == "calib: E NZI No zero index found on joint(s) 2 and 3."
    assert error.request is request and error.request_number == 2
    assert "calibrate (0203, packet 2)" in str(error)
    assert error.meaning == "No zero index found on joint(s)"


def test_unreadable_error_string_still_fails_the_request() -> None:
    core = make_core()
    send(core, "calibrate", 2)
    event = one(feed(core, ServerOp.NON_FATAL_ERROR, encode_terminator(2) + b"no separator"))
    assert isinstance(event, RequestFailed) and isinstance(event.error, NonFatalError)
    assert "no separator" in event.error.message


def test_fatal_error_fails_every_pending_request_at_once() -> None:
    core = make_core()
    requests = [send(core, "calibrate", n) for n in (2, 3, 4)]
    events = feed(core, ServerOp.FATAL_ERROR, encode_error(0o201, 3, err("PAN", "F", "Panic button")))
    assert isinstance(events[0], FatalErrorReceived) and events[0].error.request is requests[1]
    failed = [e for e in events if isinstance(e, RequestFailed)]
    assert [e.request for e in failed] == requests
    assert all(isinstance(e.error, FatalError) and e.error.request is e.request for e in failed)
    assert all(r.state is RequestState.FAILED for r in requests)
    assert core.phase is Phase.FAILED and not core.pending
    code = REGISTRY.request_code("calibrate")
    with pytest.raises(ConnectionLostError):
        core.sent(Request(code, packet_number=9))


def test_asynchronous_error_is_its_own_event() -> None:
    core = make_core()
    request = send(core, "calibrate", 2)
    event = one(feed(core, ServerOp.ASYNCHRONOUS_ERROR, encode_error(0o204, 2, err("AWA", "E", "aborted"))))
    assert isinstance(event, AsyncErrorReceived) and event.error.code == "AWA"
    assert request.state is RequestState.SENT


def test_connection_lost_fails_pending_requests() -> None:
    core = make_core()
    request = send(core, "here", 2)
    events = core.connection_lost("peer went away")
    assert isinstance(events[0], RequestFailed) and isinstance(events[0].error, ConnectionLostError)
    assert events[-1] == ConnectionEnded("peer went away")
    assert request.state is RequestState.FAILED and core.phase is Phase.CLOSED


# ----------------------------------------------------------------------------------- handler types


def test_handler_type_order_first_handler_wins_and_may_pass_on() -> None:
    registry = REGISTRY.copy()
    registry.define_response_handler_type("spy")
    registry.define_response_handler_type("greedy")
    seen: list[str] = []

    @registry.response_handler("normal-response", "spy")
    def spy(ctx: ResponseContext) -> None:
        seen.append(f"spy {ctx.request_number} at {ctx.handler_type}")
        ctx.pass_on()

    @registry.response_handler("normal-response", "greedy")
    def greedy(ctx: ResponseContext) -> None:
        seen.append("greedy")
        ctx.keep_packet()

    core = MatchingCore(registry, ("spy", "generic"), expect_initial_response=False)
    request = send(core, "calibrate", 2)
    events = feed(core, ServerOp.RESPONSE, encode_terminator(2))
    assert seen == ["spy 2 at spy"] and events == [RequestAnswered(request, None)]

    core.handler_types = ("greedy", "spy", "generic")
    events = feed(core, ServerOp.RESPONSE, encode_terminator(3))
    assert seen[-1] == "greedy" and isinstance(one(events), PacketKept)

    core.handler_types = ("generic", "spy")  # generic comes first: spy is never asked
    send(core, "calibrate", 4)
    feed(core, ServerOp.RESPONSE, encode_terminator(4))
    assert seen == ["spy 2 at spy", "greedy"]


def test_passing_on_with_no_later_handler_is_reported() -> None:
    registry = REGISTRY.copy()
    registry.define_response_handler_type("shy")
    registry.define_response_handler("normal-response", "shy", lambda ctx: ctx.pass_on() and None)
    core = MatchingCore(registry, ("shy",), expect_initial_response=False)
    event = one(feed(core, ServerOp.RESPONSE, encode_terminator(2)))
    assert reason(event) is OutOfSequenceReason.UNKNOWN_OPCODE and "passed" in str(event.error)


def test_new_response_code_with_its_own_handler_type() -> None:
    registry = REGISTRY.copy()
    registry.define_response_code("finger-data", 0o70)
    registry.define_response_handler_type("fingers")
    got: list[bytes] = []
    registry.define_response_handler("finger-data", "fingers", lambda ctx: got.append(ctx.payload))
    core = MatchingCore(registry, ("fingers", "generic"), expect_initial_response=False)
    assert feed(core, 0o270, struct.pack("<HH", 1, 0o1234)) == []
    assert got == [struct.pack("<H", 0o1234)]
    core.handler_types = ("generic",)
    assert reason(one(feed(core, 0o270, struct.pack("<H", 1)))) is OutOfSequenceReason.UNKNOWN_OPCODE


def test_undefined_handler_type_is_refused() -> None:
    with pytest.raises(ValueError, match="undefined response handler type"):
        MatchingCore(REGISTRY, ("nonesuch",))


# ----------------------------------------------------------------------------------- trivial errors


def trivial_core() -> MatchingCore:
    return MatchingCore(
        REGISTRY,
        (NOTIFY_TRIVIAL_ERRORS, CHAOS_MANIPULATOR, GENERIC),
        expect_initial_response=False,
        trivial_errors=TrivialErrors(codes=frozenset({"UIM"})),
    )


def test_trivial_error_of_a_done_request_is_notified_and_the_request_answered() -> None:
    core = trivial_core()
    request = send(core, "set-configuration", 2, extractor=extract_done, value_optional=True)
    events = feed(core, 0o202, encode_error(0o202, 2, err("UIM", "E", "not on this arm")))
    assert events[0] == RequestAnswered(request, None)
    assert isinstance(events[1], TrivialErrorNotified) and events[1].error.code == "UIM"


def test_non_trivial_error_and_data_requests_still_fail() -> None:
    core = trivial_core()
    done = send(core, "calibrate", 2, extractor=extract_done, value_optional=True)
    here = send(core, "here", 3)
    e1 = one(feed(core, 0o202, encode_error(0o202, 2, err("NAP"))))
    e2 = one(feed(core, 0o202, encode_error(0o202, 3, err("UIM"))))
    assert isinstance(e1, RequestFailed) and e1.request is done
    assert isinstance(e2, RequestFailed) and e2.request is here


def test_a_handler_that_raises_is_reported_not_propagated() -> None:
    registry = REGISTRY.copy()
    registry.define_response_handler_type("buggy")

    def buggy(ctx: ResponseContext) -> None:
        raise ZeroDivisionError("oops")

    registry.define_response_handler("asynchronous-warning", "buggy", buggy)
    core = MatchingCore(registry, ("buggy", "generic"), expect_initial_response=False)
    event = one(feed(core, ServerOp.ASYNCHRONOUS_WARNING, encode_error(0o205, 1, err("CTO", "W", "slow"))))
    assert reason(event) is OutOfSequenceReason.HANDLER_FAILED
    assert isinstance(event, OutOfSequence) and isinstance(event.error.__cause__, ZeroDivisionError)
