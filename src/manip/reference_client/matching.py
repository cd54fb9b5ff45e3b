"""The sans-I/O matching core: sent requests and received packets in, events out.

Theory of operation
-------------------
The core keeps the requests that were sent and not yet answered in ``pending``, keyed by the packet
number each went out with.  Every packet from the server carries a request number in its first data
word (erratum ``echo-vs-ack``: never the Chaos ack field); the transport's ``get_response_info`` has
already found it, and the response code, when a packet reaches :meth:`MatchingCore.receive`.

Phases::

    AWAITING_INITIAL --first RESPONSE (any number)--> OPEN --fatal error--> FAILED
           |                                           |                     |
           +------------- connection lost -------------+---------------------+--> CLOSED

* ``AWAITING_INITIAL``: the server owes the RESPONSE it sends when the connection opens (clause
  ``connect.initial-response``).  The first 0200 packet is that response whatever number it carries
  (erratum ``initial-response``) and is never matched to a request.  Other packets are handled as
  usual (a fatal error here is a refusal).  With ``expect_initial_response=False`` the core starts OPEN.
* ``OPEN``: packets are dispatched to response handlers (below).
* ``FAILED``: a fatal error (0201) failed every pending request at once; no more requests may be sent.
* ``CLOSED``: :meth:`MatchingCore.connection_lost` failed every pending request with ConnectionLostError.

Dispatch: the response code selects a handler through the registry and the handler-type list
(:mod:`~manip.reference_client.registry`).  The built-in handlers (:mod:`~manip.reference_client.handlers`)
do the protocol's work with the primitives of :class:`ResponseContext`:

* normal response (0): find the pending request with the packet's number; a single-response request
  is answered with its extractor's value; a multi-response request collects non-empty packets and is
  answered when the empty one arrives.  No such request: an out-of-sequence event whose reason comes
  from a bounded history of finished numbers: duplicate (already answered), late (given up after a
  timeout or cancellation), unexpected (sent with response type none) or unmatched;
* non-fatal error (2): fails the matching request (even half-way through a multi-packet response);
* asynchronous response (3), asynchronous error (4), warning (5): their own events, matched to nothing;
  so an asynchronous packet in the middle of a multi-packet response does not disturb it;
* fatal error (1): fails every pending request at once, then the phase is FAILED.

A response code without a handler, a packet without a request number, a malformed asynchronous
response and a handler that raises are out-of-sequence events too.  Nothing that arrives raises:
every outcome is an event.
"""

from __future__ import annotations

import contextlib
import enum
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Final

from manip.codecs.error_string import ErrorMessage, parse_error
from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.reference_client.errors import (
    ConnectionLostError,
    ManipError,
    NonFatalError,
    OutOfSequenceReason,
    OutOfSequenceResponse,
    ResponseDataError,
)
from manip.reference_client.events import (
    ConnectionEnded,
    Event,
    InitialResponse,
    OutOfSequence,
    PacketKept,
    RequestAnswered,
    RequestFailed,
)
from manip.reference_client.faults import NO_FAULTS, ClientFault, ClientFaults
from manip.reference_client.packets import ResponseInfo, ServerPacket
from manip.reference_client.registry import Registry
from manip.reference_client.request import Request, RequestState, ResponseType

NORMAL_RESPONSE: Final = 0
DEFAULT_HISTORY: Final = 256


class Phase(enum.Enum):
    AWAITING_INITIAL = "awaiting-initial-response"
    OPEN = "open"
    FAILED = "failed"
    CLOSED = "closed"


class _Finished(enum.Enum):
    ANSWERED = OutOfSequenceReason.DUPLICATE
    ABANDONED = OutOfSequenceReason.LATE
    NO_REPLY = OutOfSequenceReason.UNEXPECTED


