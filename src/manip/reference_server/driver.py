"""The asyncio driver of the reference Puma server: Chaos connections in, one simulated robot, a servo clock.

Theory of operation
===================

:func:`serve` listens on one or more link addresses (:func:`manip.links.start_server`) for the contact
name and yields a :class:`ReferenceServer`.  The protocol is all in :class:`ServerSession` (sans-I/O);
this module only moves packets and time:

* **One server is one robot** (erratum ``server-robot``).  The robot's joint angles and hand persist
  across connections; everything the Puma-11's main process set up per connection (segment counter,
  queue, speed factor, configuration, abort flag, notifications, arm power as ``powered_at_open`` says)
  starts afresh: each connection gets a :class:`ServerSession` with a new
  :class:`~manip.arm.sim.ArmSim` standing where the robot stands.  The wrist (``wrist_factory``) is
  made once and shared.  When a connection ends the arm is brought up to date and stops where it is.
  ``max_clients`` (1 by default) connections may be open at once over all addresses; an RFC beyond
  that is refused with a CLS whose text says the robot is busy.  More than one is for benchmarks: each
  concurrent client then drives its own copy of the arm, and the last to leave sets where it stands.
* **Time** (erratum ``server-time-scale``): simulated time is ``(monotonic seconds since the server
  started) * time_scale``.  The servo ticks at every 16 ms of simulated time (real period
  ``0.016 / time_scale``, never less than 1 ms; a tick runs every servo cycle due) and calls
  ``session.tick(now)`` for every connection; the asynchronous packets it returns go out in order.
  A servo task sleeps until just before each tick and yields to the loop for the last moment (asyncio
  timers overshoot by up to a millisecond); a connection busy with requests runs a due tick itself
  between two requests.  Requests do not wait for the servo: the session runs the arm up to ``now``
  before serving one.  How late each tick ran (real seconds after its scheduled time) is kept in
  :attr:`ReferenceServer.tick_lateness` (``bench/server.py`` reports it).
* **Per connection** one task: it sends the initial RESPONSE (quoting the RFC's packet number,
  ``conn.rfc.packet_no``, errata ``initial-response`` and ``server-rfc-number``), then loops: send
  what is queued while the peer's window allows, take received packets (a few at a time, yielding in
  between, so the servo is not starved by a pipelining client) and feed each to
  ``session.on_request``, queue its output; wait
  for a packet, an open window, the servo or the end (the connection's wake-up callback is set only
  while waiting: the node checks every such connection after each packet).  A client that does not
  read its replies stops being read itself (its window closes), so nothing grows without bound.
  After a fatal error the queued packets are sent and the connection is closed (EOF, then CLS).
* **Bad input never escapes**: the session answers unknown opcodes, wrong lengths and bad floats with
  command errors; anything that still raises is logged, counted in ``stats.driver_errors`` and ends only
  that connection (CLS "Server error").  Oversize or garbled frames never get this far: the link drops
  its stream and the NCP ends that connection.
* **Logging**: one INFO line per request on ``manip.reference_server``: peer, packet number, opcode
  name, outcome.
* **Links and access** (:mod:`manip.links.guard`): ``limits`` bound every TCP link (a link that sends
  no frame, or half of one, or opens no connection is closed in time; at most so many at once) and
  ``allow`` says who may connect, by IP address and by Chaos address.  What they refused is in
  :meth:`ReferenceServer.link_stats`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import random
import weakref
from collections import deque
from collections.abc import AsyncIterator, Callable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Final

from manip.arm.kinematics import Joints
from manip.arm.sim import ArmSim
from manip.arm.trajectory import TICK
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import CodecError
from manip.codecs.messages import decode_error
from manip.links import (
    AccessList,
    ChaosConnection,
    ChaosError,
    ChaosServer,
    GuardStats,
    LinkLimits,
    LinkStats,
    NcpConfig,
    start_server,
)
from manip.links.api import LinkWrapper
from manip.links.stream import StreamLink
from manip.links.virtual_clock import is_virtual
from manip.ncp import ChaosDefects, ConnectionRequested
from manip.reference_server.defects import arm_defects, chaos_defects, defects_for
from manip.reference_server.session import Outgoing, Output, ServerConfig, ServerSession, State
from manip.reference_server.wrist import Wrist
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import ASYNC_OPS, ERROR_REPLY_OPS, ServerOp
from manip.spec.notation import octal

__all__ = [
    "BUSY_REASON",
    "DEFAULT_ADDRESS",
    "MIN_SERVO_PERIOD",
    "ReferenceServer",
    "ServerStats",
    "serve",
]

log = logging.getLogger("manip.reference_server")

DEFAULT_ADDRESS: Final = "tcp://127.0.0.1:42085"
"""Where ``manip-server`` listens by default: manip's TCP link on loopback, port 42085."""
BUSY_REASON: Final = "Busy: this robot already has a client"
MIN_SERVO_PERIOD: Final = 0.001
"""Shortest real time between servo wake-ups (s); at large time scales each runs several cycles."""
SERVO_SPIN: Final = 0.0011
"""The servo task sleeps until this long before a tick, then yields to the loop until it is due (only
when the real servo period is at least eight times as long, i.e. at time scales up to about 1.8)."""
BATCH: Final = 4
"""Requests served from one connection before yielding to the other tasks (the servo among them)."""
DROP_LINK_DELAY: Final = 0.05
"""Seconds the fault fatal-drops-link lets the fatal error travel before it drops the link."""
LATENESS_KEPT: Final = 1 << 16

