"""A word-level probe of a Cougar over the emulated DRV-11J, for the Cougar cases of ``manip-conform``.

Theory of operation
===================

The probe plays the Puma's end of the link (``docs/drv11j.md``) in lock step, so a case knows exactly
which words Cougar had when each of its clock ticks ran:

* :meth:`CougarProbe.open` connects, exchanges HELLO and runs one empty tick; a Cougar that answers it
  with BYE ``busy`` (still serving the previous case's link) is retried for a short while.
* :meth:`CougarProbe.send` encodes a Table 1 command by name (``manip.codecs.cougar``) and sends its
  words; :meth:`CougarProbe.send_words` sends any words at all (for split or unknown commands).
* :meth:`CougarProbe.run` sends TICKs one at a time, waiting for each TICKED (``reply_timeout``), and
  returns the responses that became complete: Cougar's words are reassembled across frames and ticks by
  one response :class:`~manip.codecs.cougar.WordStream`, so each :class:`WordReply` carries its decoded
  message, the raw words and the tick that completed it.  Words that do not make a Table 1 response
  become a :class:`WordReply` with a ``problem`` (unknown response code, undecodable float).  A lone
  out-of-sync code word (2) left at the end of a tick is the whole message (erratum
  cougar-out-of-sync): a :class:`WordReply` named OUT-OF-SYNC with no data.
* :meth:`CougarProbe.reply` waits, ticking, for the next response (``within`` ticks); :meth:`call` is
  send + reply; :meth:`examine` reads Cougar memory with EXMN.

What went each way is recorded in the case's transcript (:class:`LinkLog`), as the Chaos probe records
its packets: the words of each command frame sent and of each response received, so a violation names
the exchange it judged (:attr:`WordReply.packets`: the response, then the command before it) and the
report shows it.  The log is bounded as a Chaos probe's is: a case that takes more than
:data:`~manip.conformance.suite.context.MAX_CASE_PACKETS` responses from Cougar ends failed.

Tick times come from one clock per process (:data:`TICK_CLOCK`): the monotonic clock, but always at
least one 60 Hz period after the previous tick sent, so a target that keeps its state across links (as
``manip-cougar`` does) never sees time go backwards.  A failure of the link raises
:class:`~manip.conformance.suite.case.CaseFailure` (``closed`` or ``timeout``, clause ``link.drv11j.framing``;
no response in time: ``cougar.word-link``), attributed to the ``cougar-link`` invariant whatever the
case declares.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections import deque
from collections.abc import AsyncIterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, Literal

from manip.codecs.cougar import CougarMsg, CougarValue, Malformed, OutOfSync, WordStream, encode
from manip.codecs.pdp11float import words_to_f
from manip.conformance.judge.packets import DRV11J, Direction, WirePacket
from manip.conformance.judge.violation import Violation
from manip.conformance.suite.busy import BUSY_DELAY, BUSY_PATIENCE, says_busy
from manip.conformance.suite.case import CaseFailure
from manip.conformance.suite.context import MAX_CASE_PACKETS, CaseContext
from manip.conformance.suite.invariants import COUGAR_LINK
from manip.cougar.link import Drv11jError, PumaEnd, parse_drv11j_address
from manip.spec.constants import CougarResponse
from manip.spec.model import CougarMessage
from manip.spec.notation import octal_words

__all__ = [
    "DEFAULT_WITHIN",
    "TICK_CLOCK",
    "CougarProbe",
    "LinkEvent",
    "LinkLog",
    "TickClock",
    "WordReply",
    "cougar_liveness",
    "cougar_probe",
    "floats_of",
    "layout_words",
    "words_bytes",
]

DEFAULT_WITHIN: Final = 4
"""Ticks a response may take: Cougar answers in the tick that runs the command; allow a slower one."""
_READ: Final = 1 << 16
_TRANSCRIPT_NOTE: Final = 40


def words_bytes(words: Sequence[int]) -> bytes:
    """Words as they travel on the link (little-endian), for a failure's ``data``."""
    return b"".join((w & 0xFFFF).to_bytes(2, "little") for w in words)