class MatchingCore:
    """Matches responses to requests; see the module docstring for the theory of operation."""

    def __init__(
        self,
        registry: Registry,
        handler_types: Sequence[str],
        *,
        expect_initial_response: bool = True,
        trivial_errors: Callable[[NonFatalError], bool] | None = None,
        history: int = DEFAULT_HISTORY,
        align_args: bool = True,
        max_reply_bytes: int | None = None,
        faults: ClientFaults = NO_FAULTS,
    ) -> None:
        self.registry = registry
        self.max_reply_bytes = max_reply_bytes
        """The most data one reply may bring (None: no limit); see ``ClientOptions.max_reply_bytes``."""
        self._handler_types = registry.check_handler_types(handler_types)
        self.trivial_errors = trivial_errors
        """The policy the ``notify-trivial-errors`` handler consults (None: nothing is trivial)."""
        self.align_args = align_args
        self.faults = faults
        """The client's fault switches (the handlers read them too)."""
        expect_initial_response = expect_initial_response and ClientFault.NO_INITIAL_WAIT not in faults
        self.phase = Phase.AWAITING_INITIAL if expect_initial_response else Phase.OPEN
        self._pending: dict[int, Request[Any]] = {}
        self._finished: OrderedDict[int, _Finished] = OrderedDict()
        self._history = history

    # ------------------------------------------------------------------ state

    @property
    def ready(self) -> bool:
        """Requests may be sent: the initial response came and no fatal error or close happened."""
        return self.phase is Phase.OPEN

    @property
    def pending(self) -> Mapping[int, Request[Any]]:
        return self._pending

    @property
    def handler_types(self) -> tuple[str, ...]:
        return self._handler_types

    @handler_types.setter
    def handler_types(self, types: Sequence[str]) -> None:
        self._handler_types = self.registry.check_handler_types(types)

    # ------------------------------------------------------------------ inputs

    def sent(self, request: Request[Any]) -> list[Event]:
        """``request`` went out with ``request.packet_number``; a response-type-none request is
        answered at once."""
        if self.phase in (Phase.FAILED, Phase.CLOSED):
            raise ConnectionLostError(
                f"cannot send {request.describe()}: the connection is {self.phase.value}"
            )
        number = request.packet_number
        if number is None:
            raise ValueError(f"{request.describe()}: the transport did not set the packet number")
        if request.state is not RequestState.QUEUED:
            raise ValueError(f"{request.describe()} is {request.state.value}, not queued")
        if number in self._pending:
            raise ValueError(f"packet number {number} is already pending for {self._pending[number]!r}")
        request.state = RequestState.SENT
        self._finished.pop(number, None)
        if request.response_type is ResponseType.NONE:
            self._remember(number, _Finished.NO_REPLY)
            return [self.answer(request, None)]
        self._pending[number] = request
        return []

    def receive(self, packet: ServerPacket, info: ResponseInfo) -> list[Event]:
        """Handle one packet from the server."""
        events: list[Event] = []
        if self.phase is Phase.AWAITING_INITIAL and info.code == NORMAL_RESPONSE:
            self.phase = Phase.OPEN
            events.append(InitialResponse(info.request_number))
            return events
        context = ResponseContext(self, packet, info, events)
        try:
            handled = context.dispatch_from(0)
        except Exception as exc:
            oos = OutOfSequenceResponse(
                OutOfSequenceReason.HANDLER_FAILED,
                packet,
                request_number=info.request_number,
                detail=f"{type(exc).__name__}: {exc}",
            )
            oos.__cause__ = exc
            events.append(OutOfSequence(oos))
            return events
        if not handled:
            context.out_of_sequence(
                OutOfSequenceReason.UNKNOWN_OPCODE,
                f"no handler for response code {info.code} among handler types {list(self._handler_types)}",
            )
        return events

    def malformed(self, packet: ServerPacket, error: Exception) -> list[Event]:
        """A packet whose response info could not be read (for example no request-number word)."""
        oos = OutOfSequenceResponse(OutOfSequenceReason.MALFORMED, packet, detail=str(error))
        oos.__cause__ = error
        return [OutOfSequence(oos)]

    def abandon(self, request: Request[Any], error: ManipError) -> list[Event]:
        """Give up ``request`` (timeout, cancellation); a reply that comes later is reported as late."""
        if request.done:
            return []
        number = request.packet_number
        if number is not None and self._pending.get(number) is request:
            del self._pending[number]
            self._remember(number, _Finished.ABANDONED)
        return [self._failed(request, error)]

    def connection_lost(self, reason: str, cause: BaseException | None = None) -> list[Event]:
        """The connection is gone: every pending request fails with ConnectionLostError (``cause``
        chained)."""
        events: list[Event] = []
        for request in self._take_all():
            error = ConnectionLostError(reason)
            error.__cause__ = cause
            events.append(self._failed(request, error))
        self.phase = Phase.CLOSED
        events.append(ConnectionEnded(reason, cause))
        return events

    # ------------------------------------------------------------------ primitives for handlers

    def find_matching_request(self, number: int) -> Request[Any] | None:
        if ClientFault.WRONG_REQUEST_NUMBER in self.faults:
            number = (number + 1) & 0xFFFF
        if ClientFault.ARRIVAL_ORDER in self.faults and self._pending:
            return next(iter(self._pending.values()))  # the oldest waiting, whatever the number
        return self._pending.get(number)

    def why_unmatched(self, number: int) -> OutOfSequenceReason:
        finished = self._finished.get(number)
        return OutOfSequenceReason.UNMATCHED if finished is None else finished.value

    def answer(self, request: Request[Any], value: Any) -> RequestAnswered:
        self._finish(request, _Finished.ANSWERED)
        request.state = RequestState.ANSWERED
        request.result = value
        return RequestAnswered(request, value)

    def fail(self, request: Request[Any], error: ManipError) -> RequestFailed:
        """Fail a request that was answered with an error: a second reply to it is a duplicate."""
        self._finish(request, _Finished.ANSWERED)
        return self._failed(request, error)

    def extract(self, request: Request[Any]) -> Event:
        """Run the request's extractor over the payloads collected; answer or fail the request."""
        if request.extractor is None:
            return self.answer(request, None)
        try:
            payloads = tuple(request.responses)
            if request.code.spec is not None:  # the float faults read the data by the layout
                layout = request.code.spec.response.data
                payloads = tuple(self.faults.read_floats(layout, p) for p in payloads)
            value = request.extractor(request, payloads)
        except Exception as exc:
            error = ResponseDataError(request, str(exc) or type(exc).__name__)
            error.__cause__ = exc
            return self.fail(request, error)
        return self.answer(request, value)

    def fail_all(self, make_error: Callable[[Request[Any]], ManipError]) -> list[Event]:
        """Fail every pending request at once (a fatal error); no request may be sent afterwards."""
        events: list[Event] = []
        for request in self._take_all():
            events.append(self._failed(request, make_error(request)))
        self.phase = Phase.FAILED
        return events

    # ------------------------------------------------------------------ bookkeeping

    def _failed(self, request: Request[Any], error: ManipError) -> RequestFailed:
        request.state = RequestState.FAILED
        request.error = error
        return RequestFailed(request, error)

    def _finish(self, request: Request[Any], how: _Finished) -> None:
        number = request.packet_number
        if number is not None and self._pending.get(number) is request:
            del self._pending[number]
            self._remember(number, how)

    def _take_all(self) -> list[Request[Any]]:
        requests = list(self._pending.values())
        for number in self._pending:
            self._remember(number, _Finished.ABANDONED)
        self._pending.clear()
        return requests

    def _remember(self, number: int, how: _Finished) -> None:
        self._finished[number] = how
        self._finished.move_to_end(number)
        while len(self._finished) > self._history:
            self._finished.popitem(last=False)


