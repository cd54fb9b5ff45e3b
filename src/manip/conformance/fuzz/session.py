"""One Chaos connection driven by hand, for a batch of fuzz inputs.

The fuzzer cannot use an NCP of its own for the connection it fuzzes over: an NCP would renumber,
retransmit and window for it.  :class:`FuzzConnection` does the least a peer must do and nothing else:

* **Opening**: RFC from an index of ours until OPN, as the NCP cases open
  (:func:`~manip.conformance.suite.rawchaos.rfc_until_open`: a CLS saying busy is retried, the
  previous batch's connection may still be closing), an STS acknowledging it, and the initial RESPONSE.
* **Sending**: requests numbered in order, never more than the target's window ahead of its last
  acknowledgement (a packet past the window would be dropped, and its request look unanswered).  A
  stalled window is probed with SNS.  Packets placed wrongly on purpose (:class:`~.steps.ConnPacket`)
  are sent by :meth:`send_relative` and never counted as requests.
* **Receiving**: the target's controlled packets in order (duplicates of retransmissions dropped),
  acknowledged by the ack field of our requests and by STS when half our window is used, or at once
  while we wait.  A *lazy* request (a pipeline that does not read) acknowledges nothing until the
  target's window stops us.
* **Recording**: every request and every packet of the target, in order, as
  :class:`~manip.conformance.judge.packets.WirePacket` (CLS, EOF and LOS as close pseudo-packets), for the
  transcript checks; ``origin`` says which input each one belongs to.  A connection the target ends
  with EOF is recorded to its end: :meth:`FuzzConnection.await_close` waits for the CLS that follows
  the EOF (``after_eof``: CLS, LOS, or none), so that an EOF with no CLS after it shows.
* **Answers**: requests are paired with answers by the suite's one rule,
  :class:`~manip.codecs.pairing.ReplyPairing` (erratum ``capture-pairing``: by position, the initial
  RESPONSE the RFC's, a describe-self reply up to its empty packet, the packet after free joint
  answered by one packet; the echoed number is never used to pair), to know when everything sent was
  answered and how long an answer may take: the reply timeout or,
  for an answer that waits for the arm, the allowance of the spec's ``answer_within`` after the
  motion queued before it (erratum ``answer-allowance``).  A free joint the spec answers with done is
  waited for before the next request, so that which packet it discards is not a race.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Protocol

from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.packet import Packet
from manip.codecs.pairing import ReplyPairing
from manip.codecs.pdp11float import unpack_f
from manip.conformance.fuzz.steps import ConnPacket
from manip.conformance.judge.checks import WirePacket, required_refusal
from manip.conformance.suite.context import DEFAULT_CONNECT_TIMEOUT, DEFAULT_REPLY_TIMEOUT, RunOptions
from manip.conformance.suite.rawchaos import KEPT_BAD, MAX_RECEIVED, RawLink, Received, rfc_until_open
from manip.ncp.packets import is_data, pack_status, text, unpack_status
from manip.ncp.seq import seq_add, seq_gt, seq_le, seq_sub
from manip.spec import SPEC
from manip.spec.constants import ANSWER_OPS, ChaosOp, ServerOp
from manip.spec.notation import octal

__all__ = ["Allowance", "FuzzConnection", "Inbox", "Receiver"]

OUR_WINDOW: Final = 64
"""The window we grant the target: packets it may send before we acknowledge."""
PROBE_AFTER: Final = 0.2
"""Seconds of a stalled window before we send SNS to learn the target's acknowledgement."""
LAZY_GRACE: Final = 0.001
"""Seconds a lazy sender waits, its window full, before it reads (acknowledges) what came."""
SETTLE_CAP: Final = 5
"""A wait for answers ends after this many answer budgets even while answers keep coming."""
END_POLL: Final = 0.05
"""Seconds between looks at the link while waiting for the CLS after an EOF (a dropped link wakes
nothing)."""
_EOF_ENDED: Final = "EOF from the target"
_FREE_JOINT: Final = SPEC.request("free-joint").opcode
_SET_SPEED: Final = SPEC.request("set-speed").opcode


class Receiver(Protocol):
    """A connection the inbox hands its packets to."""

    def on_packet(self, packet: Packet, raw: bytes, now: float) -> None: ...


