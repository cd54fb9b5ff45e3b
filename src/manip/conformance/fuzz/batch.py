"""Sending a batch of fuzz inputs, and the liveness check that follows every batch.

A batch runs on a fresh connection (:class:`~.session.FuzzConnection`) over a fresh link, so each
batch starts from the state a new client finds, and any subset of a batch can be sent again the same
way when a violation is shrunk.  Its steps go out in input order:

* requests on the connection (a new one is opened when the target closes it, after a fatal error);
* packets placed wrongly on the connection's link;
* stray packets on one side link (on CHUDP: the same socket), each from a source index of its own;
  an RFC that is answered with OPN is closed again at once;
* raw bytes on links of their own (on CHUDP: datagrams).

Then the batch waits, within the allowances, until every request is answered, every connection the
target ended with EOF has its CLS, every LOS and RFC answer due has come and every link whose framing
was lost has been dropped, and closes the connection.  What came is judged by :mod:`.judge` after
the liveness check, so late packets that should never have come are seen too.

The liveness check (:func:`liveness`): a new link, a new connection, its initial RESPONSE and one
Here answered.  A target that refuses the link is gone (a crash); one that takes the link but does
not answer in time hangs.
"""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Final, Literal

from manip.codecs.packet import Packet
from manip.conformance.fuzz.session import Allowance, FuzzConnection, Inbox
from manip.conformance.fuzz.steps import (
    ConnPacket,
    FuzzInput,
    Pause,
    Raw,
    Reconnect,
    RequestStep,
    Silence,
    Stray,
)
from manip.conformance.suite.rawchaos import RawError, RawLink, frame, open_link
from manip.links.address import LinkAddress
from manip.spec.constants import ChaosOp, RequestOp

__all__ = ["BatchRun", "BatchRunner", "DueAnswer", "Liveness", "liveness"]

Expect = Literal["los", "answer", "silence", "sts", "close"]
POLL: Final = 0.01
_ANSWERS: Final = frozenset({ChaosOp.OPN, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD})


@dataclass
class DueAnswer:
    """An answer a step is due (or must not get), judged after the batch."""

    number: int
    what: Expect
    clause: str
    key: int
    """los, answer, silence: the destination index the answer carries; sts: the connection's index."""
    since: float
    note: str
    data: bytes
    connection: FuzzConnection | None = None
    """The batch's connection when it was sent (an RFC then finds the robot busy while it is open)."""
    link: RawLink | None = None


@dataclass
class BatchRun:
    """What a batch sent and what came back."""

    inputs: list[FuzzInput]
    connections: list[FuzzConnection] = field(default_factory=list)
    due_answers: list[DueAnswer] = field(default_factory=list)
    counted: int = 0
    """Bad frames the target's links must have counted."""
    open_error: str | None = None
    """Why the batch could not open (or reopen) its connection."""
    stalled: bool = False
    started: float = 0.0
    duration: float = 0.0
    sent_requests: int = 0

    @property
    def last_number(self) -> int:
        return self.inputs[-1].number if self.inputs else -1


@dataclass(frozen=True)
class Liveness:
    alive: bool
    kind: Literal["", "crash", "hang"]
    detail: str
    duration: float


