"""The error paths of the emulated DRV-11J link (docs/drv11j.md, manip's own contract): a bad HELLO, a
first frame that is not HELLO, a HELLO of another version, a frame from the wrong side or of an unknown
type, a short TICK, a TICK going backwards, the Puma's BYE, and a second Puma while one is linked.

Each case plays the Puma by hand on a raw TCP connection (the word probe only ever sends good frames),
sends the frame under test followed by a good command and TICK, and judges what Cougar does: it ends the
link (closes the connection), sending nothing after the bad frame but, if it likes, a BYE with its
reason; a Cougar that carried on would answer the TICK that follows.  A BYE that says busy means another
link had not quite ended yet: the case tries again, as the probe does.  What went each way is recorded
in the case's transcript as whole frames (:data:`~manip.conformance.judge.packets.DRV11J_FRAME`), and each
violation names the frames it judged.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.conformance.cases.cougar._support import expect_names
from manip.conformance.cougar.probe import LinkLog, cougar_probe
from manip.conformance.judge.packets import DRV11J_FRAME, WirePacket
from manip.conformance.judge.violation import showing
from manip.conformance.suite.busy import BUSY_DELAY, BUSY_PATIENCE, says_busy
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext
from manip.cougar.link import (
    MAGIC,
    Bye,
    Drv11jError,
    Frame,
    FrameDecoder,
    FrameType,
    Hello,
    Role,
    Tick,
    Ticked,
    Words,
    encode_frame,
    parse_drv11j_address,
)
from manip.spec.constants import CougarCommand

_READ: Final = 1 << 16
EXCHANGE_LINES: Final = 40
"""The most lines of a raw link's exchange a case's report keeps."""
VERS: Final = (int(CougarCommand.VERS), 1)
"""A good command whose answer (VERSION) shows that Cougar ran a tick."""


def raw_frame(kind: int, payload: tuple[int, ...]) -> bytes:
    """A frame's bytes as they are, whatever they say (the codec refuses to write bad ones)."""
    words = (kind, len(payload), *payload)
    return b"".join(w.to_bytes(2, "little") for w in words)


def _carry_on(index: int, time: float) -> bytes:
    """A good command and TICK ``index`` at ``time``: a Cougar that did not end the link answers them."""
    return encode_frame(Words(Role.PUMA, VERS)) + encode_frame(Tick(index, time))


@dataclass
class CougarLinkSeen:
    """What Cougar sent on one raw link: its frames, whether it closed, and a stream it sent that did not
    decode."""

    frames: list[Frame] = field(default_factory=list)
    ended: bool = False
    garbage: str = ""
    after: int = 0
    """How many of ``frames`` came before the frame under test was sent."""
    sent: list[bytes] = field(default_factory=list)
    """What the case wrote on the link, as written (frames the codec would refuse among them)."""
    log: LinkLog = field(default_factory=lambda: LinkLog(None, DRV11J_FRAME))
    records: list[WirePacket] = field(default_factory=list)
    """The record of each of ``frames`` in the case's transcript."""
    garbage_record: WirePacket | None = None
    """The record of the data that did not decode."""

    def send(self, writer: asyncio.StreamWriter, chunk: bytes) -> None:
        """Write ``chunk`` on the link and record it."""
        writer.write(chunk)
        self.sent.append(chunk)
        self.log.record("c2s", int.from_bytes(chunk[:2], "little"), 0, chunk)

    def received(self, frames: list[Frame]) -> None:
        """Frames that came from Cougar, recorded."""
        for frame in frames:
            data = encode_frame(frame)
            self.frames.append(frame)
            self.records.append(self.log.record("s2c", int.from_bytes(data[:2], "little"), 0, data))

    def shown(self, frames: Sequence[Frame], text: str) -> object:
        """Evidence: ``text`` about ``frames`` (some of :attr:`frames`), naming their records, or the last
        record of the link when there are none."""
        chosen = [r for f, r in zip(self.frames, self.records, strict=True) if any(f is g for g in frames)]
        return showing(chosen or self.records[-1:] or self.log.last(), text)

    def transcript(self) -> str:
        """The exchange in the order it went, as a passing case's report keeps it (at most
        :data:`EXCHANGE_LINES` lines)."""
        lines = [f"-> {chunk.hex(' ', 2)}" for chunk in self.sent[:1]]
        lines += [f"<- {frame}" for frame in self.frames[: self.after]]
        lines += [f"-> {chunk.hex(' ', 2)}" for chunk in self.sent[1:]]
        lines += [f"<- {frame}" for frame in self.frames[self.after :]]
        lines.append("<- (closed)" if self.ended else "(still open)")
        shown = lines[:EXCHANGE_LINES]
        more = len(lines) - len(shown)
        return "\n".join(shown) + (f"\n... {more} more" if more else "")

    @property
    def later(self) -> list[Frame]:
        return self.frames[self.after :]

    def busy(self) -> bool:
        return any(isinstance(f, Bye) and says_busy(f.reason) for f in self.frames)