class ResponseContext:
    """What a response handler gets: the packet, its info, and the core's primitives.

    A handler reports outcomes with :meth:`emit` (or the helpers that emit), may hand the packet to
    the next handler type with :meth:`pass_on`, and may keep the packet from being returned to the
    transport with :meth:`keep_packet` (the 1985 guide's ``dont-return-pkt!``).
    """

    def __init__(
        self,
        core: MatchingCore,
        packet: ServerPacket,
        info: ResponseInfo,
        events: list[Event],
        position: int = -1,
    ) -> None:
        self.core = core
        self.packet = packet
        self.info = info
        self.events = events
        self.position = position
        """Index in the handler-type list of the handler running now."""

    @property
    def payload(self) -> bytes:
        """The response data after the request number."""
        return self.info.payload(self.packet)

    @property
    def request_number(self) -> int:
        return self.info.request_number

    @property
    def handler_type(self) -> str | None:
        types = self.core.handler_types
        return types[self.position] if 0 <= self.position < len(types) else None

    def emit(self, event: Event) -> None:
        self.events.append(event)

    def find_matching_request(self) -> Request[Any] | None:
        """The pending request this packet's number names, if any."""
        return self.core.find_matching_request(self.request_number)

    def answer(self, request: Request[Any], value: Any) -> None:
        self.emit(self.core.answer(request, value))

    def fail(self, request: Request[Any], error: ManipError) -> None:
        self.emit(self.core.fail(request, error))

    def extract(self, request: Request[Any]) -> None:
        self.emit(self.core.extract(request))

    def fail_all(self, make_error: Callable[[Request[Any]], ManipError]) -> None:
        self.events.extend(self.core.fail_all(make_error))

    def out_of_sequence(self, reason: OutOfSequenceReason | None = None, detail: str = "") -> None:
        """Report this packet as answering nothing; the reason defaults to what the history says."""
        if ClientFault.STRAY_UNSIGNALLED in self.core.faults:
            return
        if reason is None:
            reason = self.core.why_unmatched(self.request_number)
        self.emit(
            OutOfSequence(
                OutOfSequenceResponse(reason, self.packet, request_number=self.request_number, detail=detail)
            )
        )

    def error_message(self) -> ErrorMessage:
        """The payload read as an E.2 error string; a string that does not parse is kept as text."""
        payload = self.payload
        if ClientFault.IGNORE_PAD in self.core.faults and 0 in payload:
            # the numbers read from right after the NUL, pad byte and all; an odd last byte dropped
            rest = len(payload) - payload.index(0) - 1
            with contextlib.suppress(CodecError):
                return parse_error(payload[: len(payload) - rest % 2], align_args=False, body="string")
        # either layout, told apart by parity (erratum error-arg-layout); then each layout alone, for a
        # server that did not pad the numbers to a word (clause client.error-args-layout); the fault
        # always-pad reads the aligned layout only
        aligned = self.core.align_args
        layouts = (True,) if ClientFault.ALWAYS_PAD in self.core.faults else (None, aligned, not aligned)
        problem = ""
        for align in layouts:
            try:
                return parse_error(payload, align_args=align, body="string")
            except CodecError as exc:
                problem = str(exc)
        nul = payload.find(0)
        text = decode_lispm(payload if nul < 0 else payload[:nul])
        return ErrorMessage("client", "?", "???", f"unreadable error string {text!r} ({problem})")

    def keep_packet(self) -> None:
        if not any(isinstance(e, PacketKept) and e.packet is self.packet for e in self.events):
            self.emit(PacketKept(self.packet))

    def pass_on(self) -> bool:
        """Let the next handler type that handles this response code have it
        (``continue-manipulator-response-handler``).  False, and an out-of-sequence event, if none does."""
        if self.dispatch_from(self.position + 1):
            return True
        self.out_of_sequence(
            OutOfSequenceReason.UNKNOWN_OPCODE,
            f"handler type {self.handler_type!r} passed response code {self.info.code} on;"
            " no later type takes it",
        )
        return False

    def dispatch_from(self, start: int) -> bool:
        """Run the first handler at or after ``start`` in the handler-type list; False if there is none."""
        found = self.core.registry.find_handler(self.info.code, self.core.handler_types, start)
        if found is None:
            return False
        index, handler = found
        handler(ResponseContext(self.core, self.packet, self.info, self.events, index))
        return True