class BatchRunner:
    """Sends batches to the target at ``address``; ``inbox`` takes everything that comes back."""

    def __init__(
        self,
        address: LinkAddress,
        allowance: Allowance,
        *,
        seed: int = 0,
        changes: Mapping[int, Callable[[], Awaitable[None]]] | None = None,
    ) -> None:
        self.address = address
        self.allowance = allowance
        self.changes = dict(changes or {})
        """What changes in the target's world before an input, by its number (the diff's phased
        conditions): awaited once every request sent before the input is answered."""
        self.inbox = Inbox()
        self.inbox.on_stray = self._on_stray
        self.datagram = address.scheme == "chudp"
        self._shared: RawLink | None = None  # CHUDP: one socket for everything
        self._side: RawLink | None = None
        self._held: list[RawLink] = []
        self._rfc_links: dict[int, RawLink] = {}
        self._rng = random.Random(seed)
        self._loop = asyncio.get_running_loop()

    async def link(self) -> RawLink:
        """A new link to the target (on CHUDP the campaign's one socket)."""
        if not self.datagram:
            return await open_link(self.address, self.inbox, self.allowance.connect)
        if self._shared is None or self._shared.ended is not None:
            self._shared = await open_link(self.address, self.inbox, self.allowance.connect)
        return self._shared

    def next_index(self) -> int:
        """An index for a connection of ours: 0xff01-0xffff (stray packets use 0x0100-0xfeff)."""
        return 0xFF00 | self._rng.randrange(1, 0x100)

    async def connect(self, link: RawLink) -> FuzzConnection:
        index = self.next_index()
        while index in self.inbox.connections:
            index = self.next_index()
        conn = FuzzConnection(link, self.inbox, index, self.allowance, rfc_no=self._rng.randrange(0x10000))
        await conn.open(self.address.contact)
        return conn

    def _on_stray(self, packet: Packet) -> None:
        """An OPN answering one of our stray RFCs: close that connection at once (the robot is busy
        with our batch, so a server that opened it serves two clients)."""
        link = self._rfc_links.get(packet.dest_index)
        if packet.opcode == ChaosOp.OPN and link is not None:
            cls = Packet(
                ChaosOp.CLS,
                self.address.peer_addr,
                packet.src_index,
                self.address.my_addr,
                packet.dest_index,
                0,
                packet.packet_no,
                b"fuzz: RFC flood",
            )
            link.send(link.forge(cls))

    async def _side_link(self) -> RawLink:
        if self.datagram:
            return await self.link()
        if self._side is None or self._side.ended is not None:
            self._side = await open_link(self.address, self.inbox, self.allowance.connect)
        return self._side

    # ------------------------------------------------------------------------------------ a batch

    async def run(self, inputs: list[FuzzInput]) -> BatchRun:
        """Send ``inputs`` in order (module docstring) and wait for what is due."""
        run = BatchRun(list(inputs), started=self._loop.time())
        self.inbox.clear_strays()
        self._rfc_links.clear()
        conn: FuzzConnection | None = None
        try:
            conn = await self._open(run)
            for item in inputs:
                if conn is None:
                    break
                conn = await self._input(run, conn, item)
                if conn is not None and conn.stalled:
                    run.stalled = True
                    break
            await self._wait(run)
        finally:
            for c in run.connections:
                c.close()
                if not self.datagram:
                    c.link.close()  # after the CLS, which goes out first
            run.sent_requests = sum(c.requests for c in run.connections)
            run.duration = self._loop.time() - run.started
        return run

    async def _input(self, run: BatchRun, conn: FuzzConnection, item: FuzzInput) -> FuzzConnection | None:
        """Send the steps of one input; the connection it leaves (a new one after the target closed the
        last, None if none could be opened)."""
        change = self.changes.get(item.number)
        if change is not None:
            await conn.settle()
            await change()
        conn.current = item.number
        for index, step in enumerate(item.steps):
            if isinstance(step, RequestStep):
                if conn.ended is not None and not conn.stalled:
                    reopened = await self._open(run)
                    if reopened is None:
                        return None
                    conn = reopened
                    conn.current = item.number
                await conn.request(step.opcode, step.data, chunk=step.chunk, lazy=step.lazy)
            elif isinstance(step, ConnPacket):
                self._relative(run, conn, item, step)
            elif isinstance(step, Stray):
                await self._stray(run, item, index, step, conn)
            elif isinstance(step, Pause):
                await conn.pause(step.seconds)
            elif isinstance(step, Silence):
                await conn.silence(step.seconds)
            elif isinstance(step, Reconnect):
                reopened = await self._reconnect(run, conn, step)
                if reopened is None:
                    return None
                conn = reopened
                conn.current = item.number
            else:
                await self._raw(run, item, step)
        return conn

    async def _reconnect(self, run: BatchRun, conn: FuzzConnection, step: Reconnect) -> FuzzConnection | None:
        """Close ``conn`` once its requests are answered, and open the next connection."""
        if conn.ended is None:
            await conn.settle()
            conn.close("fuzz: a new connection")
        await asyncio.sleep(step.after)
        return await self._open(run)

    async def _open(self, run: BatchRun) -> FuzzConnection | None:
        link: RawLink | None = None
        try:
            link = await self.link()
            conn = await self.connect(link)
        except (RawError, OSError, TimeoutError) as exc:
            if link is not None and not self.datagram:
                link.close()
            run.open_error = f"{type(exc).__name__}: {exc}" if not isinstance(exc, RawError) else str(exc)
            return None
        run.connections.append(conn)
        return conn

    def _relative(self, run: BatchRun, conn: FuzzConnection, item: FuzzInput, step: ConnPacket) -> None:
        since = self._loop.time()
        bogus = conn.send_relative(step)
        if step.what == "rfc":  # the RFC again: nothing from another index of the target may answer it
            run.due_answers.append(
                DueAnswer(item.number, "silence", step.clause, conn.index, since, item.note, step.data, conn)
            )
        elif bogus is not None:
            run.due_answers.append(
                DueAnswer(item.number, "los", step.clause, bogus, since, item.note, step.data, conn)
            )
        elif step.what == "sns" and conn.ended is None:
            run.due_answers.append(
                DueAnswer(item.number, "sts", step.clause, conn.index, since, item.note, step.data, conn)
            )

    async def _stray(
        self, run: BatchRun, item: FuzzInput, index: int, step: Stray, conn: FuzzConnection
    ) -> None:
        try:
            link = await self._side_link()
        except (OSError, TimeoutError) as exc:
            run.open_error = run.open_error or f"the side link did not open: {exc}"
            return
        packet = step.packet
        taken = {c.server_index for c in run.connections if c.ended is None}
        while packet.dest_index and packet.dest_index in taken:
            # By chance, the index of a connection of ours, on another link: the target may take it for
            # that connection's (manip's drops it as from the wrong link), not as a stray.
            packet = packet.with_(dest_index=(packet.dest_index * 7 + 1) & 0xFFFF or 1)
        dest, source = packet.dest_host or self.address.peer_addr, packet.src_host or self.address.my_addr
        packet = packet.with_(dest_host=dest, src_host=source)
        raw = frame(
            packet, datagram=self.datagram, hop=(dest, source), damage=step.damage, chaosd=link.chaosd
        )
        if packet.opcode == ChaosOp.RFC:
            self._rfc_links[packet.src_index] = link
        link.send(raw)
        run.counted += int(step.counted)
        run.due_answers.append(
            DueAnswer(
                item.number,
                step.expect,
                step.clause,
                packet.src_index,
                self._loop.time(),
                item.note,
                raw,
                conn,
            )
        )

    async def _raw(self, run: BatchRun, item: FuzzInput, step: Raw) -> None:
        run.counted += step.counted
        if self.datagram:
            (await self.link()).send(step.data)
            return
        try:
            link = await open_link(self.address, self.inbox, self.allowance.connect)
        except (OSError, TimeoutError) as exc:
            run.open_error = run.open_error or f"a link did not open: {exc}"
            return
        link.send(step.data)
        if step.closes:
            run.due_answers.append(
                DueAnswer(
                    item.number, "close", step.clause, 0, self._loop.time(), item.note, step.data, link=link
                )
            )
            self._held.append(link)
        elif step.hold:
            self._held.append(link)
        else:
            link.close()

    def _due(self, run: BatchRun) -> bool:
        """Whether some LOS, RFC answer or link drop is still due."""
        for e in run.due_answers:
            if e.what == "los" and not _has(self.inbox, e.key, lambda p: p.opcode == ChaosOp.LOS):
                return True
            if e.what == "answer" and not _has(self.inbox, e.key, lambda p: p.opcode in _ANSWERS):
                return True
            if e.what == "close" and e.link is not None and e.link.ended is None:
                return True
            conn = e.connection
            if e.what == "sts" and conn is not None and conn.ended is None and not _sts_since(conn, e.since):
                return True
        return False

    async def _wait(self, run: BatchRun) -> None:
        for conn in run.connections:
            if conn.ended is None and not await conn.settle():
                run.stalled = run.stalled or conn.stalled
            await conn.await_close()  # after an EOF: the CLS that must follow it
        deadline = self._loop.time() + self.allowance.reply
        while self._due(run) and self._loop.time() < deadline:
            self.inbox.arrived.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(POLL):
                    await self.inbox.arrived.wait()

    def finish(self) -> None:
        """Close the side link and the links left open (after the liveness check: late packets count)."""
        for link in self._held:
            link.close(reset=True)
        self._held.clear()
        if self._side is not None:
            self._side.close()
            self._side = None

    def close(self) -> None:
        self.finish()
        if self._shared is not None:
            self._shared.close()
            self._shared = None