async def _read_until(
    reader: asyncio.StreamReader,
    decoder: FrameDecoder,
    link: CougarLinkSeen,
    done: type | None,
    timeout: float,
) -> None:
    """Read Cougar's frames into ``link`` until one of type ``done`` is among them (None: until it closes)
    or ``timeout`` seconds pass."""
    loop = asyncio.get_running_loop()
    give_up = loop.time() + timeout
    while not (done is not None and any(isinstance(f, done) for f in link.frames)):
        left = give_up - loop.time()
        if left <= 0:
            return
        try:
            data = await asyncio.wait_for(reader.read(_READ), left)
        except TimeoutError:
            return
        except OSError:
            data = b""
        if not data:
            link.ended = True
            return
        try:
            link.received(decoder.feed(data))
        except Drv11jError as exc:
            link.garbage = str(exc)
            link.garbage_record = link.log.record("s2c", int.from_bytes(data[:2], "little"), 0, data)
            return


async def _once(ctx: CaseContext, first: bytes | None, bad: bytes) -> CougarLinkSeen:
    """One raw link: Cougar's HELLO, then ``first`` (a good HELLO and a tick whose TICKED is awaited) or
    nothing, then ``bad``; Cougar's frames until it closes or the reply timeout passes."""
    host, port = parse_drv11j_address(ctx.options.address)
    timeout = ctx.options.reply_timeout
    try:
        async with asyncio.timeout(ctx.options.connect_timeout):
            reader, writer = await asyncio.open_connection(host, port)
    except (OSError, TimeoutError) as exc:
        ctx.fail(
            f"DRV-11J link to {ctx.options.address}: cannot connect",
            clause="link.drv11j.framing",
            expected="Cougar accepting a link",
            seen=str(str(exc) or type(exc).__name__),
        )
    link, decoder = CougarLinkSeen(log=LinkLog(ctx, DRV11J_FRAME)), FrameDecoder()
    try:
        await _read_until(reader, decoder, link, Hello, timeout)
        if first is not None:
            link.send(writer, first)
            await _read_until(reader, decoder, link, Ticked, timeout)
        link.after = len(link.frames)
        if not link.ended:
            if not link.busy():
                link.send(writer, bad)
            await _read_until(reader, decoder, link, None, timeout)
    finally:
        writer.close()
        with contextlib.suppress(OSError, TimeoutError):
            await asyncio.wait_for(writer.wait_closed(), timeout)
    return link


async def run_link(ctx: CaseContext, first: bytes | None, bad: bytes) -> CougarLinkSeen:
    """:func:`_once`, again while Cougar says busy (a previous link still ending) for a while."""
    loop = asyncio.get_running_loop()
    give_up = loop.time() + BUSY_PATIENCE
    while True:
        link = await _once(ctx, first, bad)
        if not link.busy() or loop.time() >= give_up:
            return link
        await asyncio.sleep(BUSY_DELAY)


GOOD_START: Final = encode_frame(Hello(Role.PUMA)) + _carry_on(0, 0.0)
"""A good HELLO, a command and tick 0 at time 0 (Cougar moves the first tick of a link past its clock)."""


@dataclass(frozen=True)
class BadFrame:
    """One error path: the case's id and summary, the clause it judges, whether the bad frame is the
    first one (in place of HELLO), its bytes, and what it is (for the report).  ``then_hello``: a good
    HELLO follows a bad first frame, for a Cougar that dropped it; a Cougar that took the bad frame as
    its greeting answers the TICK after it, which a second HELLO would stop first."""

    name: str
    clause: str
    summary: str
    first: bool
    bad: bytes
    what: str
    then_hello: bool = True