class TickClock:
    """Tick times: monotonic, never less than one period after the previous one (see module doc)."""

    period: float = 1.0 / 60.0

    def __init__(self) -> None:
        self.last: float | None = None

    def next(self, gap: float | None = None) -> float:
        """The next tick's time; ``gap`` forces it that long after the previous tick (re-entry tests)."""
        now = time.monotonic()
        if self.last is None:
            t = now
        elif gap is not None:
            t = self.last + gap
        else:
            t = max(now, self.last + self.period)
        t = round(t * 1e6) / 1e6  # the TICK frame carries microseconds
        self.last = t
        return t


TICK_CLOCK: Final = TickClock()


class LinkLog:
    """What went each way on one DRV-11J link, recorded in the case's transcript as
    :class:`~manip.conformance.judge.packets.WirePacket` records of ``link`` (:data:`DRV11J` by
    default), numbered as the case's next connection; without a case (the liveness probe) nothing is
    kept.  Bounded as a Chaos probe's recording: past :data:`MAX_CASE_PACKETS` records from Cougar the
    case ends failed."""

    def __init__(self, ctx: CaseContext | None, link: str = DRV11J) -> None:
        self._ctx = ctx
        self.link = link
        self.connection = 1 + max((p.connection for p in ctx.transcript), default=-1) if ctx else 0
        self.last_sent: WirePacket | None = None
        """The last record of what went to Cougar (what a response answers)."""

    def record(self, direction: Direction, code: int, tick: int, data: bytes) -> WirePacket:
        """One record: ``code`` the first word (a Table 1 code, a frame type), ``tick`` the probe's tick."""
        ctx = self._ctx
        when = ctx.clock() if ctx is not None else 0.0
        number = tick & 0xFFFF
        packet = WirePacket(direction, code & 0xFFFF, number, 0, data, when, self.connection, self.link)
        if direction == "c2s":
            self.last_sent = packet
        if ctx is None:
            return packet
        ctx.transcript.append(packet)
        if direction == "s2c":
            ctx.received += 1
            if ctx.received > MAX_CASE_PACKETS:
                raise CaseFailure(
                    Violation(
                        f"Cougar sent more than {MAX_CASE_PACKETS:,} responses within one case; the "
                        "suite reads no more",
                        "cougar.word-link",
                        expected=f"at most {MAX_CASE_PACKETS:,} responses for one case's commands",
                        actual=f"{ctx.received - 1:,} responses, and more coming",
                        kind="unexpected_message",
                        invariant=COUGAR_LINK.name,
                        packet=packet,
                    )
                )
        return packet

    def last(self) -> tuple[WirePacket, ...]:
        """The last record of the case (what a check of the link's state judged), or none."""
        ctx = self._ctx
        return ctx.judged() if ctx is not None else ()


@dataclass(frozen=True)
class WordReply:
    """One response from Cougar: decoded (``message``) or not (``problem`` says why)."""

    tick: int
    """The probe's tick number that completed it (0 is the empty tick of :meth:`CougarProbe.open`)."""
    words: tuple[int, ...]
    message: CougarMsg | None
    problem: str = ""
    bare: str = ""
    """The name of a response recognised without its data (a lone out-of-sync code word)."""
    record: WirePacket | None = field(default=None, compare=False, repr=False)
    """Its record in the case's transcript."""
    command: WirePacket | None = field(default=None, compare=False, repr=False)
    """The record of the last words sent to Cougar before it (the command it answers)."""

    @property
    def packets(self) -> tuple[WirePacket, ...]:
        """The exchange it closes, as evidence names it: this response, then the command before it."""
        return tuple(p for p in (self.record, self.command) if p is not None)

    @property
    def code(self) -> int:
        return self.words[0] if self.words else -1

    @property
    def name(self) -> str:
        if self.bare:
            return self.bare
        return self.message.name if self.message is not None else f"code {self.code}"

    @property
    def values(self) -> dict[str, CougarValue]:
        return dict(self.message.values) if self.message is not None else {}

    def floats(self) -> tuple[float, ...]:
        """Every float of the response, in order (NTD, FORCES)."""
        out: list[float] = []
        for value in self.values.values():
            items = value if isinstance(value, tuple) else (value,)
            out += [float(v) for v in items if isinstance(v, float)]
        return tuple(out)

    @property
    def data_words(self) -> tuple[int, ...]:
        return self.words[1:]

    @property
    def data(self) -> bytes:
        """The words as they travel on the link (a failure's bytes)."""
        return words_bytes(self.words)

    def __str__(self) -> str:
        head = self.name if not self.problem else f"{self.name} ({self.problem})"
        return f"{head}: {octal_words(self.words)}"