def _sts_since(conn: FuzzConnection, since: float) -> bool:
    return any(t >= since for t in conn.sts_times)


def _has(inbox: Inbox, index: int, match: object) -> bool:
    assert callable(match)
    return any(match(p) for p, _ in inbox.strays.get(index, ()))


async def liveness(runner: BatchRunner) -> Liveness:
    """Connect, wait for the initial RESPONSE, ask Here (see the module docstring)."""
    loop = asyncio.get_running_loop()
    started = loop.time()

    def result(alive: bool, kind: Literal["", "crash", "hang"], detail: str) -> Liveness:
        return Liveness(alive, kind, detail, loop.time() - started)

    try:
        link = await runner.link()
    except TimeoutError:
        return result(False, "hang", f"the link did not open within {runner.allowance.connect:g} s")
    except OSError as exc:
        return result(False, "crash", f"the link could not be opened: {exc.strerror or exc}")
    conn: FuzzConnection | None = None
    try:
        try:
            conn = await runner.connect(link)
        except RawError as exc:
            gone = link.ended is not None and "target closed" in link.ended
            return result(False, "crash" if gone else "hang", f"no connection: {exc}")
        await conn.request(RequestOp.HERE, b"")
        if not await conn.settle() and conn.unanswered:
            why = conn.ended or f"not within {runner.allowance.reply:g} s"
            return result(False, "hang", f"Here was not answered ({why})")
        return result(True, "", "connected, Here answered")
    finally:
        if conn is not None:
            conn.close("fuzz liveness check done")
        if not runner.datagram:
            link.close()
