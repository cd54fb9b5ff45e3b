"""The background process: an asyncio task between the user's requests and the transport.

Theory of operation
-------------------
The user side calls :meth:`BackgroundProcess.submit`, which puts the request on the user request queue
and returns a future.  The task loops::

    read every available packet -> matching core -> events -> futures, listeners, log
    connection closed?          -> fail everything with ConnectionLostError, stop
    while the queue is not empty, the initial RESPONSE came and may_transmit():
        send_user_request(request) -> matching core knows the packet number
    sleep until the transport or a new request wakes us

States of the process::

    starting --initial RESPONSE--> running --fatal error / connection lost / close()--> terminated

In ``terminated`` every queued and pending request has failed (FatalError after a fatal error,
ConnectionLostError otherwise), close listeners have been called (async iterators end, segment waiters
fail) and new requests are refused at once with ConnectionLostError, chained to the cause.  Nothing waits
for ever: per-request timers fail a request with RequestTimeout, a fatal error or a lost connection
fails all of them.  A reply that comes after a timeout is reported as a late out-of-sequence response.

Asynchronous responses go to the asynchronous-response listeners; asynchronous errors, warnings,
trivial errors and out-of-sequence responses go to the log (logger ``manip.reference_client``) and the
error listeners.  A listener that raises is logged and otherwise ignored.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable
from typing import Any, TypeVar

from manip.codecs.messages import AsyncResponse
from manip.reference_client.errors import ConnectionLostError, FatalError, ManipError, RequestTimeout
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
from manip.reference_client.faults import NO_FAULTS, ClientFault, ClientFaults
from manip.reference_client.matching import MatchingCore
from manip.reference_client.request import Request, RequestState
from manip.reference_client.transport import ManipTransport

log = logging.getLogger("manip.reference_client")

T = TypeVar("T")
AsyncListener = Callable[[AsyncResponse], None]
ErrorListener = Callable[[ManipError], None]
CloseListener = Callable[[ManipError], None]


def _remover(items: list[Any], item: Any) -> Callable[[], None]:
    def remove() -> None:
        if item in items:
            items.remove(item)

    return remove


def _error_for(error: ManipError, request: Request[Any]) -> ManipError:
    """The error a still-queued request fails with when the process ends with ``error``."""
    if isinstance(error, FatalError):
        return FatalError(
            error.error, request_number=error.request_number, request=request, faults=error.faults
        )
    if isinstance(error, ConnectionLostError):
        lost = ConnectionLostError(error.reason)
        lost.__cause__ = error.__cause__
        return lost
    return error


class BackgroundProcess:
    """Runs one connection; see the module docstring."""

    def __init__(
        self,
        transport: ManipTransport,
        core: MatchingCore,
        *,
        name: str = "manipulator",
        faults: ClientFaults = NO_FAULTS,
    ) -> None:
        self.transport = transport
        self.core = core
        self.name = name
        self.faults = faults
        self._queue: deque[Request[Any]] = deque()
        self._futures: dict[Request[Any], asyncio.Future[Any]] = {}
        self._timers: dict[Request[Any], asyncio.TimerHandle] = {}
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._initial: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self._terminal: ManipError | None = None
        self._closed_by_user = False
        self._async_listeners: list[AsyncListener] = []
        self._error_listeners: list[ErrorListener] = []
        self._close_listeners: list[CloseListener] = []

    # ------------------------------------------------------------------ public

    @property
    def closed(self) -> bool:
        return self._terminal is not None

    @property
    def closed_by_user(self) -> bool:
        """True when :meth:`close` ended the process (rather than the server or the network)."""
        return self._closed_by_user

    @property
    def terminal_error(self) -> ManipError | None:
        """Why the process ended (None while it runs)."""
        return self._terminal

    @property
    def queued(self) -> tuple[Request[Any], ...]:
        return tuple(self._queue)

    async def start(self, connect_timeout: float | None = None) -> None:
        """Open the connection, start the task, wait for the initial RESPONSE."""
        self.transport.set_wakeup(self._wake.set)
        try:
            await self.transport.set_up_communications()
        except ManipError:
            raise
        except Exception as exc:
            raise ConnectionLostError(f"cannot connect: {exc}") from exc
        self._task = asyncio.create_task(self._run(), name=f"manip background ({self.name})")
        if self.core.ready:
            return
        try:
            await asyncio.wait_for(asyncio.shield(self._initial), connect_timeout)
        except TimeoutError:
            await self.close(f"no initial RESPONSE within {connect_timeout:g} s")
            raise ConnectionLostError(f"no initial RESPONSE within {connect_timeout:g} s") from None

    def submit(self, request: Request[T]) -> asyncio.Future[T]:
        """Queue ``request``; the future completes with its result or fails with a ManipError."""
        if self._terminal is not None:
            raise self._refusal(request)
        if request.state is not RequestState.QUEUED or request in self._futures:
            raise ValueError(f"{request!r} was already submitted")
        loop = asyncio.get_running_loop()
        future: asyncio.Future[T] = loop.create_future()
        self._futures[request] = future
        future.add_done_callback(lambda f: self._future_done(request, f))
        if request.timeout is not None:
            self._timers[request] = loop.call_later(request.timeout, self._expire, request)
        self._queue.append(request)
        self._wake.set()
        return future

    async def close(self, reason: str = "closed by the user") -> None:
        """Fail everything still waiting with ConnectionLostError(reason), disconnect, stop the task."""
        if self._terminal is None:
            self._closed_by_user = True
            self._handle(self.core.connection_lost(reason))
        self._wake.set()
        if self._task is None:
            await self._disconnect()
        elif not self._task.done():
            await asyncio.wait([self._task])  # the task disconnects on its way out

    def add_async_listener(self, listener: AsyncListener) -> Callable[[], None]:
        """Call ``listener`` with every asynchronous response; returns a function that removes it."""
        self._async_listeners.append(listener)
        return _remover(self._async_listeners, listener)

    def add_error_listener(self, listener: ErrorListener) -> Callable[[], None]:
        """Call ``listener`` with asynchronous errors, warnings, notified trivial errors, fatal errors and
        out-of-sequence responses."""
        self._error_listeners.append(listener)
        return _remover(self._error_listeners, listener)

    def add_close_listener(self, listener: CloseListener) -> Callable[[], None]:
        """Call ``listener`` once with the terminal error when the process ends (at once if it has)."""
        if self._terminal is not None:
            self._call(listener, self._terminal)
            return lambda: None
        self._close_listeners.append(listener)
        return _remover(self._close_listeners, listener)

    # ------------------------------------------------------------------ the task

    async def _run(self) -> None:
        try:
            while self._terminal is None:
                self._wake.clear()
                self._read_packets()
                if self._terminal is not None:
                    break
                if not self.transport.connection_open():
                    reason = self.transport.handle_closed_connection()
                    log.info("%s: connection closed: %s", self.name, reason)
                    cause = getattr(self.transport, "close_cause", None)  # optional transport extra
                    self._handle(
                        self.core.connection_lost(reason, cause if isinstance(cause, BaseException) else None)
                    )
                    break
                await self._send_queued()
                if self._terminal is None and not self._wake.is_set():
                    await self._wake.wait()
        except asyncio.CancelledError:
            if self._terminal is None:
                self._handle(self.core.connection_lost("background process cancelled"))
            raise
        except Exception as exc:
            if isinstance(exc, ConnectionLostError):
                reason = exc.reason
                log.info("%s: %s", self.name, exc)
            else:
                reason = f"background process failed: {exc!r}"
                log.exception("%s: background process failed", self.name)
            if self._terminal is None:
                self._handle(self.core.connection_lost(reason))
        finally:
            await self._disconnect()

    def _read_packets(self) -> None:
        transport = self.transport
        while self._terminal is None and transport.response_available():
            packet = transport.get_next_packet()
            if packet is None:
                break
            try:
                info = transport.get_response_info(packet)
            except Exception as exc:
                events = self.core.malformed(packet, exc)
            else:
                events = self.core.receive(packet, info)
            self._handle(events)
            if not any(isinstance(e, PacketKept) for e in events):
                transport.return_packet(packet)

    async def _send_queued(self) -> None:
        transport = self.transport
        while self._queue and self.core.ready and self._terminal is None and transport.may_transmit():
            request = self._queue.popleft()
            if request.state is not RequestState.QUEUED:
                continue
            try:
                await transport.send_user_request(request)
            except BaseException:
                self._queue.appendleft(request)  # still unsent: it fails with everything else
                raise
            log.debug("%s: sent %s", self.name, request.describe())
            self._handle(self.core.sent(request))

    async def _disconnect(self) -> None:
        self.transport.set_wakeup(None)
        try:
            await self.transport.disconnect()
        except Exception:
            log.exception("%s: disconnect failed", self.name)

    # ------------------------------------------------------------------ events

    def _handle(self, events: list[Event]) -> None:
        for event in events:
            match event:
                case InitialResponse(number):
                    log.debug("%s: initial RESPONSE (number %d)", self.name, number)
                    if not self._initial.done():
                        self._initial.set_result(number)
                    self._wake.set()
                case RequestAnswered(request, value):
                    self._resolve(request, value, None)
                case RequestFailed(request, error):
                    self._resolve(request, None, error)
                case AsyncResponseReceived(response):
                    log.debug("%s: asynchronous response %s", self.name, response)
                    for listener in list(self._async_listeners):
                        self._call(listener, response)
                case AsyncErrorReceived(error):
                    self._report(logging.WARNING, error)
                case WarningReceived(warning):
                    self._report(logging.WARNING, warning)
                case TrivialErrorNotified(error):
                    self._report(logging.INFO, error)
                case OutOfSequence(error):
                    self._report(logging.WARNING, error)
                case FatalErrorReceived(error):
                    self._report(logging.ERROR, error)
                    self._terminate(error)
                case ConnectionEnded(reason, cause):
                    self._closed_by(reason, cause)
                case PacketKept():
                    pass

    def _closed_by(self, reason: str, cause: BaseException | None) -> None:
        if ClientFault.SILENT_CLOSE in self.faults:
            return
        lost = ConnectionLostError(reason)
        lost.__cause__ = cause
        self._terminate(lost)

    def _report(self, level: int, error: ManipError) -> None:
        log.log(level, "%s: %s", self.name, error)
        for listener in list(self._error_listeners):
            self._call(listener, error)

    def _call(self, listener: Callable[[Any], None], arg: Any) -> None:
        try:
            listener(arg)
        except Exception:
            log.exception("%s: listener %r failed", self.name, listener)

    def _resolve(self, request: Request[Any], value: Any, error: ManipError | None) -> None:
        timer = self._timers.pop(request, None)
        if timer is not None:
            timer.cancel()
        future = self._futures.pop(request, None)
        if future is None or future.done():
            return
        if error is None:
            future.set_result(value)
        else:
            future.set_exception(error)

    def _terminate(self, error: ManipError) -> None:
        if self._terminal is not None:
            return
        self._terminal = error
        queued, self._queue = list(self._queue), deque()
        for request in queued:
            if not request.done:
                request.state = RequestState.FAILED
                request.error = _error_for(error, request)
                self._resolve(request, None, request.error)
        if not self._initial.done():
            self._initial.set_exception(error)
            self._initial.exception()  # retrieved: start() re-raises it when it is waiting
        listeners, self._close_listeners = self._close_listeners, []
        for listener in listeners:
            self._call(listener, error)
        self._wake.set()

    def _refusal(self, request: Request[Any]) -> ConnectionLostError:
        cause = self._terminal
        reason = cause.reason if isinstance(cause, ConnectionLostError) else f"closed after {cause}"
        error = ConnectionLostError(f"cannot send {request.describe()}: {reason}")
        error.__cause__ = cause
        return error

    # ------------------------------------------------------------------ timeouts and cancellation

    def _expire(self, request: Request[Any]) -> None:
        self._timers.pop(request, None)
        if not request.done and request.timeout is not None:
            log.warning("%s: %s timed out after %g s", self.name, request.describe(), request.timeout)
            self._abandon(request, RequestTimeout(request, request.timeout))

    def _future_done(self, request: Request[Any], future: asyncio.Future[Any]) -> None:
        if future.cancelled() and not request.done:
            self._abandon(request, ManipError(f"{request.describe()} was cancelled"))

    def _abandon(self, request: Request[Any], error: ManipError) -> None:
        if request.state is RequestState.QUEUED:
            if request in self._queue:
                self._queue.remove(request)
            request.state = RequestState.FAILED
            request.error = error
            self._resolve(request, None, error)
        else:
            self._handle(self.core.abandon(request, error))
