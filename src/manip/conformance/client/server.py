"""The judging server: a scripted Puma on the project's NCP and links, one scenario per case.

Each case gets a fresh listener (its own port, NCP settings and acceptance policy) so nothing of one case
leaks into the next.  Every packet both ways is recorded by a tap between the node and its link (the
*wire*, judged afterwards); on CHUDP the tap can also duplicate and reorder what the server sends.

A scenario's script drives a :class:`ServerSide`: take the client's next request, answer it (whole, in
pieces, late, with an error string, with asynchronous packets first), close or drop the connection.  The
initial RESPONSE is sent before the script runs (its number: the RFC's packet number).

Throttling, to judge the client's window (``ncp.window``): the server's driver acknowledges a request only
when the script takes it (:meth:`ServerSide.next_request`), so a script that *holds* (takes nothing for a
while) holds its acknowledgements and its replies; :meth:`ServerSide.delay_status` holds the STS packets
that would open the window for a time; :meth:`ServerSide.offer_window` changes the window the server
offers mid-case (every STS from then on carries it, and one goes out at once).
"""

from __future__ import annotations

import asyncio
import contextlib
import random
import shutil
import tempfile
import threading
from collections.abc import Awaitable, Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Final, Literal

from manip.captures.tap import TappedLink
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_async, encode_reply, request_op
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, ChaosError, Link, NcpConfig, start_server
from manip.links.api import ChaosServer
from manip.ncp import ConnectionRequested
from manip.ncp.packets import pack_status, unpack_status
from manip.spec.constants import ChaosOp, ServerOp
from manip.spec.model import FieldType

__all__ = [
    "CLIENT_ADDR",
    "JUDGE_ADDR",
    "Mangle",
    "ServerSide",
    "Wire",
    "WireRecord",
    "scenario_in_thread",
    "serve_scenario",
]

JUDGE_ADDR: Final = 0o440
CLIENT_ADDR: Final = 0o401
END_WAIT: Final = 3.0
"""Seconds the script's end waits for the client to close before the server lets go."""

Script = Callable[["ServerSide"], Awaitable[None]]


@dataclass(frozen=True)
class WireRecord:
    t: float
    dir: Literal["c2s", "s2c"]
    packet: Packet


@dataclass
class Mangle:
    """What the tap does to the server's packets on the way out (CHUDP scenarios)."""

    duplicate: float = 0.0
    """Probability of sending a packet twice."""
    reorder: float = 0.0
    """Probability of holding a packet back until after the next one."""
    rng: random.Random = field(default_factory=random.Random)


class Wire:
    """The tap: records every packet with the loop's time, and mangles the server's if asked."""

    def __init__(self, mangle: Mangle | None = None) -> None:
        self.records: list[WireRecord] = []
        self.mangle = mangle
        self.links: list[TappedLink] = []
        self.window: int | None = None
        """The window every OPN and STS the server sends carries instead of its NCP's (None: its NCP's)."""
        self.status_held_until: float = 0.0
        """STS packets sent before this time of the loop's clock go out only then."""
        self._loop = asyncio.get_running_loop()
        self._t0 = self._loop.time()

    def since_start(self, loop_time: float) -> float:
        """A time of the loop's clock as seconds on this wire's clock."""
        return loop_time - self._t0

    def clock_ns(self) -> int:
        return int((self._loop.time() - self._t0) * 1e9)

    def wrap(self, link: Link) -> Link:
        tapped = _JudgeLink(link, self)
        self.links.append(tapped)
        return tapped

    def loop_time(self) -> float:
        return self._loop.time()

    def link_opened(self, link: TappedLink) -> None:
        pass

    def packet_sent(self, link: TappedLink, packet: Packet, next_hop: int | None, t_ns: int) -> None:
        self.records.append(WireRecord(t_ns / 1e9, "s2c", packet))

    def packet_received(self, link: TappedLink, packet: Packet, t_ns: int) -> None:
        self.records.append(WireRecord(t_ns / 1e9, "c2s", packet))

    def link_closed(self, link: TappedLink, reason: str, t_ns: int) -> None:
        pass

    def c2s(self) -> list[Packet]:
        return [r.packet for r in self.records if r.dir == "c2s"]

    def s2c(self) -> list[Packet]:
        return [r.packet for r in self.records if r.dir == "s2c"]