@dataclass(frozen=True)
class LinkEvent:
    """What crossed the link: words either way, or a tick."""

    direction: Literal["puma", "cougar", "tick"]
    tick: int
    words: tuple[int, ...] = ()
    time: float = 0.0

    def __str__(self) -> str:
        if self.direction == "tick":
            return f"TICK #{self.tick} at {self.time:.6f}"
        arrow = "->" if self.direction == "puma" else "<-"
        return f"{arrow} {octal_words(self.words)}"


class CougarProbe:
    """The Puma's end of one DRV-11J link, in lock step; see the module docstring."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        end: PumaEnd,
        *,
        address: str,
        reply_timeout: float,
        clock: TickClock = TICK_CLOCK,
        log: LinkLog | None = None,
    ) -> None:
        self.address = address
        self.reply_timeout = reply_timeout
        self.clock = clock
        self.log = log or LinkLog(None)
        """The records of the link in the case's transcript."""
        self.events: deque[LinkEvent] = deque(maxlen=_TRANSCRIPT_NOTE)
        """The last link events (ticks included), for the case's notes."""
        self.event_count = 0
        self._reader = reader
        self._writer = writer
        self._end = end
        self._stream = WordStream("response")
        self._inbox: list[WordReply] = []
        self._ticks = 0

    # ------------------------------------------------------------------------------------ opening
    @classmethod
    async def open(
        cls,
        address: str,
        *,
        reply_timeout: float,
        connect_timeout: float,
        busy_wait: float = BUSY_PATIENCE,
        ctx: CaseContext | None = None,
    ) -> CougarProbe:
        """Connect, exchange HELLO, run one empty tick; a busy Cougar is retried for ``busy_wait`` s.
        With ``ctx`` the link is recorded in the case's transcript (:class:`LinkLog`)."""
        host, port = parse_drv11j_address(address)
        loop = asyncio.get_running_loop()
        give_up = loop.time() + busy_wait
        while True:
            try:
                async with asyncio.timeout(connect_timeout):
                    reader, writer = await asyncio.open_connection(host, port)
            except (OSError, TimeoutError) as exc:
                raise _link_failure(address, f"cannot connect: {exc or type(exc).__name__}") from exc
            end = PumaEnd()
            probe = cls(reader, writer, end, address=address, reply_timeout=reply_timeout, log=LinkLog(ctx))
            writer.write(end.hello())
            try:
                await probe.run(1)
            except CaseFailure:
                await probe.close()
                if says_busy(end.closed) and loop.time() < give_up:
                    await asyncio.sleep(BUSY_DELAY)
                    continue
                raise
            probe._inbox.clear()  # replies to the empty tick are in the log only
            return probe

    async def close(self) -> None:
        """End the link with BYE (quietly: the target may be gone)."""
        writer = self._writer
        if writer.is_closing():
            return
        with contextlib.suppress(Exception):
            writer.write(self._end.bye("conformance case done"))
        writer.close()
        with contextlib.suppress(Exception):
            async with asyncio.timeout(1.0):
                await writer.wait_closed()

    # ------------------------------------------------------------------------------------ sending
    async def send(self, name: str, **values: Any) -> tuple[int, ...]:
        """Encode Table 1 command ``name`` with ``values`` and send its words; returns them."""
        words = tuple(encode("command", name, **values))
        await self.send_words(words)
        return words

    async def send_words(self, words: Sequence[int]) -> None:
        """Send exactly these words (any split of any commands, known or not)."""
        if not words:
            return
        self._check_open()
        self._event(LinkEvent("puma", self._ticks, tuple(words)))
        self.log.record("c2s", words[0], self._ticks, words_bytes(words))
        self._writer.write(self._end.send(words))

    def _event(self, event: LinkEvent) -> None:
        self.events.append(event)
        self.event_count += 1

    # ------------------------------------------------------------------------------------ ticking
    @property
    def ticks(self) -> int:
        """Ticks run so far on this link (the next tick's number)."""
        return self._ticks

    async def run(self, ticks: int = 1, *, gap: float | None = None) -> list[WordReply]:
        """Run ``ticks`` clock ticks; the responses completed by them (and any not taken before)."""
        for _ in range(ticks):
            await self._tick(gap)
        return self.take()

    def take(self) -> list[WordReply]:
        """The responses received and not yet taken."""
        out, self._inbox = self._inbox, []
        return out

    async def reply(self, what: str, *, within: int = DEFAULT_WITHIN) -> WordReply:
        """The next response, ticking up to ``within`` times for it; CaseFailure (timeout) if none."""
        for _ in range(within + 1):
            if self._inbox:
                return self._inbox.pop(0)
            if _ == within:
                break
            await self._tick(None)
        pending = self.pending_words
        sent = self.log.last_sent
        raise CaseFailure(
            Violation(
                f"no response from Cougar to {what} within {within} ticks",
                "cougar.word-link",
                expected=f"a response to {what} within {within} ticks",
                actual=f"no whole response: {len(pending)} word(s) came that make no Table 1 response "
                f"yet: {octal_words(pending)}"
                if pending
                else "nothing",
                kind="timeout",
                invariant=COUGAR_LINK.name,
                packets=() if sent is None else (sent,),
            )
        )

    async def call(self, name: str, *, within: int = DEFAULT_WITHIN, **values: Any) -> WordReply:
        """Send command ``name`` and wait for the next response."""
        words = await self.send(name, **values)
        return await self.reply(f"{name} ({octal_words(words)})", within=within)

    async def examine(self, address: int, count: int, *, within: int = DEFAULT_WITHIN) -> WordReply:
        """EXMN ``count`` words at byte ``address``: the raw reply (the case judges it)."""
        return await self.call("EXMN", address=address, count=count, within=within)

    async def _tick(self, gap: float | None) -> None:
        self._check_open()
        index = self._ticks
        now = self.clock.next(gap)
        self._event(LinkEvent("tick", index, (), now))
        self._writer.write(self._end.tick(now))
        self._ticks += 1
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.reply_timeout
        while self._end.ticks_done <= index:
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise CaseFailure(
                    f"Cougar did not finish tick #{index} within {self.reply_timeout:g} s",
                    clause="link.drv11j.framing",
                    expected=f"TICKED #{index}",
                    actual="nothing (timeout)",
                    kind="timeout",
                    invariant=COUGAR_LINK.name,
                )
            try:
                async with asyncio.timeout(remaining):
                    data = await self._reader.read(_READ)
            except TimeoutError:
                continue
            except OSError as exc:
                raise _link_failure(self.address, f"the link broke: {exc}") from exc
            if not data:
                raise _link_failure(self.address, self._end.closed or "Cougar closed the link")
            try:
                words = self._end.receive(data)
            except Drv11jError as exc:
                raise _link_failure(self.address, f"bad DRV-11J stream: {exc}") from exc
            if words:
                self._event(LinkEvent("cougar", index, tuple(words)))
                self._decode(index, words)
            if self._end.closed is not None and self._end.ticks_done <= index:
                raise _link_failure(self.address, f"Cougar ended the link: {self._end.closed}")
        self._bare_out_of_sync(index)
        if self._end.ticks_done != index + 1:
            raise CaseFailure(
                Violation(
                    f"Cougar answered TICK #{index} with TICKED #{self._end.ticks_done - 1}",
                    "link.drv11j.framing",
                    expected=f"TICKED #{index}",
                    actual=f"TICKED #{self._end.ticks_done - 1}",
                    invariant=COUGAR_LINK.name,
                    packets=self.log.last(),
                )
            )

    def _decode(self, tick: int, words: Sequence[int]) -> None:
        for item in self._stream.feed(words):
            if isinstance(item, CougarMsg):
                message, got, problem = item, item.words, ""
            elif isinstance(item, OutOfSync):
                message, got, problem = None, item.discarded, f"{item.code} is no Table 1 response code"
            else:
                assert isinstance(item, Malformed)
                message, got, problem = None, item.words, str(item.error)
            record = self._recorded(tick, got)
            self._inbox.append(
                WordReply(tick, got, message, problem, record=record, command=self.log.last_sent)
            )

    def _recorded(self, tick: int, words: Sequence[int]) -> WirePacket:
        """A response's words recorded in the log."""
        return self.log.record("s2c", words[0] if words else 0, tick, words_bytes(words))

    def _bare_out_of_sync(self, tick: int) -> None:
        """A lone out-of-sync code word left at the end of a tick is the whole message (B.7 gives the
        message no layout; Table 1's code 2 with the offending word is manip's, erratum
        cougar-out-of-sync): everything a tick produced comes before its TICKED, and nothing follows the
        dump of the input buffer in that tick."""
        if self._stream.pending != (CougarResponse.OUT_OF_SYNC,):
            return
        self._stream = WordStream("response")
        words = (int(CougarResponse.OUT_OF_SYNC),)
        record = self._recorded(tick, words)
        self._inbox.append(
            WordReply(tick, words, None, bare="OUT-OF-SYNC", record=record, command=self.log.last_sent)
        )

    def _check_open(self) -> None:
        if self._end.closed is not None or self._writer.is_closing():
            raise _link_failure(self.address, self._end.closed or "the link is closed")

    # ------------------------------------------------------------------------------------ reporting
    @property
    def pending_words(self) -> tuple[int, ...]:
        """Response words received that do not yet make a whole response."""
        return self._stream.pending

    def transcript(self, last: int = _TRANSCRIPT_NOTE) -> str:
        """The last ``last`` link events, one a line."""
        shown = list(self.events)[-last:]
        earlier = self.event_count - len(shown)
        head = [f"... {earlier} earlier events"] if earlier else []
        return "\n".join(head + [str(e) for e in shown])