_BAD_FRAMES: Final = (
    BadFrame(
        "bad-hello",
        "link.drv11j.bad-frame-ends",
        "A first frame that is HELLO with the wrong magic word ends the link.",
        True,
        raw_frame(FrameType.HELLO, (MAGIC ^ 0xFFFF, 1, int(Role.PUMA))),
        "after a HELLO with the wrong magic word",
    ),
    BadFrame(
        "hello-wrong-role",
        "link.drv11j.bad-frame-ends",
        "A HELLO naming the Cougar's own role (a Cougar at the other end) ends the link.",
        True,
        encode_frame(Hello(Role.COUGAR)),
        "after a HELLO naming role Cougar",
    ),
    BadFrame(
        "not-hello-first",
        "link.drv11j.hello-first",
        "A link whose first frame is a command (PUMA), with no HELLO before it, ends.",
        True,
        encode_frame(Words(Role.PUMA, VERS)),
        "after a PUMA frame (then TICK 1) with no HELLO before it",
        then_hello=False,
    ),
    BadFrame(
        "hello-other-version",
        "link.drv11j.hello-version",
        "A first frame that is HELLO of version 2 (the framing is version 1) ends the link.",
        True,
        encode_frame(Hello(Role.PUMA, version=2)),
        "after a HELLO of version 2",
        then_hello=False,
    ),
    BadFrame(
        "wrong-side",
        "link.drv11j.bad-frame-ends",
        "A COUGAR frame (words only Cougar sends) from the Puma ends the link.",
        False,
        encode_frame(Words(Role.COUGAR, (8, 1))),
        "after a COUGAR frame from the Puma",
    ),
    BadFrame(
        "unknown-type",
        "link.drv11j.bad-frame-ends",
        "A frame of an unknown type (9) ends the link.",
        False,
        raw_frame(9, (1,)),
        "after a frame of type 9",
    ),
    BadFrame(
        "short-tick",
        "link.drv11j.bad-frame-ends",
        "A TICK of 4 payload words (6 are the frame's) ends the link.",
        False,
        raw_frame(FrameType.TICK, (1, 0, 0, 0)),
        "after a TICK of 4 words",
    ),
    BadFrame(
        "tick-backwards",
        "link.drv11j.tick-backwards",
        "A TICK half a second earlier than the one before it on the link ends the link.",
        False,
        encode_frame(Tick(1, -0.5)),
        "after TICK 1 at -0.5 s, following TICK 0 at 0 s",
    ),
    BadFrame(
        "bye",
        "link.drv11j.bye",
        "After the Puma's BYE Cougar runs nothing more of the link and closes it.",
        False,
        encode_frame(Bye("conformance case: the link ends here")),
        "after the Puma's BYE",
    ),
)


@case.each(_BAD_FRAMES)
def _bad_frame_case(row: BadFrame) -> None:
    async def ends(ctx: CaseContext) -> None:
        # a Cougar that carried on would take the good HELLO (after a bad first frame) and answer the tick
        hello = row.first and row.then_hello
        trailer = (encode_frame(Hello(Role.PUMA)) if hello else b"") + _carry_on(1, 1.0)
        link = await run_link(ctx, None if row.first else GOOD_START, row.bad + trailer)
        judge_ending(ctx, link, row.clause, row.what)

    case(
        f"cougar.link.{row.name}",
        clauses=[row.clause, "link.drv11j.framing"],
        summary=row.summary,
        hazard="config",
    )(ends)


def judge_ending(ctx: CaseContext, link: CougarLinkSeen, clause: str, what: str) -> None:
    """Cougar said a good HELLO, sent nothing but BYE after the frame under test, and closed."""
    ctx.note("DRV-11J exchange (-> Puma to Cougar as raw bytes, <- Cougar to Puma):\n" + link.transcript())
    ctx.expect(
        not link.garbage,
        clause="link.drv11j.framing",
        expected="every frame from Cougar well formed",
        seen=showing(link.garbage_record, link.garbage),
    )
    ctx.expect(
        bool(link.frames) and link.frames[0] == Hello(Role.COUGAR),
        clause="link.drv11j.framing",
        expected="Cougar's HELLO (version 1, role Cougar) first",
        seen=link.shown(link.frames[:1], str(link.frames[:1])),
    )
    others = [f for f in link.later if not isinstance(f, Bye)]
    ctx.expect(
        not others,
        clause=clause,
        expected=f"{what}: nothing from Cougar but, at most, BYE with its reason",
        seen=link.shown(others, "; ".join(str(f) for f in others[:4])),
    )
    ctx.expect(
        link.ended,
        clause=clause,
        expected=f"{what}: Cougar closes the link within {ctx.options.reply_timeout:g} s",
        seen=link.shown(link.later, f"still open; it sent {[str(f) for f in link.later][:4]}"),
    )


@case(
    "cougar.link.busy",
    clauses=["link.drv11j.busy", "link.drv11j.framing", "cougar.vers.reply"],
    hazard="config",
)
async def link_busy(ctx: CaseContext) -> None:
    """While one Puma is linked, a second connection gets HELLO then BYE saying busy and is closed, and
    the first link carries on."""
    async with cougar_probe(ctx) as probe:
        second = await _once(ctx, None, b"")
        byes = [f for f in second.frames if isinstance(f, Bye)]
        ctx.expect(
            bool(second.frames) and second.frames[0] == Hello(Role.COUGAR),
            clause="link.drv11j.framing",
            expected="Cougar's HELLO first, on the second connection too",
            seen=second.shown(second.frames[:1], str(second.frames[:1])),
        )
        ctx.expect(
            any(says_busy(b.reason) for b in byes),
            clause="link.drv11j.busy",
            expected="BYE with a reason that says busy on a second connection while a link is up",
            seen=second.shown(second.frames[1:4], f"frames {[str(f) for f in second.frames[1:4]]}"),
        )
        ctx.expect(
            second.ended,
            clause="link.drv11j.busy",
            expected=f"the second connection closed by Cougar within {ctx.options.reply_timeout:g} s",
            seen=second.shown(second.frames, "still open"),
        )
        reply = await probe.call("VERS", version=1)
        expect_names(
            ctx,
            [reply],
            ["VERSION"],
            clause="link.drv11j.busy",
            expected="the first link carrying on: VERS answered with VERSION",
        )
