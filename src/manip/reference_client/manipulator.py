"""The manipulator object: requests, operations, asynchronous responses and segments.

:class:`Manipulator` is what :func:`~manip.reference_client.connect.aconnect` returns.  It has the
1985 guide's three request entry points (``make_request``, ``send_request``, ``request``), every
operation of E.1 (:mod:`~manip.reference_client.generic`) and of manip's Puma extensions
(:mod:`~manip.reference_client.puma`), and the asynchronous side of E.3.

Free joint (0213, erratum ``free-joint-replies``): after the server frees a joint it discards the next
packet, whatever it is, and answers it with done.  The manipulator therefore refuses every request with
:class:`~manip.reference_client.errors.JointFreedError` between :meth:`Manipulator.free_joint` and
:meth:`Manipulator.release_joint`, which sends that throw-away packet (a Here request, harmless if a
server were to execute it).  ``async with arm.joint_freed(3): ...`` does both.

Segments: :meth:`Manipulator.wait_for_segment` waits for the segment-completed asynchronous response
(E.3 code 2) of a segment number a motion request returned.  It asks for segment notifications first
if they are not on (request-notifications, 0257).  That opcode is one of manip's Puma extensions: a
server written from the 1985 guide alone refuses it (or describe self does not list it), and then the
wait falls back to the guide's own requests: it polls Joint angles (0202) in the client's own time,
every :data:`POLL_INTERVAL` seconds, until the arm has stood still for :data:`STILL_POLLS` readings
(at the goal of the segment, when it was a set joint angles whose goal the client knows), bounded by
the timeout (:data:`POLL_TIMEOUT` without one).  The arm standing still means every segment queued so
far has ended.  Readings are PDP-11 floats: an arm starting a move at a very low speed factor may read
still for a moment, so a wait whose goal the client does not know (a transform, an increment) can end
early then; with notifications there is no such doubt.  Segments complete in order, so a completion of a
later segment also completes the ones before it (numbers compare modulo 2^16).  A segment that
completed while notifications were off was never reported: turn them on (``request_notifications``)
before the motion you will wait for.  An asynchronous error (motion aborted) fails every segment
waiter with that error, and a guard hit that stops the move fails them with
:class:`~manip.reference_client.errors.GuardTrippedError`.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Iterable, Mapping, Sequence
from contextlib import asynccontextmanager
from dataclasses import replace
from types import TracebackType
from typing import Any, Final, SupportsInt, TypeVar

from manip.codecs.messages import AsyncResponse, copy_request_data, encode_request
from manip.codecs.packet import MAX_DATA
from manip.ncp.seq import seq_gt, seq_le
from manip.reference_client.arguments import word
from manip.reference_client.background import AsyncListener, BackgroundProcess, CloseListener, ErrorListener
from manip.reference_client.errors import (
    AsynchronousError,
    ConnectionLostError,
    GuardTrippedError,
    JointFreedError,
    ManipError,
    NonFatalError,
    RequestTimeout,
)
from manip.reference_client.extractors import extract_done, extract_nothing
from manip.reference_client.faults import ClientFault
from manip.reference_client.generic import GenericOperations
from manip.reference_client.handlers import NOTIFY_TRIVIAL_ERRORS
from manip.reference_client.issuer import DEFAULT, Default, Timeout
from manip.reference_client.options import ClientOptions
from manip.reference_client.puma import PumaOperations
from manip.reference_client.request import DataExtractor, Request, RequestCode, ResponseType
from manip.reference_client.stream import AsyncResponseStream
from manip.spec import SPEC
from manip.spec.constants import AsyncCondition

T = TypeVar("T")

NOTIFY_GUARD_HITS: Final = 1 << SPEC.async_codes[AsyncCondition.GUARD_HIT].notification_bit
NOTIFY_SEGMENTS: Final = 1 << SPEC.async_codes[AsyncCondition.SEGMENT_COMPLETED].notification_bit
GUARD_STOPS: Final = 1
"""Word 2 of a guard-hit response when the trip stopped the trajectory."""
POLL_INTERVAL: Final = 0.05
"""Seconds between the Joint angles polls of a wait without segment notifications (3 servo cycles)."""
STILL_POLLS: Final = 3
"""Equal readings in a row that mean the arm stands still."""
POLL_TIMEOUT: Final = 120.0
"""The bound of a wait by polling when the caller gave no timeout."""
AT_GOAL_DEG: Final = 0.01
"""How close (degrees, each joint) a still arm must be to a known goal for its segment to count as ended."""
_NOTIFICATIONS_OPCODE: Final = SPEC.request("request-notifications").opcode
_SEGMENT_OPERATIONS: Final = frozenset(
    op.name for op in SPEC.requests.values() if op.response.form == "segment"
)

RequestData = bytes | bytearray | int | float | Iterable[Any]
"""Request data for ``copy-manipulator-request-data``: integers are words, floats PDP-11 floats,
sequences are flattened; bytes are sent as they are."""


_MOVES: Final = frozenset({"move", "straight-move"})
_SOLVES_SWAPPED: Final = {"solve-forwards": "solve-backwards", "solve-backwards": "solve-forwards"}
"""Each solve request and the one whose opcode it goes out under (fault solve-opcodes-swapped)."""
_ROW_MAJOR: Final = tuple(column * 3 + row for row in range(3) for column in range(4))
"""Where each float of a transform goes row after row (fault move-row-major): its column-major index."""


def _row_major(payload: bytes) -> bytes:
    """A transform's 12 floats (column major, N O A P) sent row after row (fault move-row-major)."""
    if len(payload) != 48:
        return payload
    return b"".join(payload[4 * i : 4 * i + 4] for i in _ROW_MAJOR)