class _JudgeLink(TappedLink):
    """The server's link as the tap sees it: offers the scenario's window, holds STS packets while
    told to, and on CHUDP duplicates and reorders outgoing data packets (the NCP above must still
    deliver them once, in order)."""

    def __init__(self, inner: Link, tap: Wire) -> None:
        super().__init__(inner, tap)
        self.wire = tap
        self._held: tuple[Packet, int | None] | None = None
        self._held_status: list[tuple[Packet, int | None]] = []

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        wire = self.wire
        if packet.opcode in (ChaosOp.STS, ChaosOp.OPN) and wire.window is not None:
            status = unpack_status(packet.data)
            if status is not None:
                packet = packet.with_(data=pack_status(status[0], wire.window) + packet.data[4:])
        if packet.opcode == ChaosOp.STS and wire.loop_time() < wire.status_held_until:
            if not self._held_status:
                asyncio.get_running_loop().call_at(wire.status_held_until, self._release_status)
            self._held_status.append((packet, next_hop))
            return True
        mangle = wire.mangle
        if mangle is None or packet.opcode < ChaosOp.DAT:  # control packets go straight through
            return super().send(packet, next_hop)
        if self._held is None and mangle.rng.random() < mangle.reorder:
            self._held = (packet, next_hop)
            asyncio.get_running_loop().call_later(0.05, self._flush)
            return True
        sent = super().send(packet, next_hop)
        if mangle.rng.random() < mangle.duplicate:
            super().send(packet, next_hop)
        self._flush()
        return sent

    def _flush(self) -> None:
        held, self._held = self._held, None
        if held is not None and not self.inner.is_closed:
            super().send(*held)

    def _release_status(self) -> None:
        held, self._held_status = self._held_status, []
        for packet, next_hop in held:
            if not self.inner.is_closed:
                self.send(packet, next_hop)