def layout_words(message: CougarMessage) -> str:
    """A Table 1 message's words as a failure states them: ``words: 2, code`` (the code word's value,
    then each field, a float counting two words, counted words their count first)."""
    parts = [str(message.code)]
    for f in message.data:
        if f.count is None:
            parts.append(f"count, {f.name}...")
        elif f.words == 1:
            parts.append(f.name)
        else:
            parts.append(f"{f.name} ({f.words} words)")
    return "words: " + ", ".join(parts)


def floats_of(words: Sequence[int]) -> tuple[float, ...]:
    """Pairs of words as F floats (sign/exponent word first); a reserved operand reads as NaN."""
    out: list[float] = []
    for i in range(0, len(words) - 1, 2):
        try:
            out.append(words_to_f(words[i], words[i + 1]))
        except ValueError:
            out.append(float("nan"))
    return tuple(out)


def _link_failure(address: str, why: str) -> CaseFailure:
    return CaseFailure(
        f"DRV-11J link to {address}: {why}",
        clause="link.drv11j.framing",
        expected="the link to stay up and every TICK answered with TICKED",
        actual=why,
        kind="closed",
        invariant=COUGAR_LINK.name,
    )


@contextlib.asynccontextmanager
async def cougar_probe(ctx: CaseContext) -> AsyncIterator[CougarProbe]:
    """A probe on the run's Cougar (``ctx.options.address``) for the block; closed after it.  The last
    link events go to the case's notes whatever its outcome (a passing case's, so that what it checked
    can be audited; within the same bound as a failing one's)."""
    options = ctx.options
    probe = await CougarProbe.open(
        options.address,
        reply_timeout=options.reply_timeout,
        connect_timeout=options.connect_timeout,
        ctx=ctx,
    )
    try:
        yield probe
    finally:
        ctx.note(
            "DRV-11J exchange (-> Puma to Cougar, <- Cougar to Puma, octal words):\n" + probe.transcript()
        )
        await probe.close()


async def cougar_liveness(address: str, *, reply_timeout: float, connect_timeout: float) -> tuple[bool, str]:
    """Whether a Cougar answers at ``address``: HELLO, then one tick answered with TICKED."""
    try:
        probe = await CougarProbe.open(address, reply_timeout=reply_timeout, connect_timeout=connect_timeout)
    except CaseFailure as exc:
        return False, exc.actual or exc.message
    await probe.close()
    return True, "HELLO exchanged and a tick answered"