@dataclass
class Inbox:
    """Every packet from the target, on any of the batch's links (the :class:`PacketSink` of each): to
    the connection it names (:meth:`register`), else kept by destination index (the fuzzer gives every
    stray packet a source index of its own, so the answer names it).  Frames that do not decode are
    kept in ``bad``: a target must not send them."""

    connections: dict[int, Receiver] = field(default_factory=dict)
    strays: defaultdict[int, list[tuple[Packet, float]]] = field(default_factory=lambda: defaultdict(list))
    bad: list[tuple[bytes, DecodeError]] = field(default_factory=list)
    on_stray: Callable[[Packet], None] | None = None

    def __post_init__(self) -> None:
        self.arrived = asyncio.Event()

    def register(self, index: int, connection: Receiver) -> None:
        self.connections[index] = connection

    def unregister(self, index: int) -> None:
        self.connections.pop(index, None)

    def deliver(self, packet: Packet, raw: bytes, now: float) -> None:
        conn = self.connections.get(packet.dest_index)
        if conn is not None:
            conn.on_packet(packet, raw, now)
        else:
            self.keep_stray(packet, now)
            if self.on_stray is not None:
                self.on_stray(packet)
        self.arrived.set()

    def keep_stray(self, packet: Packet, now: float) -> None:
        """Keep a packet no connection takes, by its destination index (at most :data:`MAX_RECEIVED` of
        one index: a flood to an index of ours is judged by what came first)."""
        kept = self.strays[packet.dest_index]
        if len(kept) < MAX_RECEIVED:
            kept.append((packet, now))

    def reject(self, raw: bytes, exc: DecodeError) -> None:
        if len(self.bad) < KEPT_BAD:
            self.bad.append((raw[:64], exc))
        self.arrived.set()

    def link_ended(self, link: RawLink) -> None:
        self.arrived.set()

    def clear_strays(self) -> None:
        self.strays.clear()
        self.bad.clear()


@dataclass(frozen=True)
class Allowance:
    """How long answers may take (seconds): the reply timeout, the connect timeout, and the factor on
    every wait for the arm (``--deadline-scale``).  A campaign's is read from its run options
    (:meth:`of`), where those settings are kept."""

    reply: float = DEFAULT_REPLY_TIMEOUT
    connect: float = DEFAULT_CONNECT_TIMEOUT
    scale: float = 1.0

    @classmethod
    def of(cls, options: RunOptions) -> Allowance:
        return cls(options.reply_timeout, options.connect_timeout, options.deadline_scale)


@dataclass
class _Pending:
    request: WirePacket
    number: int
    """The input it belongs to."""
    opcode: int
    arm_wait: float
    sent: float
    discarded: bool = False