_COMMAND_ERROR: Final = "C"
"""Severity of a request the server could not understand (bad input)."""


@dataclass(slots=True)
class ServerStats:
    """What the server has done since it started."""

    connections: int = 0
    """Connections opened (each got a session)."""
    refused: int = 0
    """RFCs refused because ``max_clients`` connections were open."""
    requests: int = 0
    """Data packets fed to a session (the packet after free joint included)."""
    errors: int = 0
    """Requests answered with an error (non-fatal or fatal)."""
    fatal: int = 0
    """Requests answered with a fatal error (the connection is then closed)."""
    bad_inputs: int = 0
    """Requests answered with a command error (severity C: unknown opcode, bad length, bad value...)."""
    discarded: int = 0
    """Packets swallowed after free joint (answered done, not executed)."""
    async_packets: int = 0
    """Asynchronous responses, errors and warnings sent."""
    packets_sent: int = 0
    """Server packets sent (replies, errors, asynchronous packets, the initial responses)."""
    ticks: int = 0
    """Servo wake-ups."""
    late_ticks: int = 0
    """Servo wake-ups more than one period late (the cycles are still run, by the next wake-up)."""
    driver_errors: int = 0
    """Exceptions caught in the driver (each ended one connection; should stay 0)."""

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class _Client:
    """One open connection: its session, its outgoing queue and the future its task sleeps on."""

    __slots__ = ("conn", "name", "out", "session", "waiter")

    def __init__(self, conn: ChaosConnection, session: ServerSession) -> None:
        self.conn = conn
        self.session = session
        host, index = conn.peer
        self.name = f"{octal(host)}/{octal(index)}"
        self.out: deque[tuple[int, bytes]] = deque()
        self.waiter: asyncio.Future[None] | None = None

    def poke(self) -> None:
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)


