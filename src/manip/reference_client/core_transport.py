"""An in-memory transport wired straight to a sans-I/O server core, with a virtual clock.

Tests run the client against a real server implementation without sockets, threads or sleeping:
hand :class:`CoreTransport` any object that has the four calls of :class:`ServerCore` (the reference
server's ``ServerSession`` has them) and drive time yourself::

    transport = CoreTransport(ServerSession(), first_number=0xFFFE)   # numbers wrap soon
    async with aconnect(transport) as arm:
        await arm.enable_power()
        await arm.request_notifications(NOTIFY_SEGMENTS)
        segment = await arm.ready()
        await transport.run_until(arm.wait_for_segment(segment))   # ticks virtual time

The client layer does not import the server: :class:`ServerCore` is a structural protocol.

Theory of operation
-------------------
Packet numbers imitate an NCP connection: the "RFC" has number ``first_number`` and every request
takes the next one, modulo 2^16; the server's "OPN" has ``server_first_number`` and its packets follow, with
the Chaos ack field set to the last request number the server received.  A request goes to
``core.on_request`` as soon as it is sent, and the core's packets are queued for the client at once,
unless the transport is *holding*: then requests wait (at most ``window`` of them, which is what
``may_transmit`` reports) until :meth:`CoreTransport.deliver_held`.  Time moves only through
:meth:`CoreTransport.advance`, which calls ``core.tick`` every ``tick_period`` virtual seconds.
A core output with ``close`` set closes the connection after its packets (they stay readable, as a
fatal error followed by CLS must be); :meth:`CoreTransport.drop` breaks the connection as a lost
link would (held requests vanish, nothing more arrives).
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Awaitable, Sequence
from typing import Any, Protocol, TypeVar

from manip.reference_client.inbox import MOD, InboxTransport
from manip.reference_client.memory import SentRequest
from manip.reference_client.packets import ServerPacket
from manip.reference_client.request import Request

T = TypeVar("T")

_SETTLE_TURNS = 8
"""Event-loop turns :meth:`CoreTransport.run_until` allows after time stops (the connection closed)."""
DEFAULT_TICK = 0.016
"""Seconds between server ticks during :meth:`CoreTransport.advance` (the Puma's servo period)."""


class CorePacket(Protocol):
    @property
    def opcode(self) -> int: ...
    @property
    def data(self) -> bytes: ...


class CoreOutput(Protocol):
    """What a server core returns: packets to send in order, then close if ``close``."""

    @property
    def packets(self) -> Sequence[CorePacket]: ...
    @property
    def close(self) -> bool: ...


class ServerCore(Protocol):
    """A sans-I/O server: the calls a driver makes (the reference ``ServerSession`` has them)."""

    def on_open(self, now: float, rfc_packet_no: int) -> CoreOutput: ...

    def on_request(
        self, now: float, opcode: int, packet_no: int, data: bytes, ack_no: int | None = None
    ) -> CoreOutput: ...

    def tick(self, now: float) -> CoreOutput: ...

    def on_close(self, now: float) -> CoreOutput: ...


class VirtualClock:
    """Seconds that pass only when told to."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = start

    @property
    def now(self) -> float:
        return self._now

    def advance_to(self, when: float) -> None:
        if when < self._now:
            raise ValueError(f"a clock does not go back: {when} < {self._now}")
        self._now = when


class CoreTransport(InboxTransport):
    """A :class:`~manip.reference_client.transport.ManipTransport` whose far end is a server core."""

    def __init__(
        self,
        core: ServerCore,
        *,
        clock: VirtualClock | None = None,
        first_number: int = 1,
        server_first_number: int = 1,
        window: int = 8,
        tick_period: float = DEFAULT_TICK,
        hold: bool = False,
    ) -> None:
        if tick_period <= 0:
            raise ValueError("the tick period must be positive")
        super().__init__(window=window, first_number=first_number)
        self.core = core
        self.clock = clock or VirtualClock()
        self.tick_period = tick_period
        self.hold = hold
        """Keep requests from the core until :meth:`deliver_held` (flip it any time)."""
        self.sent: list[SentRequest] = []
        """Every request the client sent, in order."""
        self.received: list[ServerPacket] = []
        """Every packet the core sent, in order."""
        self._held: deque[SentRequest] = deque()
        self._server_number = server_first_number & 0xFFFF  # the "OPN"; data packets follow
        self._server_received: int = self.first_number

    # ------------------------------------------------------------------ ManipTransport

    def may_transmit(self) -> bool:
        return self._open and len(self._held) < self.window

    def return_packet(self, packet: ServerPacket) -> None:
        pass

    async def send_user_request(self, request: Request[Any]) -> None:
        sent = SentRequest(request.opcode, self._number(request), bytes(request.data))
        self.sent.append(sent)
        if self.hold:
            self._held.append(sent)
        else:
            self._serve(sent)

    async def set_up_communications(self) -> None:
        self._opening("core")
        self._deliver(self.core.on_open(self.clock.now, self.first_number))

    async def disconnect(self) -> None:
        if self._open:
            self._close("closed by the client")

    # ------------------------------------------------------------------ test controls

    @property
    def held(self) -> tuple[SentRequest, ...]:
        return tuple(self._held)

    def deliver_held(self, count: int | None = None) -> int:
        """Hand up to ``count`` held requests (all when None) to the core; returns how many."""
        done = 0
        while self._held and self._open and (count is None or done < count):
            self._serve(self._held.popleft())
            done += 1
        self._wake()
        return done

    async def advance(self, seconds: float) -> None:
        """Let ``seconds`` of virtual time pass, ticking the core; yields to the event loop after each
        tick that produced packets so the client sees them in time order."""
        end = self.clock.now + seconds
        while self.clock.now < end and self._open:
            self.clock.advance_to(min(self.clock.now + self.tick_period, end))
            if self._deliver(self.core.tick(self.clock.now)):
                await asyncio.sleep(0)
        await asyncio.sleep(0)

    async def run_until(self, awaitable: Awaitable[T], *, limit: float = 60.0) -> T:
        """Tick virtual time until ``awaitable`` is done (at most ``limit`` virtual seconds); return its
        result.  TimeoutError if it is still waiting then."""
        task = asyncio.ensure_future(awaitable)
        end = self.clock.now + limit
        while not task.done() and self.clock.now < end and self._open:
            await self.advance(self.tick_period)
        for _ in range(_SETTLE_TURNS):
            if task.done():
                break
            await asyncio.sleep(0)
        if not task.done():
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            raise TimeoutError(f"still waiting after {limit:g} virtual seconds")
        return await task

    def drop(self, reason: str = "connection broken") -> None:
        """Break the connection: held requests vanish, the core is told, nothing more arrives."""
        self._held.clear()
        self._close(reason)

    # ------------------------------------------------------------------ internals

    def _serve(self, sent: SentRequest) -> None:
        self._server_received = sent.number
        ack = self._server_number  # the client has seen every server packet queued so far
        self._deliver(self.core.on_request(self.clock.now, sent.opcode, sent.number, sent.data, ack))

    def _deliver(self, output: CoreOutput) -> bool:
        if not self._open:
            return False
        for item in output.packets:
            self._server_number = (self._server_number + 1) % MOD
            packet = ServerPacket(item.opcode, bytes(item.data), self._server_number, self._server_received)
            self._inbox.append(packet)
            self.received.append(packet)
        delivered = bool(output.packets)
        if output.close:
            self._close("closed by the server")
        elif delivered:
            self._wake()
        return delivered

    def _close(self, reason: str) -> bool:
        if not super()._close(reason):
            return False
        self.core.on_close(self.clock.now)
        return True