class FuzzConnection:
    """A connection to the target over ``link`` from our ``index`` (see the module docstring)."""

    def __init__(
        self, link: RawLink, inbox: Inbox, index: int, allowance: Allowance, *, rfc_no: int = 0
    ) -> None:
        self.link = link
        self.inbox = inbox
        self.index = index
        self.allowance = allowance
        self.rfc_no = rfc_no & 0xFFFF
        self.contact = ""
        """The contact name the RFC asked for (set by :meth:`open`)."""
        self._loop = asyncio.get_running_loop()
        self.t0 = self._loop.time()
        self.server_index = 0
        self.packets: list[WirePacket] = []
        self.origin: dict[int, int] = {}
        """``id`` of each recorded packet -> the input it belongs to (answers: their request's)."""
        self.current = -1
        """The input whose steps are being sent."""
        self.next_no = seq_add(self.rfc_no, 1)
        self.server_ack = self.rfc_no
        self.server_window = 1
        self.received_upto = 0
        self.acked_upto = 0
        self.ended: str | None = None
        self.ended_at: float | None = None
        """When the connection began to end (EOF, CLS or LOS from the target, or our CLS), loop clock."""
        self.stalled = False
        """A wait for an answer or for the window ran out of its allowance."""
        self.after_eof: str | None = None
        """What ended the connection after the target's EOF (:meth:`await_close`): "CLS", "LOS", or
        "none" (the link dropped, or nothing within the reply timeout); None: no EOF, or not waited."""
        self.sts_times: list[float] = []
        self.ahead: Counter[int] = Counter()
        """How many times each controlled packet numbered past the next one expected came (dropped)."""
        self.lost: tuple[int, int] | None = None
        """The number of the packet a ``lose`` step lost, and the input of the step."""
        self._lose: int | None = None
        """The input of a ``lose`` step whose packet has not come yet."""
        self.requests = 0
        self.asynchronous = 0
        """Data packets from the target that answer no request (asynchronous responses, errors, warnings)."""
        self._pairing: ReplyPairing[_Pending | None] = ReplyPairing()
        """Which request each answer is (:mod:`manip.codecs.pairing`); the RFC's tag is None."""
        self._last_request: tuple[int, bytes, int] | None = None
        self._lazy = False
        self._writing = False
        self._sts_due = False
        self._silent = False
        """A :class:`~.steps.Silence` step runs: no receipt goes out (:meth:`silence`)."""
        self._progress = asyncio.Event()
        self._acked_at = self._answered_at = self.t0
        self._answer: asyncio.Future[Received] | None = None
        self._motion_until = 0.0
        self._speed = 1.0

    def __repr__(self) -> str:
        return f"<FuzzConnection {octal(self.index)} -> {octal(self.server_index)} {self.ended or 'open'}>"

    # ------------------------------------------------------------------------------------ opening

    async def open(self, contact: str) -> None:
        """RFC until OPN, then the initial RESPONSE (waited for up to the reply timeout);
        :class:`~manip.conformance.suite.rawchaos.RefusedError` on another answer,
        :class:`~manip.conformance.suite.rawchaos.RawError` on none."""
        self.contact = contact
        rfc = self._rfc()
        self.inbox.register(self.index, self)
        try:
            received = await rfc_until_open(
                lambda: self._send(rfc),
                self._rfc_answer,
                contact=contact,
                timeout=self.allowance.connect,
                ended=lambda: self.link.ended,
            )
        except BaseException:
            self.inbox.unregister(self.index)
            raise
        finally:
            self._answer = None
        answer = received.packet
        self.server_index = answer.src_index
        self.received_upto = self.acked_upto = answer.packet_no
        self._note_ack(answer.ack_no)
        status = unpack_status(answer.data)
        if status is not None:
            self.server_window = max(1, status[1])
        self._sts()
        self.t0 = self._loop.time()
        # The user waits for the initial RESPONSE before relying on replies (connect.initial-response):
        # the first answer is the RFC's, by position.  One that did not come answers nothing.
        self._pairing.rfc(None)
        deadline = self.t0 + self.allowance.reply
        while self._pairing.completed == 0 and self.ended is None and self._loop.time() < deadline:
            await self._wait(deadline - self._loop.time())
        if self._pairing.completed == 0:
            self._pairing = ReplyPairing()

    async def _rfc_answer(self, wait: float) -> Received | None:
        """The target's answer to our RFC within ``wait`` seconds (:meth:`on_packet` gives it), else None."""
        if self.link.ended is not None:
            return None
        self._answer = self._loop.create_future()
        try:
            async with asyncio.timeout(wait):
                return await self._answer
        except TimeoutError:
            return None

    # ------------------------------------------------------------------------------------ sending

    def _send(self, packet: Packet) -> None:
        self.link.send(self.link.forge(packet))

    def _rfc(self) -> Packet:
        """The connection's RFC: sent until the OPN comes, and again by a ``rfc`` step."""
        address = self.link.address
        contact = self.contact.encode("ascii")
        return Packet(ChaosOp.RFC, address.peer_addr, 0, address.my_addr, self.index, self.rfc_no, 0, contact)

    def _packet(
        self, opcode: int, packet_no: int, ack_no: int, data: bytes = b"", src: int | None = None
    ) -> Packet:
        a = self.link.address
        index = self.index if src is None else src
        return Packet(
            opcode, a.peer_addr, self.server_index, a.my_addr, index, packet_no & 0xFFFF, ack_no, data
        )

    def _sts(self) -> None:
        if self._silent:  # a peer gone quiet receipts nothing, and answers no SNS
            return
        if self._writing:  # a frame is going out in pieces: nothing may come between them
            self._sts_due = True
            return
        self.acked_upto = self.received_upto
        self._send(
            self._packet(
                ChaosOp.STS, self.next_no, self.received_upto, pack_status(self.received_upto, OUR_WINDOW)
            )
        )

    def _record(
        self, direction: str, opcode: int, packet_no: int, ack_no: int, data: bytes, number: int
    ) -> WirePacket:
        wp = WirePacket(direction, opcode, packet_no, ack_no, data, self._loop.time() - self.t0)  # type: ignore[arg-type]
        self.packets.append(wp)
        self.origin[id(wp)] = number
        return wp

    def _arm_wait(self, opcode: int) -> float:
        op = SPEC.requests.get(opcode)
        if op is None or op.answer_within is None:
            return 0.0
        queued = max(0.0, self._motion_until - self._loop.time())
        return queued + op.answer_within * self.allowance.scale / self._speed

    async def request(self, opcode: int, data: bytes, *, chunk: int = 0, lazy: bool = False) -> None:
        """Send one request, waiting for room in the target's window; if the connection ends or stalls
        meanwhile it is not sent (``ended``, ``stalled`` say why)."""
        self._lazy = lazy
        if not await self._room():
            return
        number = self.next_no
        self.next_no = seq_add(number, 1)
        ack = self.acked_upto if lazy else self.received_upto
        if not lazy:
            self.acked_upto = ack
        packet = self._packet(opcode, number, ack, data)
        raw = self.link.forge(packet)
        # Recorded before it goes out: its answer may come while a frame in pieces is still being written.
        self.requests += 1
        wp = self._record("c2s", opcode, number, ack, data, self.current)
        well_formed = required_refusal(opcode, data) is None
        pending = _Pending(wp, self.current, opcode, self._arm_wait(opcode), self._loop.time())
        pending.discarded = self._pairing.request(pending, opcode, data)
        self._last_request = (opcode, data, number)
        if chunk and not self.link.datagram:
            self._writing = True
            try:
                for at in range(0, len(raw), chunk):
                    self.link.send(raw[at : at + chunk])
                    await asyncio.sleep(0)
            finally:
                self._writing = False
            if self._sts_due:
                self._sts_due = False
                self._sts()
        else:
            self.link.send(raw)
        if opcode == _FREE_JOINT and well_formed and not pending.discarded:
            await self.settle()  # which packet free joint discards must not be a race

    def send_relative(self, step: ConnPacket) -> int | None:
        """Send a :class:`ConnPacket`; return the source index an answer (LOS) goes back to, if any."""
        if self.ended is not None:
            return None
        opcode, data = step.opcode, step.data
        ack = self.received_upto
        if step.what == "ahead":
            number = seq_add(self.next_no, self.server_window + step.offset - 1)
        elif step.what == "behind":
            number = seq_add(self.next_no, -step.offset)
        elif step.what == "duplicate":
            if self._last_request is None:
                number = seq_add(self.next_no, -1)
            else:
                opcode, data, number = self._last_request
        elif step.what == "rfc":
            self._send(self._rfc())
            return None
        elif step.what == "lose":
            self._lose = self.current
            return None
        elif step.what == "wrong-source":
            bogus = 0xFF00 | (((self.index & 0xFF) ^ (step.offset & 0xFF or 1)) & 0xFF)
            self._send(self._packet(opcode, self.next_no, ack, data, src=bogus))
            return bogus
        else:  # sns, unc: uncontrolled, numbered like an STS
            number = self.next_no
        self._send(self._packet(opcode, number, ack, data))
        return None

    async def _room(self) -> bool:
        """Wait until the target's window has room; False if the connection ended or stalled (no
        acknowledgement within the budget: packets of other kinds do not count, so a target that
        sends but never acknowledges cannot hold the batch)."""
        probed = -math.inf
        blocked = self._loop.time()
        while True:
            if self.ended is not None or self.stalled:
                return False
            outstanding = seq_sub(seq_add(self.next_no, -1), self.server_ack)
            if outstanding < self.server_window:
                return True
            if self._lazy:  # a pipeline that does not read: it reads now, as its window is full
                await self._wait(LAZY_GRACE)
                self._lazy = False
                if self.acked_upto != self.received_upto:
                    self._sts()
                continue
            if self.acked_upto != self.received_upto:
                self._sts()
            since = self._loop.time() - max(self._acked_at, blocked)
            if since >= self._budget():
                self.stalled = True
                return False
            # Everything answered but not acknowledged: the target's ack waits for a timer of its own;
            # an SNS has it in one round trip.  Otherwise probe when nothing came for a while.
            due = 0.0 if not self._outstanding() else PROBE_AFTER
            if since >= due and probed <= self._loop.time() - PROBE_AFTER:
                probed = self._loop.time()
                self._send(self._packet(ChaosOp.SNS, self.next_no, self.received_upto))
            await self._wait(min(PROBE_AFTER, self._budget() - since))

    def _budget(self) -> float:
        """Seconds without progress the head of the queue may take."""
        head = self._head()
        arm = head.arm_wait if head is not None else 0.0
        return max(self.allowance.reply, arm)

    async def _wait(self, timeout: float) -> None:
        self._progress.clear()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, timeout)):
                await self._progress.wait()

    async def settle(self) -> bool:
        """Wait until every request sent is answered (True), or the connection ends or stalls (no
        answer within the budget, or answers that never end: :data:`SETTLE_CAP` budgets in all)."""
        self._lazy = False
        cap = self._loop.time() + SETTLE_CAP * max(
            self._budget(), self.allowance.reply * len(self._outstanding()) / 16
        )
        while (head := self._head()) is not None:
            if self.ended is not None or self.stalled:
                return False
            if self._loop.time() >= cap:
                self.stalled = True
                return False
            if self.acked_upto != self.received_upto:
                self._sts()
            since = self._loop.time() - max(self._answered_at, head.sent)
            budget = self._budget()
            if since >= budget:
                self.stalled = True
                return False
            await self._wait(budget - since)
        if self.acked_upto != self.received_upto:
            self._sts()
        return True

    async def pause(self, seconds: float) -> None:
        """Wait up to ``seconds`` for an asynchronous packet (acknowledging what comes meanwhile)."""
        if self.ended is not None:
            return
        deadline = self._loop.time() + seconds
        seen = self.asynchronous
        while self.asynchronous == seen and self.ended is None and self._loop.time() < deadline:
            if self.acked_upto != self.received_upto:
                self._sts()
            await self._wait(deadline - self._loop.time())

    async def silence(self, seconds: float) -> None:
        """Once every request is answered and receipted, send nothing for ``seconds``: no receipt of what
        comes meanwhile, no STS for the target's SNS probes (what comes is recorded)."""
        if self.ended is not None or not await self.settle():
            return
        self._silent = True
        try:
            await asyncio.sleep(seconds)
        finally:
            self._silent = False

    async def await_close(self) -> None:
        """After an EOF from the target, wait up to the reply timeout for the CLS (or LOS) that ends the
        connection, and say in ``after_eof`` what came.  Nothing to wait for without an EOF."""
        if self.ended != _EOF_ENDED:
            return
        deadline = self._loop.time() + self.allowance.reply
        while self.ended == _EOF_ENDED and self.link.ended is None and self._loop.time() < deadline:
            await self._wait(min(END_POLL, deadline - self._loop.time()))
        ended = self.ended or ""
        self.after_eof = ended[:3] if ended.startswith(("CLS", "LOS")) else "none"

    def skipped(self) -> int | None:
        """The packet number the target skipped, if that shows: the next number expected never came, and
        a packet numbered past it came again (a target sends again every packet not receipted, so the
        one expected would have come again with it, had it been sent)."""
        expected = seq_add(self.received_upto, 1)
        again = any(times > 1 and seq_gt(number, expected) for number, times in self.ahead.items())
        return expected if again else None

    def never_again(self) -> tuple[int, int] | None:
        """The packet a ``lose`` step lost (its number, the step's input), if it never came again."""
        if self.lost is None or seq_le(self.lost[0], self.received_upto):
            return None
        return self.lost

    @property
    def unanswered(self) -> int:
        return len(self._outstanding())

    def _outstanding(self) -> list[_Pending]:
        """The requests not yet fully answered, oldest first."""
        return [p for p in self._pairing.outstanding() if p is not None]

    def _head(self) -> _Pending | None:
        """The oldest request not yet fully answered."""
        return next(iter(self._outstanding()), None)

    def _number(self) -> int:
        """The input a packet from the target now belongs to: the request it would answer's."""
        head = self._head()
        return self.current if head is None else head.number

    def close(self, reason: str = "fuzz batch done") -> None:
        """CLS (best effort, as Chaos closes are) unless the target closed it; over for us."""
        closed = self.ended is not None and self.ended.startswith(("CLS", "LOS"))
        if not closed and self.server_index:
            self._send(self._packet(ChaosOp.CLS, self.next_no, self.received_upto, reason.encode("ascii")))
        self.ended = self.ended or "closed by the fuzzer"
        self.ended_at = self.ended_at or self._loop.time()
        self.inbox.unregister(self.index)

    # ------------------------------------------------------------------------------------ receiving

    def _note_ack(self, ack: int) -> None:
        if seq_gt(ack, self.server_ack) and seq_le(ack, seq_add(self.next_no, -1)):
            self.server_ack = ack
            self._acked_at = self._loop.time()

    def on_packet(self, packet: Packet, raw: bytes, now: float) -> None:
        if self._answer is not None:  # opening: the answer to our RFC
            if not self._answer.done() and packet.opcode in (
                ChaosOp.OPN,
                ChaosOp.CLS,
                ChaosOp.ANS,
                ChaosOp.FWD,
                ChaosOp.LOS,
            ):
                self._answer.set_result(Received(packet, raw, now))
            return
        if packet.src_index != self.server_index and packet.opcode != ChaosOp.OPN:
            self.inbox.keep_stray(packet, now)
            return
        self._progress.set()
        opcode = packet.opcode
        if opcode not in (ChaosOp.LOS, ChaosOp.CLS):
            self._note_ack(packet.ack_no)
        if opcode == ChaosOp.STS:
            self.sts_times.append(now)
            status = unpack_status(packet.data)
            if status is not None:  # its receipt is not an acknowledgement: only acks open the window
                self.server_window = max(1, status[1])
            return
        if is_data(opcode) or opcode == ChaosOp.EOF:
            self._on_controlled(packet, now)
            return
        if opcode in (ChaosOp.CLS, ChaosOp.LOS):
            number = self._number()
            self._record("s2c", opcode, packet.packet_no, packet.ack_no, packet.data, number)
            name = "CLS" if opcode == ChaosOp.CLS else "LOS"
            self.ended = f"{name} from the target: {text(packet.data)!r}"
            self.ended_at = self.ended_at or now
            self.inbox.unregister(self.index)
        elif opcode in (ChaosOp.OPN, ChaosOp.SNS):  # an OPN again: our STS was lost
            self._sts()

    def _on_controlled(self, packet: Packet, now: float) -> None:
        """A data packet or EOF: taken in order (a duplicate of one taken is acknowledged again)."""
        opcode = packet.opcode
        expected = seq_add(self.received_upto, 1)
        if packet.packet_no == expected and self._lose is not None:  # lost on its way: never seen
            self.lost = (packet.packet_no, self._lose)
            self._lose = None
            return
        if packet.packet_no != expected:
            if seq_le(packet.packet_no, self.received_upto):  # a retransmission: our receipt was not seen
                if not self._lazy:  # a lazy reader receipts nothing yet
                    self._sts()
            elif len(self.ahead) < MAX_RECEIVED or packet.packet_no in self.ahead:
                self.ahead[packet.packet_no] += 1
            return
        self.received_upto = expected
        number = self._number()
        wp = self._record("s2c", opcode, packet.packet_no, packet.ack_no, packet.data, number)
        if opcode == ChaosOp.EOF:  # acknowledged at once: the target's CLS waits for that
            self.ended = _EOF_ENDED
            self.ended_at = now
            self._sts()
        elif opcode in ANSWER_OPS:
            self._answered(packet, wp)
        else:
            self.asynchronous += 1
        if not self._lazy and seq_sub(self.received_upto, self.acked_upto) >= OUR_WINDOW // 2:
            self._sts()

    def _answered(self, packet: Packet, wp: WirePacket) -> None:
        """Pair an answer with its request by the one pairing rule (module docstring)."""
        self._answered_at = self._loop.time()
        place = self._pairing.server(packet.opcode, packet.data)
        head = place.request
        if head is None:  # the initial RESPONSE, or an answer to nothing
            return
        self.origin[id(wp)] = head.number
        if not place.final or head.discarded or packet.opcode != ServerOp.RESPONSE:
            return
        op = SPEC.requests.get(head.opcode)
        if op is None:
            return
        if head.opcode == _SET_SPEED:
            with contextlib.suppress(CodecError):
                factor = unpack_f(head.request.data[:4])
                if 0.0 < factor <= 1.0:
                    self._speed = factor
        elif op.response.form == "segment" or (op.hazard == "motion" and op.answer_within is not None):
            segment = SPEC.segment_within * self.allowance.scale / self._speed
            self._motion_until = max(self._motion_until, self._loop.time()) + segment