class ServerSide:
    """What a scenario's script uses to play the Puma on one connection."""

    def __init__(self, conn: ChaosConnection, wire: Wire, rng: random.Random) -> None:
        self.conn = conn
        self.wire = wire
        self.random = rng
        self.requests: list[Packet] = []
        self.notes: list[str] = []
        self.segment = 0
        """The last segment number given out."""

    @property
    def rfc_number(self) -> int:
        """The packet number of the RFC that opened the connection (what the initial RESPONSE carries)."""
        return _rfc_number(self.wire)

    @property
    def last_number(self) -> int:
        """The number of the last request received (what asynchronous packets carry)."""
        return self.requests[-1].packet_no if self.requests else 0

    async def next_request(self, timeout: float = 10.0) -> Packet | None:
        """The client's next data packet, or None when the connection ends or nothing comes in time."""
        try:
            async with asyncio.timeout(timeout):
                packet = await self.conn.receive()
        except (TimeoutError, ChaosError):
            return None
        self.requests.append(packet)
        return packet

    async def arrived(self, timeout: float = 10.0, count: int = 1) -> bool:
        """Wait until ``count`` packets are there to take, without taking (so without acknowledging)
        them; False when the connection ends or they do not all come in time."""
        conn = self.conn
        arrived = await self._until(lambda: conn.pending >= count or conn.ended, timeout)
        return arrived and conn.pending >= count

    async def send(self, opcode: int, data: bytes) -> int:
        return await self.conn.send(data, opcode)

    async def reply(self, request: Packet, **values: object) -> None:
        """A RESPONSE answering ``request`` with ``values`` by its opcode's reply layout."""
        op = request_op(request.opcode)
        await self.send(ServerOp.RESPONSE, encode_reply(op.opcode, request.packet_no, **values))

    async def reply_payload(self, request: Packet, payload: bytes) -> None:
        """A RESPONSE answering ``request`` with ``payload`` after the request number, as given."""
        await self.send(ServerOp.RESPONSE, request.packet_no.to_bytes(2, "little") + payload)

    async def error(self, opcode: int, number: int, error: ErrorMessage, *, align: bool = True) -> None:
        """An error packet (0201, 0202, 0204, 0205) with ``error``, its numbers padded to a word or not."""
        await self.send(opcode, number.to_bytes(2, "little") + error.encode(align_args=align))

    async def async_response(self, code: int, word2: int, word3: int, number: int | None = None) -> None:
        n = self.last_number if number is None else number
        await self.send(ServerOp.ASYNCHRONOUS_RESPONSE, encode_async(n, code, word2, word3))

    async def text_reply(self, request: Packet, chunks: Sequence[bytes]) -> None:
        """A multi-packet reply: each chunk of text in its own RESPONSE, then the empty terminator."""
        number = request.packet_no.to_bytes(2, "little")
        for chunk in chunks:
            await self.send(ServerOp.RESPONSE, number + chunk)
        await self.send(ServerOp.RESPONSE, number)

    def close_now(self, reason: str) -> None:
        """End the connection at once with a CLS carrying ``reason``."""
        self.conn.abort(reason)

    def _opn(self) -> Packet | None:
        """The OPN the server sent (it gives the connection's hosts and indexes)."""
        return next(
            (r.packet for r in self.wire.records if r.dir == "s2c" and r.packet.opcode == ChaosOp.OPN), None
        )

    def send_los(self, reason: str) -> bool:
        """Send the client a LOS for this connection, as an NCP that lost it would; False when the OPN
        (which gives the indexes) was not recorded."""
        return self.send_raw(ChaosOp.LOS, reason.encode("latin-1"))

    def send_raw(self, opcode: int, data: bytes = b"", *, packet_no: int = 0, ack_no: int = 0) -> bool:
        """Put a Chaos packet for this connection on the link as it is, around the server's NCP (stray
        control packets, illegal opcodes, numbers of its own); False when the OPN (which gives the
        indexes) was not recorded."""
        opn = self._opn()
        if opn is None or not self.wire.links:
            return False
        packet = Packet(
            opcode,
            dest_host=opn.dest_host,
            dest_index=opn.dest_index,
            src_host=opn.src_host,
            src_index=opn.src_index,
            packet_no=packet_no & 0xFFFF,
            ack_no=ack_no & 0xFFFF,
            data=data,
        )
        return self.wire.links[0].send(packet)

    async def hold(self, seconds: float) -> None:
        """Take nothing for ``seconds``: the client's requests stay unacknowledged and unanswered (the
        server's driver acknowledges a packet when the script takes it)."""
        await asyncio.sleep(seconds)

    def delay_status(self, seconds: float) -> None:
        """Hold every STS the server sends in the next ``seconds``; they go out, in order, after."""
        self.wire.status_held_until = self.wire.loop_time() + seconds

    def offer_window(self, window: int) -> bool:
        """Offer the client ``window`` from now on: every STS carries it, and one goes out at once
        (acknowledging what the server last acknowledged); False when there is no OPN to address it."""
        self.wire.window = window
        opn = self._opn()
        if opn is None or not self.wire.links:
            return False
        sent = [r.packet for r in self.wire.records if r.dir == "s2c"]
        ack = next((p.ack_no for p in reversed(sent) if _carries_ack(p)), opn.ack_no)
        statuses = [unpack_status(p.data) for p in sent if p.opcode == ChaosOp.STS]
        receipt = next((st[0] for st in reversed(statuses) if st is not None), ack)
        sts = Packet(
            ChaosOp.STS,
            dest_host=opn.dest_host,
            dest_index=opn.dest_index,
            src_host=opn.src_host,
            src_index=opn.src_index,
            ack_no=ack,
            data=pack_status(receipt, window),
        )
        return self.wire.links[0].send(sts)

    def drop_link(self) -> None:
        """Drop the link under the connection (the client sees it lost, no CLS)."""
        for link in self.wire.links:
            link.close()

    async def serve_plainly(self, until_end: float = END_WAIT) -> None:
        """Answer whatever comes next as a conformant server would, until the client closes (after its
        EOF, wait for its CLS: a server that closed first would keep the client from sending it)."""
        while (request := await self.next_request(until_end)) is not None:
            await plain_answer(self, request)
        await self.until_ended(until_end)

    async def until_ended(self, timeout: float) -> bool:
        """Wait until the connection has ended (the client's CLS, a LOS, the link); False on timeout."""
        conn = self.conn
        return await self._until(lambda: conn.ended, timeout)

    async def _until(self, condition: Callable[[], bool], timeout: float) -> bool:
        """Wait, woken by the connection at each change, until ``condition()`` holds; False on timeout."""
        event = asyncio.Event()
        self.conn.set_wakeup(event.set)
        try:
            async with asyncio.timeout(timeout):
                while not condition():
                    event.clear()
                    await event.wait()
        except TimeoutError:
            return False
        finally:
            self.conn.set_wakeup(None)
        return True


async def plain_answer(side: ServerSide, request: Packet) -> None:
    """A plain conformant answer: zeros of the right layout, segment numbers counting from 1."""
    try:
        op = request_op(request.opcode)
    except KeyError:
        await side.error(
            ServerOp.NON_FATAL_ERROR,
            request.packet_no,
            ErrorMessage("PUMA", "C", "UOP", "Unknown opcode ~", (request.opcode,)),
        )
        return
    kind = op.response.form
    if kind == "done":
        await side.reply_payload(request, b"")
    elif kind == "segment":
        side.segment = (side.segment + 1) & 0xFFFF
        await side.reply_payload(request, side.segment.to_bytes(2, "little"))
    elif kind == "multi":
        await side.text_reply(request, [b'((:brand-name "judge"))'])
    else:
        values = {f.name: zero_value(f.type) for f in op.response.data.fields}
        await side.reply(request, **values)