class ReferenceServer:
    """A running reference server (made by :func:`serve`).

    ``address`` is the first listening address with its real port (``tcp://127.0.0.1:PORT``);
    ``addresses`` all of them."""

    def __init__(
        self,
        config: ServerConfig,
        *,
        contact: str,
        time_scale: float,
        seed: int | None,
        max_clients: int,
        wrist: Wrist | None,
    ) -> None:
        if not (math.isfinite(time_scale) and time_scale > 0.0):
            raise ValueError(f"time_scale must be finite and positive, not {time_scale}")
        if max_clients < 1:
            raise ValueError(f"max_clients must be at least 1, not {max_clients}")
        self.config = config
        self.contact = contact
        self.time_scale = float(time_scale)
        self.seed = seed
        self.rng = random.Random(seed)
        """The server's random generator (seeded by ``seed``); the arm model itself is deterministic."""
        self.max_clients = max_clients
        self._admits_all = defects_for(config.faults).admits_second_client
        """Every RFC is accepted, whatever is open (fault second-client-admitted)."""
        self.wrist = wrist
        self.stats = ServerStats()
        self.servo_period = max(TICK / self.time_scale, MIN_SERVO_PERIOD)
        """Real seconds between servo wake-ups."""
        self.tick_lateness: deque[float] = deque(maxlen=LATENESS_KEPT)
        """Real seconds each servo wake-up came after its scheduled time (the last 65536)."""
        self.joints: Joints = config.model.ready
        """Where the robot stands (updated when a connection ends)."""
        self.hand_open = True
        self._carried: ArmSim | None = None
        self._last_session: ServerSession | None = None
        """The session of the connection opened last (the connection-keeps-* faults carry its state)."""
        """An arm a closed connection left moving (fault close-keeps-moving): the next session gets it."""
        self.servers: list[ChaosServer] = []
        self._loop = asyncio.get_running_loop()
        self._t0 = self._loop.time()
        self._clients: dict[ChaosConnection, _Client] = {}
        self._released: weakref.WeakSet[ChaosConnection] = weakref.WeakSet()
        self._clients_changed = asyncio.Event()
        self._servo: asyncio.Task[None] | None = None
        self._k = 0  # index of the next servo tick
        self._due = math.inf  # when it is due (loop time); infinite while no client is connected

    def __repr__(self) -> str:
        return f"<ReferenceServer {self.contact} at {', '.join(self.addresses)}>"

    # ------------------------------------------------------------------------------ public view
    @property
    def address(self) -> str:
        return self.addresses[0]

    @property
    def addresses(self) -> list[str]:
        """Every listening address, with its real port and (when not PUMA) the contact name: a client
        can open any of them as it is."""
        return [str(replace(server.address, contact=self.contact)) for server in self.servers]

    @property
    def clients(self) -> int:
        """Connections being served now."""
        return len(self._clients)

    @property
    def sessions(self) -> list[ServerSession]:
        return [client.session for client in self._clients.values()]

    def link_stats(self) -> tuple[GuardStats, LinkStats]:
        """What every address's guard refused and closed (RFCs refused as busy are ``stats.refused``),
        and the counters of every link, closed ones included, summed."""
        guards, links = GuardStats(), LinkStats()
        for server in self.servers:
            guards.add(server.guard.stats)
            links.add(server.node.link_stats())
        return guards, links

    @property
    def bad_frames(self) -> int:
        """Frames the links refused (oversize, garbled, bad checksum): bad input below the protocol,
        which ends the link or connection it came on and nothing else."""
        return sum(server.node.link_stats().bad_total for server in self.servers)

    def now(self) -> float:
        """Simulated time: real seconds since the server started, times ``time_scale``."""
        return (self._loop.time() - self._t0) * self.time_scale

    async def wait_idle(self, timeout: float = 5.0) -> None:
        """Wait until no connection is being served (for tests and orderly shutdowns)."""
        async with asyncio.timeout(timeout):
            while self._clients:
                self._clients_changed.clear()
                await self._clients_changed.wait()

    # ---------------------------------------------------------------------------- accepting
    def _policy(self, request: ConnectionRequested) -> str | None:
        """Refuse an RFC while ``max_clients`` connections are open or opening (on any address)."""
        live = sum(
            1
            for server in self.servers
            for conn in server.connections
            if not conn.ended and conn not in self._released
        )
        if live < self.max_clients or self._admits_all:
            return None
        self.stats.refused += 1
        log.info(
            "refused %s/%s: %d client(s) connected (max %d)",
            octal(request.peer_host),
            octal(request.peer_index),
            live,
            self.max_clients,
        )
        return BUSY_REASON

    def _new_session(self) -> ServerSession:
        config = self.config
        arm = ArmSim(
            config.model,
            start=self.joints,
            powered=config.powered_at_open,
            defects=arm_defects(config.faults),
        )
        arm.hand_open = self.hand_open
        if self._carried is not None:
            arm, self._carried = self._carried, None
        session = ServerSession(config, arm=arm, wrist=self.wrist)
        if self._last_session is not None:
            session.inherit(self._last_session)  # nothing, unless a connection-keeps-* fault is on
        self._last_session = session
        return session

    # --------------------------------------------------------------------------- a connection
    async def _handle(self, conn: ChaosConnection) -> None:
        session = self._new_session()
        client = _Client(conn, session)
        self._clients[conn] = client
        self._clients_changed.set()
        self.stats.connections += 1
        rfc_no = conn.rfc.packet_no if conn.rfc is not None else 0
        log.info("%s: connected (RFC #%d)", client.name, rfc_no)
        reason = "closed"
        try:
            self._queue(client, session.on_open(self.now(), rfc_no))
            reason = await self._run(client)
        except ChaosError as exc:
            reason = str(exc)
        except Exception:
            self.stats.driver_errors += 1
            log.exception("%s: driver error", client.name)
            reason = "driver error"
            conn.abort("Server error")
        finally:
            self._finish(client, reason)

    async def _run(self, client: _Client) -> str:
        """Serve ``client`` until its connection ends; returns why it ended."""
        conn, session, loop = client.conn, client.session, self._loop
        out = client.out
        while True:
            served = 0
            while True:
                while out and conn.can_send():
                    opcode, data = out.popleft()
                    await conn.send(data, opcode)
                    self.stats.packets_sent += 1
                if session.state is State.CLOSED:
                    if not out:
                        if session.defects.after_fatal == "drop-link":
                            return await self._drop_link(conn)
                        if session.defects.after_fatal == "eof-drop-link":
                            return await self._eof_drop_link(conn)
                        await conn.close()
                        return "closed after a fatal error"
                    break
                if out or served >= BATCH:
                    break  # window full: stop reading this client until it reads us
                packet = conn.receive_nowait()  # raises the connection's end
                if packet is None:
                    break
                served += 1
                self._servo_if_due()
                self._serve(client, packet.opcode, packet.packet_no, packet.data, packet.ack_no)
            if served >= BATCH and not out:
                await asyncio.sleep(0)  # let the other connections and the servo run
                continue
            if conn.ended:
                return f"ended: {conn.end_reason}"
            # Watched only while waiting: the node checks every watched connection after each packet.
            client.waiter = waiter = loop.create_future()
            conn.set_wakeup(client.poke)
            try:
                await waiter
            finally:
                client.waiter = None
                conn.set_wakeup(None)

    async def _drop_link(self, conn: ChaosConnection) -> str:
        """Fault fatal-drops-link: give the last packets a moment, then close the stream link under
        ``conn`` (no CLS); a shared datagram link is left alone and the connection just forgotten."""
        await asyncio.sleep(DROP_LINK_DELAY)
        link = conn.node.link_of(conn)
        if isinstance(link, StreamLink):
            link.close()
        return "link dropped after a fatal error (fault fatal-drops-link)"

    async def _eof_drop_link(self, conn: ChaosConnection) -> str:
        """Fault fatal-eof-without-cls: start the close (the EOF goes out after the last packets), then
        close the stream link under ``conn`` before the peer's acknowledgement of the EOF can arrive and
        draw the CLS.  A shared datagram link is not dropped, so there the close completes with its CLS:
        the fault shows on stream links (tcp://, unix://)."""
        link = conn.node.link_of(conn)
        closing = asyncio.ensure_future(conn.close(timeout=DROP_LINK_DELAY))
        await asyncio.sleep(0)  # the close runs up to its first wait: the EOF is written, no reply read yet
        if isinstance(link, StreamLink):
            link.close()
        with contextlib.suppress(ChaosError):
            await closing
        return "EOF sent and the link dropped after a fatal error (fault fatal-eof-without-cls)"

    def _serve(self, client: _Client, opcode: int, packet_no: int, data: bytes, ack_no: int) -> None:
        session = client.session
        freed = session.state is State.FREE_JOINT_WAIT
        output = session.on_request(self.now(), opcode, packet_no, data, ack_no)
        stats = self.stats
        stats.requests += 1
        if freed:
            stats.discarded += 1
        answer = self._queue(client, output)
        if log.isEnabledFor(logging.INFO):
            op = SPEC.requests.get(opcode)
            name = op.name if op is not None else "unknown"
            if answer is None:
                what = f"no reply yet ({session.state.value})"
            elif freed and answer.opcode == ServerOp.RESPONSE:
                what = "discarded after free joint: done"
            else:
                what = _outcome(op, answer, output)
            log.info("%s #%d %s (%s): %s", client.name, packet_no, name, octal(opcode), what)

    def _queue(self, client: _Client, output: Output) -> Outgoing | None:
        """Queue ``output`` on ``client`` and count it; returns the first packet answering a request."""
        stats = self.stats
        answer = None
        out = client.out
        for packet in output.packets:
            opcode = packet.opcode
            out.append((opcode, packet.data))
            if opcode in ASYNC_OPS:
                stats.async_packets += 1
                continue
            if answer is None:
                answer = packet
            if opcode in ERROR_REPLY_OPS:
                stats.errors += 1
                if opcode == ServerOp.FATAL_ERROR:
                    stats.fatal += 1
                error = _error(packet)
                if error is not None and error.severity == _COMMAND_ERROR:
                    stats.bad_inputs += 1
        return answer

    def _finish(self, client: _Client, reason: str) -> None:
        conn = client.conn
        self._released.add(conn)
        conn.set_wakeup(None)
        session = client.session
        with contextlib.suppress(Exception):  # the arm is brought up to date; its output has no reader
            session.tick(self.now())
        arm = session.arm
        arm.unfree()
        self.joints = arm.actual
        self.hand_open = arm.hand_open
        if session.defects.keeps_arm_after_close:
            self._carried = arm
        with contextlib.suppress(Exception):
            session.on_close(self.now())
        self._clients.pop(conn, None)
        self._clients_changed.set()
        log.info("%s: disconnected (%s)", client.name, reason)

    # ---------------------------------------------------------------------------- the servo
    async def _servo_loop(self) -> None:
        """Wake at every servo period while a client is connected.

        ``asyncio`` sleeps overshoot by up to a millisecond (epoll rounds its timeout up), so the task
        sleeps until ``SERVO_SPIN`` before the tick and then yields to the loop (``sleep(0)``: I/O and
        the other tasks still run) until the tick is due.  Busy connections also run a due tick
        themselves, between two requests (:meth:`_servo_if_due`), so a long burst of requests does not
        hold the servo back."""
        loop = self._loop
        period = self.servo_period
        # Sped-up clocks just sleep; so does a virtual clock, whose sleeps end exactly on time.
        spin = SERVO_SPIN if period >= 8 * SERVO_SPIN and not is_virtual(loop) else 0.0
        while True:
            if not self._clients:
                self._due = math.inf
                self._clients_changed.clear()
                await self._clients_changed.wait()
                continue
            if self._due == math.inf:
                self._k = math.floor((loop.time() - self._t0) / period) + 1
                self._due = self._t0 + self._k * period
            delay = self._due - loop.time()
            if delay > spin:
                await asyncio.sleep(delay - spin)
            elif delay > 0.0:
                await asyncio.sleep(0)
            else:
                self._servo_step()

    def _servo_if_due(self) -> None:
        if self._due <= self._loop.time():
            self._servo_step()

    def _servo_step(self) -> None:
        """Run the servo tick that is due, and schedule the next one."""
        period = self.servo_period
        woke = self._loop.time()
        late = woke - self._due
        self.tick_lateness.append(late)
        stats = self.stats
        stats.ticks += 1
        if late > period:
            stats.late_ticks += 1
            self._k = math.floor((woke - self._t0) / period)
        self._k += 1
        self._due = self._t0 + self._k * period
        self._tick_all()

    def _tick_all(self) -> None:
        now = self.now()
        for client in list(self._clients.values()):
            try:
                output = client.session.tick(now)
            except Exception:
                self.stats.driver_errors += 1
                log.exception("%s: servo error", client.name)
                client.conn.abort("Server error")
                continue
            if output.packets:
                self._queue(client, output)
                client.poke()

    # ----------------------------------------------------------------------------- lifetime
    async def _start(
        self,
        addresses: Sequence[str],
        options: NcpConfig | None,
        wrap_link: LinkWrapper | None,
        limits: LinkLimits | None = None,
        allow: AccessList | None = None,
    ) -> None:
        for address in addresses:
            server = await start_server(
                address,
                self.contact,
                self._handle,
                policy=self._policy,
                options=options,
                wrap_link=wrap_link,
                limits=limits,
                allow=allow,
            )
            self.servers.append(server)
            log.info("listening on %s (contact %s)", server.address, self.contact)
        self._servo = self._loop.create_task(self._servo_loop(), name="manip-server-servo")

    async def aclose(self) -> None:
        """Stop listening, close every connection (CLS "Server closing") and stop the servo."""
        for server in self.servers:
            server.close("Server closing")
        for server in self.servers:
            await server.wait_closed()
        if self._servo is not None:
            self._servo.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._servo
            self._servo = None