def _extract_unfree(request: Request[Any], payloads: Sequence[bytes]) -> None:
    """The reply to the packet that un-frees a joint: done (or a Here reply from a lax server)."""
    return None


class Manipulator(GenericOperations, PumaOperations):
    """One connected manipulator.  Use it as ``async with await aconnect(...)`` or ``async with
    aconnect(...) as arm``; :meth:`aclose` ends it and fails whatever is still waiting."""

    def __init__(self, process: BackgroundProcess, options: ClientOptions) -> None:
        self._process = process
        self.options = options
        self.registry = options.registry
        self._freed_joint: int | None = None
        self._notifications = 0
        self._last_segment: int | None = None
        self._segment_waiters: list[tuple[int, asyncio.Future[None]]] = []
        self._polling = False
        """Segments are waited for by polling: the server does not serve segment notifications."""
        self._last_queued: int | None = None
        self._goals: dict[int, tuple[float, ...]] = {}
        """The joint goals of the set-joint-angles segments queued (the latest few)."""
        process.add_async_listener(self._on_async_response)
        process.add_error_listener(self._on_error)
        process.add_close_listener(self._on_close)

    # ------------------------------------------------------------------ state

    @property
    def process(self) -> BackgroundProcess:
        return self._process

    @property
    def closed(self) -> bool:
        return self._process.closed

    @property
    def notify_trivial_errors(self) -> bool:
        """Whether trivial errors are notified instead of raised (settable while connected)."""
        return NOTIFY_TRIVIAL_ERRORS in self._process.core.handler_types

    @notify_trivial_errors.setter
    def notify_trivial_errors(self, on: bool) -> None:
        self._process.core.handler_types = self.options.effective_handler_types(on)

    @property
    def freed_joint(self) -> int | None:
        """The joint freed by :meth:`free_joint` and not yet released."""
        return self._freed_joint

    @property
    def notifications(self) -> int:
        """The notification mask last set with :meth:`request_notifications`."""
        return self._notifications

    @property
    def last_completed_segment(self) -> int | None:
        return self._last_segment

    # ------------------------------------------------------------------ requests

    def make_request(
        self,
        code: str | int | RequestCode,
        data: RequestData | None = None,
        *,
        fields: Mapping[str, Any] | None = None,
        response_type: ResponseType | None = None,
        extractor: str | DataExtractor[Any] | Default | None = DEFAULT,
        timeout: Timeout = DEFAULT,
    ) -> Request[Any]:
        """Build a request (``:make-request``).  Its data come from ``data`` by the
        copy-manipulator-request-data rules, or from ``fields`` by the spec layout of the opcode (a
        spec opcode with neither gets its layout checked with no fields).  Encoding errors are raised
        here, in the caller's task."""
        rc = self.registry.request_code(code, self.options.manipulator_type)
        if data is not None and fields is not None:
            raise ValueError("give the request data or its fields, not both")
        if isinstance(data, bytes | bytearray):
            payload = bytes(data)
        elif data is not None:
            payload = copy_request_data(data)
        elif rc.spec is not None:
            payload = encode_request(rc.spec.opcode, **(fields or {}))
        elif fields:
            raise ValueError(f"{rc} has no spec layout for fields; pass data")
        else:
            payload = b""
        faults = self.options.faults
        if ClientFault.SET_SPEED_LENGTH in faults and rc.spec is not None and rc.spec.name == "set-speed":
            payload += bytes(4)
        if ClientFault.MOVE_ROW_MAJOR in faults and rc.spec is not None and rc.spec.name in _MOVES:
            payload = _row_major(payload)
        if ClientFault.SOLVE_OPCODES_SWAPPED in faults and rc.name in _SOLVES_SWAPPED:
            other = self.registry.request_code(_SOLVES_SWAPPED[rc.name], self.options.manipulator_type)
            rc = replace(rc, opcode=other.opcode)  # this request's data under the other's opcode
        if len(payload) > MAX_DATA:  # a Chaos packet cannot carry it: refused here, not by the link later
            raise ValueError(f"{rc}: {len(payload)} data bytes, more than a Chaos packet holds ({MAX_DATA})")
        if ClientFault.EARLY_TIMEOUT in faults and isinstance(timeout, int | float):
            timeout = timeout / 2
        chosen = rc.default_extractor if isinstance(extractor, Default) else extractor
        function = self.registry.resolve_extractor(chosen)
        return Request(
            rc,
            payload,
            response_type or rc.response_type,
            function,
            self.options.timeout if isinstance(timeout, Default) else timeout,
            value_optional=function is None or function in (extract_done, extract_nothing),
        )

    def send_request(self, request: Request[T]) -> asyncio.Future[T]:
        """Queue ``request`` (``:send-request``); await the future for its result."""
        if self._freed_joint is not None:
            raise JointFreedError(self._freed_joint)
        return self._process.submit(request)

    async def request(
        self,
        code: str | int | RequestCode,
        data: RequestData | None = None,
        *,
        fields: Mapping[str, Any] | None = None,
        response_type: ResponseType | None = None,
        extractor: str | DataExtractor[Any] | Default | None = DEFAULT,
        timeout: Timeout = DEFAULT,
    ) -> Any:
        """Make, send and wait for a request (``:request``); returns its extractor's value."""
        request = self.make_request(
            code, data, fields=fields, response_type=response_type, extractor=extractor, timeout=timeout
        )
        return await self.send_request(request)

    async def _call(
        self,
        code: str,
        extractor: DataExtractor[T],
        fields: Mapping[str, Any] | None = None,
        *,
        timeout: Timeout = DEFAULT,
    ) -> T:
        request = self.make_request(code, fields=fields, extractor=extractor, timeout=timeout)
        result: T = await self.send_request(request)
        self._took(code, fields, result)
        return result

    def _took(self, code: str, fields: Mapping[str, Any] | None, result: object) -> None:
        """What a wait by polling needs to know of a request that succeeded: the segments queued and
        their joint goals, and whether describe self lists segment notifications."""
        if code in _SEGMENT_OPERATIONS and isinstance(result, int):
            self._last_queued = result
            if code == "set-joint-angles" and fields is not None:
                self._goals[result] = tuple(float(q) for q in fields["joints"])
                while len(self._goals) > 64:
                    del self._goals[next(iter(self._goals))]
        elif code == "describe-self" and isinstance(result, Mapping):
            operations = result.get("operations")
            if isinstance(operations, list | tuple) and _NOTIFICATIONS_OPCODE not in operations:
                self._polling = True

    # ------------------------------------------------------------------ free joint

    async def free_joint(self, joint: int, *, timeout: Timeout = DEFAULT) -> None:
        """Free joint (0213), 1-based; afterwards only :meth:`release_joint` may be sent."""
        number = word(joint, "joint", 1, 0xFF)
        future = self.send_request(
            self.make_request("free-joint", fields={"joint": number}, extractor=extract_done, timeout=timeout)
        )
        self._freed_joint = number
        try:
            await future
        except NonFatalError:
            self._freed_joint = None  # the server refused: nothing was freed
            raise

    async def release_joint(self, *, timeout: Timeout = DEFAULT) -> None:
        """Send the packet that un-frees the joint (the server discards it and answers done)."""
        if self._freed_joint is None:
            return
        request = self.make_request("here", extractor=_extract_unfree, timeout=timeout)
        try:
            await self._process.submit(request)
        finally:
            self._freed_joint = None

    @asynccontextmanager
    async def joint_freed(self, joint: int) -> AsyncIterator[None]:
        """Free ``joint`` for the body of the ``async with``."""
        await self.free_joint(joint)
        try:
            yield
        finally:
            await self.release_joint()

    # ------------------------------------------------------------------ asynchronous responses

    async def request_notifications(self, mask: int, *, timeout: Timeout = DEFAULT) -> None:
        """Choose the asynchronous responses wanted (0257): :data:`NOTIFY_GUARD_HITS` |
        :data:`NOTIFY_SEGMENTS`."""
        value = word(mask, "mask")
        await self._call("request-notifications", extract_done, {"mask": value}, timeout=timeout)
        self._notifications = value

    def async_responses(self) -> AsyncResponseStream:
        """An async iterator of asynchronous responses from now on."""
        return AsyncResponseStream(self._process)

    def add_async_listener(self, listener: AsyncListener) -> Callable[[], None]:
        """Call ``listener(response)`` for each asynchronous response; returns a remover."""
        return self._process.add_async_listener(listener)

    def add_error_listener(self, listener: ErrorListener) -> Callable[[], None]:
        """Call ``listener(error)`` for asynchronous errors, warnings, trivial errors, fatal errors and
        out-of-sequence responses; returns a remover."""
        return self._process.add_error_listener(listener)

    def add_close_listener(self, listener: CloseListener) -> Callable[[], None]:
        """Call ``listener(error)`` once when the connection ends; returns a remover."""
        return self._process.add_close_listener(listener)

    async def wait_for_segment(self, segment: SupportsInt, *, timeout: float | None = None) -> None:
        """Return when segment ``segment`` has completed (see the module docstring)."""
        number = word(segment, "segment")
        if self._segment_done(number):
            return
        if self._process.closed:
            raise ConnectionLostError(f"cannot wait for segment {number}: the connection is closed")
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        entry = (number, future)
        self._segment_waiters.append(entry)
        try:
            await self.prepare_segment_wait()
            if self._polling:
                await self._poll_for_segment(number, future, timeout)
                return
            try:
                await asyncio.wait_for(future, timeout)
            except TimeoutError as exc:
                if isinstance(exc, ManipError):
                    raise
                raise RequestTimeout(None, timeout or 0.0, f"segment {number} did not complete") from None
        finally:
            if entry in self._segment_waiters:
                self._segment_waiters.remove(entry)

    @property
    def waits_by_polling(self) -> bool:
        """Segments are waited for by polling Joint angles: the server does not serve segment
        notifications (it refused request-notifications, or describe self does not list it)."""
        return self._polling

    async def prepare_segment_wait(self) -> None:
        """Ask for segment notifications (0257) unless they are on, before a motion you will wait for;
        a server that does not serve them (a command error: a server written from the 1985 guide alone
        answers it as an unknown opcode) sends the waits to polling instead."""
        if self._polling or self._notifications & NOTIFY_SEGMENTS:
            return
        try:
            await self.request_notifications(self._notifications | NOTIFY_SEGMENTS)
        except NonFatalError as exc:
            if not exc.is_command_error:
                raise
            self._polling = True

    async def _poll_for_segment(
        self, number: int, future: asyncio.Future[None], timeout: float | None
    ) -> None:
        """Wait for segment ``number`` with the 1985 guide's own requests (the module docstring); an
        asynchronous error (the motion aborted) or the connection's end fails the wait through
        ``future``, as it fails a wait for notifications."""
        bound = POLL_TIMEOUT if timeout is None else timeout
        loop = asyncio.get_running_loop()
        end = loop.time() + bound
        goal = self._goals.get(number) if number == self._last_queued else None  # else it ended on the way
        last: tuple[float, ...] | None = None
        still = 0
        while True:
            if future.done():
                future.result()  # raises what failed the waiters
            if self._segment_done(number):
                return
            angles = tuple(await self.joint_angles())
            still = still + 1 if angles == last else 1
            last = angles
            at_goal = goal is None or all(
                abs(a - g) <= AT_GOAL_DEG for a, g in zip(angles, goal, strict=False)
            )
            if still >= STILL_POLLS and at_goal:
                self._arm_stood_still()
                return
            if loop.time() >= end:
                where = "stands still away from its goal" if still >= STILL_POLLS else "is still moving"
                raise RequestTimeout(
                    None, bound, f"segment {number} did not complete (polled joint angles: the arm {where})"
                )
            await asyncio.sleep(POLL_INTERVAL)

    def _arm_stood_still(self) -> None:
        """Polling found the arm still: every segment queued so far has ended."""
        queued = self._last_queued
        if queued is not None and (self._last_segment is None or seq_gt(queued, self._last_segment)):
            self._last_segment = queued

    def _segment_done(self, number: int) -> bool:
        return self._last_segment is not None and seq_le(number, self._last_segment)

    def _on_async_response(self, response: AsyncResponse) -> None:
        if response.condition == AsyncCondition.SEGMENT_COMPLETED:
            if self._last_segment is None or seq_gt(response.word3, self._last_segment):
                self._last_segment = response.word3
            for number, future in list(self._segment_waiters):
                if self._segment_done(number) and not future.done():
                    future.set_result(None)
        elif response.condition == AsyncCondition.GUARD_HIT and response.word2 == GUARD_STOPS:
            self._fail_segment_waiters(GuardTrippedError(response))

    def _on_error(self, error: ManipError) -> None:
        if isinstance(error, AsynchronousError):
            self._fail_segment_waiters(error)

    def _on_close(self, error: ManipError) -> None:
        self._fail_segment_waiters(error)

    def _fail_segment_waiters(self, error: ManipError) -> None:
        for _, future in self._segment_waiters:
            if not future.done():
                future.set_exception(error)

    # ------------------------------------------------------------------ lifecycle

    async def aclose(self) -> None:
        """Disconnect; requests still waiting fail with ConnectionLostError("closed by the user")."""
        await self._process.close()

    async def __aenter__(self) -> Manipulator:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        await self.aclose()