def zero_value(ft: FieldType) -> object:
    """A zero of a spec field type (for plain answers)."""
    if ft.element == "counted":
        return []
    count = ft.count or 1
    zero: object = 0.0 if ft.element == "float" else 0
    return zero if count == 1 else [zero] * count


@dataclass
class Listener:
    """One case's listening judging server."""

    server: ChaosServer
    wire: Wire
    address: str
    done: asyncio.Event
    script_error: list[BaseException]
    sides: list[ServerSide]
    socket_dir: str | None = None
    """The temporary directory of the chaosd socket (link chaosd), removed at close."""

    async def aclose(self) -> None:
        with contextlib.suppress(Exception):
            async with asyncio.timeout(2.0):
                await self.server.aclose()
        if self.socket_dir is not None:
            shutil.rmtree(self.socket_dir, ignore_errors=True)


async def serve_scenario(
    link: str,
    script: Script,
    *,
    rng: random.Random,
    contact: str = "PUMA",
    ncp: NcpConfig | None = None,
    refuse: str | None = None,
    mangle: Mangle | None = None,
    initial: bool = True,
    offer: int | None = None,
) -> Listener:
    """Listen on a fresh loopback port for one case; the first connection runs ``script``.  ``offer``:
    the window the server's OPN and STS packets offer from the start, when it differs from the receive
    window of its NCP (``ncp.window``, what it really accepts)."""
    wire = Wire(mangle)
    wire.window = offer
    done = asyncio.Event()
    errors: list[BaseException] = []
    sides: list[ServerSide] = []

    async def handler(conn: ChaosConnection) -> None:
        side = ServerSide(conn, wire, rng)
        sides.append(side)
        try:
            if initial:
                await side.send(ServerOp.RESPONSE, _rfc_number(wire).to_bytes(2, "little"))
            await script(side)
        except ChaosError as exc:
            side.notes.append(f"the connection ended under the script: {exc}")
        except Exception as exc:  # a bug of the scenario: reported, never a hang
            errors.append(exc)
        finally:
            done.set()

    def policy(_request: ConnectionRequested) -> str | None:
        if refuse is not None:
            done.set()
        return refuse

    socket_dir = None
    if link == "chaosd":  # the judge stands in for the chaosd daemon the client dials
        socket_dir = tempfile.mkdtemp(prefix="manip-judge-")
        where = f"{socket_dir}/chaosd.sock"
    else:
        where = "127.0.0.1:0"
    address = f"{link}://{where}?addr={JUDGE_ADDR:o}&me={CLIENT_ADDR:o}"
    server = await start_server(
        address,
        contact,
        handler,
        options=ncp,
        policy=policy,
        wrap_link=wire.wrap,
        chaosd_daemon=socket_dir is not None,
    )
    if socket_dir is None:
        where = f"127.0.0.1:{server.port}"
    address = f"{link}://{where}?me={CLIENT_ADDR:04o}&addr={JUDGE_ADDR:04o}"
    if contact != "PUMA":
        address += f"&contact={contact}"
    return Listener(server, wire, address, done, errors, sides, socket_dir)


@contextlib.contextmanager
def scenario_in_thread(
    link: str, script: Script, *, rng: random.Random, initial: bool = True
) -> Iterator[Listener]:
    """:func:`serve_scenario` on an event loop of its own thread, for a caller that blocks meanwhile (a
    client under test in the main thread, or a process it waits for).  Yields the listener; at the end
    the listener is closed, its tasks cancelled and the loop and thread stopped."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    try:
        serving = serve_scenario(link, script, rng=rng, initial=initial)
        listener = asyncio.run_coroutine_threadsafe(serving, loop).result(10)
        try:
            yield listener
        finally:
            with contextlib.suppress(Exception):
                asyncio.run_coroutine_threadsafe(listener.aclose(), loop).result(10)
    finally:
        for task in asyncio.all_tasks(loop):
            loop.call_soon_threadsafe(task.cancel)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)
        if not thread.is_alive():
            loop.close()


def _carries_ack(packet: Packet) -> bool:
    return packet.opcode in (ChaosOp.OPN, ChaosOp.STS) or packet.opcode >= ChaosOp.DAT


def _rfc_number(wire: Wire) -> int:
    for record in reversed(wire.records):
        if record.dir == "c2s" and record.packet.opcode == ChaosOp.RFC:
            return record.packet.packet_no
    return 0