def _error(packet: Outgoing) -> ErrorMessage | None:
    try:
        return decode_error(packet.opcode, packet.data).error
    except CodecError:  # a deliberately malformed error string (a fault switch)
        return None


def _outcome(op: RequestOpcode | None, answer: Outgoing, output: Output) -> str:
    """How a request was answered, for the log."""
    if answer.opcode in ERROR_REPLY_OPS:
        kind = "FATAL" if answer.opcode == ServerOp.FATAL_ERROR else "error"
        error = _error(answer)
        return f"{kind} {error.render() if error is not None else '(undecodable error string)'}"
    body = answer.data[2:]
    if op is None or not body:
        return "done"
    match op.response.form:
        case "segment" if len(body) == 2:
            return f"segment {int.from_bytes(body, 'little')}"
        case "multi":
            count = sum(1 for p in output.packets if p.opcode == ServerOp.RESPONSE)
            return f"text in {count} packets"
    return f"{len(body)} data bytes"


@contextlib.asynccontextmanager
async def serve(
    address: str = DEFAULT_ADDRESS,
    config: ServerConfig | None = None,
    *,
    contact: str = "PUMA",
    time_scale: float = 1.0,
    seed: int | None = None,
    max_clients: int = 1,
    wrist_factory: Callable[[], Wrist] | None = None,
    extra_addresses: Sequence[str] = (),
    options: NcpConfig | None = None,
    wrap_link: LinkWrapper | None = None,
    limits: LinkLimits | None = None,
    allow: AccessList | None = None,
) -> AsyncIterator[ReferenceServer]:
    """Run a reference server for the ``async with`` block.

    ``address`` and ``extra_addresses`` are link addresses (``tcp://HOST:PORT`` with port 0 for a free
    one, ``chudp://HOST:PORT?addr=..``, ``chaosd:///path``); ``server.address`` is the first with its
    real port.  ``time_scale`` is simulated seconds per real second; ``max_clients`` how many
    connections may be open at once (one robot: 1); ``wrist_factory`` makes the robot's wrist once.
    ``wrap_link`` is given every link of every address (:func:`manip.links.start_server`): a capture's
    ``RecorderTap(recorder, "server").wrap`` records all the server's traffic.  ``limits`` and
    ``allow`` bound the links and say who may connect (:func:`manip.links.start_server`; default:
    :class:`~manip.links.LinkLimits`, everyone)."""
    config = config or ServerConfig()
    defects = chaos_defects(config.faults)
    if defects != ChaosDefects():  # the Chaos-level faults reach the NCP and the links as a value
        options = replace(options or NcpConfig(), defects=defects)
    server = ReferenceServer(
        config,
        contact=contact,
        time_scale=time_scale,
        seed=seed,
        max_clients=max_clients,
        wrist=wrist_factory() if wrist_factory is not None else None,
    )
    try:
        await server._start([address, *extra_addresses], options, wrap_link, limits, allow)
        yield server
    finally:
        await server.aclose()
