"""The target's Chaos NCP, tested from below with hand-made packets (:mod:`manip.conformance.suite.rawchaos`).

These cases open the target's link themselves and drive the connection by hand: they choose the
indices and packet numbers, decide what to acknowledge and when, and look at every packet the target
sends.  They run on ``tcp://`` and ``chudp://`` targets (skipped on ``chaosd://``).

Timing bounds are generous multiples of the erratum ``ncp-timers`` (retransmit after 0.5 s): any NCP
that retransmits at least every second (ITS 0.5 s, the MIT UNIX NCP 1 s) passes, with room for a slow
target; ``--deadline-scale`` stretches them further.  A case that waits for silence ("no LOS in answer
to a LOS") waits :data:`QUIET` seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

from manip.codecs.messages import encode_request
from manip.codecs.packet import MAX_DATA, Packet
from manip.conformance.cases._support import host_delay
from manip.conformance.judge.checks import WirePacket
from manip.conformance.judge.violation import missing, showing
from manip.conformance.suite.case import CaseFailure, case
from manip.conformance.suite.context import CaseContext, RunOptions
from manip.conformance.suite.rawchaos import (
    Direction,
    RawConnection,
    RawError,
    RawPeer,
    Received,
    RefusedError,
    format_packet,
)
from manip.links.address import parse_address
from manip.ncp.packets import is_data, unpack_status
from manip.ncp.seq import seq_add, seq_ge, seq_gt, seq_sub
from manip.spec import SPEC
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

RETRANSMIT_BOUND: Final = 3.0
"""Seconds within which an unreceipted packet must come again (6x the erratum's 0.5 s, 3x UNIX's 1 s)."""
LOS_BOUND: Final = 2.0
"""Seconds within which a LOS must answer a packet for a connection that does not exist."""
QUIET: Final = 1.0
"""Seconds of silence that show a packet drew no answer."""
IN_FLIGHT: Final = 0.25
"""A copy sent just before our receipt arrived may still come this long after it."""
PROGRESS_BOUND: Final = 3.0
"""Seconds within which a target sends again once our acknowledgement opened its window."""
WINDOW: Final = 2
"""The receive window the window case announces."""
WINDOW_REQUESTS: Final = 4
"""Requests the window case sends at once."""
RAW_CONNECTION: Final = 90
"""``WirePacket.connection`` of packets a raw peer recorded (probes count from 0)."""
ILLEGAL_OPCODES: Final = (0o17, 0o100, 0o177)
"""Opcodes outside 001-016 and 0200-0377 (0177 is cbridge's private ACK, not a Chaos opcode)."""

_HERE: Final = SPEC.request("here")


# ------------------------------------------------------------------------------------------ helpers


def _scale(ctx: CaseContext, seconds: float) -> float:
    return seconds * max(1.0, ctx.options.deadline_scale)


def _frames(*frames: bytes) -> bytes:
    """The frames that show a failure, one after the other (what we sent, then what came)."""
    return b"".join(frames)


def _lines(items: Sequence[Received]) -> str:
    if not items:
        return "nothing"
    shown = "; ".join(f"{format_packet(r.packet)} at {r.time:.2f} s" for r in items[:6])
    return shown + (f"; and {len(items) - 6} more" if len(items) > 6 else "")


async def _open(ctx: CaseContext) -> RawPeer:
    """A raw peer on the target's link, recording into the case's transcript."""
    address = parse_address(ctx.options.address)
    if address.framing not in ("tcp", "chudp"):
        ctx.not_judged(
            f"the case sends raw Chaos packets, on tcp://, unix:// and chudp:// links, not "
            f"{address.scheme}://: the same server reached over one of those would be judged"
        )
    ctx.auto_check = False  # the transcript holds Chaos control packets, not a manip session

    def record(direction: Direction, p: Packet, raw: bytes) -> None:
        packet = WirePacket(direction, p.opcode, p.packet_no, p.ack_no, p.data, ctx.clock(), RAW_CONNECTION)
        ctx.transcript.append(packet)

    try:
        return await RawPeer.open(
            address, on_packet=record, clock=ctx.clock, timeout=ctx.options.connect_timeout
        )
    except RawError as exc:
        raise CaseFailure(
            f"could not open the link: {exc}",
            expected="the target's link to open",
            actual=str(exc),
            kind="closed",
        ) from exc


def _index(ctx: CaseContext, taken: Sequence[int] = ()) -> int:
    """A random connection index for our side (low byte non-zero, distinct from ``taken``)."""
    while True:
        index = ctx.random.randrange(0x0101, 0xFFFF)
        if index & 0xFF and index not in taken:
            return index


async def _handshake(ctx: CaseContext, peer: RawPeer, index: int, packet_no: int) -> RawConnection:
    try:
        return await peer.handshake(index, packet_no, timeout=_scale(ctx, ctx.options.connect_timeout))
    except RefusedError as exc:
        raise CaseFailure(
            f"the target refused our RFC: {exc}",
            expected="OPN in answer to the RFC",
            actual=format_packet(exc.answer.packet),
            data=exc.answer.raw,
            kind="closed",
        ) from exc
    except RawError as exc:
        raise CaseFailure(
            f"no OPN: {exc}", expected="OPN in answer to the RFC", actual=str(exc), kind="timeout"
        ) from exc


async def _next_data(ctx: CaseContext, peer: RawPeer, conn: RawConnection, after: int, what: str) -> Received:
    """The first data packet of ``conn`` numbered beyond ``after`` (copies of older ones are skipped)."""
    wait = _scale(ctx, max(ctx.options.reply_timeout, PROGRESS_BOUND))
    got = await peer.receive(
        lambda p: conn.mine(p) and is_data(p.opcode) and seq_gt(p.packet_no, after), wait
    )
    if got is None:
        ctx.fail(
            f"no {what} within {wait:g} s",
            expected=f"{what} (a data packet numbered after #{after}) on the connection opened by hand",
            seen=missing(f"nothing; other packets: {_lines(peer.inbox)}"),
        )
    return got


def _request(conn: RawConnection, *, ack: int) -> Packet:
    """Send one Here request (read-only) on ``conn``."""
    return conn.data(encode_request("here"), opcode=_HERE.opcode, ack=ack)


# ------------------------------------------------------------------------------------------ LOS


@case("server.ncp.los-unknown-connection", clauses=["ncp.los"], technique="negative", deadline=12.0)
async def los_unknown_connection(ctx: CaseContext) -> None:
    """A data packet for a connection that does not exist draws a LOS; a LOS or CLS to one draws nothing."""
    async with await _open(ctx) as peer:
        index = _index(ctx)
        to_lose = _index(ctx, (index,))
        to_close = _index(ctx, (index, to_lose))
        bogus = _index(ctx, (index, to_lose, to_close))
        number, ack = ctx.random.randrange(0x10000), ctx.random.randrange(0x10000)
        probe = peer.packet(
            ChaosOp.DAT, dest_index=bogus, src_index=index, packet_no=number, ack_no=ack, data=b"?"
        )
        frame = peer.send(probe)
        wait = _scale(ctx, LOS_BOUND)
        answer = await peer.receive(lambda p: p.dest_index == index, wait)
        if answer is None:
            ctx.fail(
                "no LOS for a data packet to a connection that does not exist",
                clause="ncp.los",
                expected=f"LOS to index {octal(index)} within {wait:g} s",
                seen=missing("nothing" + (f" ({peer.ended})" if peer.ended else ""), after=frame),
            )
        los = answer.packet
        ctx.expect(
            los.opcode == ChaosOp.LOS,
            clause="ncp.los",
            expected=f"LOS answering {format_packet(probe)}",
            seen=showing(answer.raw, format_packet(los)),
        )
        ctx.note(f"LOS: {format_packet(los)}")
        if (los.packet_no, los.ack_no, los.src_index) != (number, ack, bogus):
            ctx.note(
                "the LOS does not reflect the packet (AIM 628 keeps its packet and ack numbers and "
                f"swaps the indices): sent pkt#{number} ack#{ack} to {octal(bogus)}"
            )

        silent: list[tuple[str, bytes, int]] = []
        for opcode, src in ((ChaosOp.LOS, to_lose), (ChaosOp.CLS, to_close)):
            p = peer.packet(opcode, dest_index=bogus, src_index=src, data=b"no such connection here")
            silent.append((opcode.name, peer.send(p), src))
        late = await peer.collect(_scale(ctx, QUIET), lambda p: p.dest_index in (to_lose, to_close))
        if late:
            name, sent, _ = next(s for s in silent if s[2] == late[0].packet.dest_index)
            ctx.fail(
                f"a {name} to a connection that does not exist was answered",
                clause="ncp.los",
                expected=f"no answer to a {name} (never a LOS in answer to a LOS or CLS)",
                seen=showing(_frames(sent, late[0].raw), _lines(late)),
            )


def _illegal_frame_check(
    ctx: CaseContext, answer: Received | None, sent: Packet, frame: bytes, why: str, clause: str
) -> None:
    """The answer to an illegal packet must be a LOS: ``clause`` is the rule the packet broke (an illegal
    opcode, more than 488 data bytes), which says so as well as ``ncp.los`` does."""
    if answer is None:
        ctx.fail(
            f"no LOS for {why}",
            clause=clause,
            expected=f"LOS to index {octal(sent.src_index)} within {_scale(ctx, LOS_BOUND):g} s",
            seen=missing("nothing", after=frame),
        )
    ctx.expect(
        answer.packet.opcode == ChaosOp.LOS,
        clause=clause,
        expected=f"LOS answering {why}",
        seen=showing(_frames(frame, answer.raw), format_packet(answer.packet)),
    )
    ctx.note(f"{why}: {format_packet(answer.packet)}")


@case(
    "server.ncp.los-illegal-opcode",
    clauses=["ncp.los", "chaos.opcode.legal"],
    technique="negative",
    deadline=20.0,
)
async def los_illegal_opcode(ctx: CaseContext) -> None:
    """A packet with an illegal opcode on an open connection draws a LOS."""
    async with await _open(ctx) as peer:
        index = _index(ctx)
        conn = await _handshake(ctx, peer, index, ctx.random.randrange(0x10000))
        conn.sts(ack=conn.opn_no, window=5)
        for opcode in ILLEGAL_OPCODES:
            number = conn.next_packet_no
            p = conn.packet(opcode, packet_no=number, ack_no=conn.opn_no, data=b"xy")
            frame = peer.send_forged(p)
            answer = await peer.receive(
                lambda q: (
                    q.dest_index == index
                    and not is_data(q.opcode)
                    and q.opcode not in (ChaosOp.STS, ChaosOp.SNS, ChaosOp.OPN)
                ),
                _scale(ctx, LOS_BOUND),
            )
            _illegal_frame_check(ctx, answer, p, frame, f"opcode {octal(opcode)}", "chaos.opcode.legal")


@case(
    "server.ncp.los-oversize", clauses=["ncp.los", "chaos.data.max-488"], technique="negative", deadline=12.0
)
async def los_oversize(ctx: CaseContext) -> None:
    """A CHUDP packet with more than 488 data bytes draws a LOS (TCP frames cannot carry one)."""
    if parse_address(ctx.options.address).scheme != "chudp":
        ctx.skip(
            "only a CHUDP datagram can carry more than 488 data bytes (see server.negative.oversize-frame)"
        )
    async with await _open(ctx) as peer:
        index = _index(ctx)
        conn = await _handshake(ctx, peer, index, ctx.random.randrange(0x10000))
        conn.sts(ack=conn.opn_no, window=5)
        p = conn.packet(
            ChaosOp.DAT, packet_no=conn.next_packet_no, ack_no=conn.opn_no, data=bytes(MAX_DATA + 2)
        )
        frame = peer.send_forged(p)
        answer = await peer.receive(
            lambda q: q.dest_index == index and q.opcode in (ChaosOp.LOS, ChaosOp.CLS), _scale(ctx, LOS_BOUND)
        )
        _illegal_frame_check(ctx, answer, p, frame, f"{MAX_DATA + 2} data bytes", "chaos.data.max-488")


# ------------------------------------------------------------------------------------------ duplicate RFC


@case("server.ncp.duplicate-rfc", clauses=["ncp.duplicate-rfc"], technique="scripted", deadline=20.0)
async def duplicate_rfc(ctx: CaseContext) -> None:
    """A repeated RFC (same host, index and number) goes to the connection it opened, not a second one.

    The duplicate is sent twice: while the OPN is unacknowledged (the usual case: the OPN was lost) and
    once the connection is open.  Either may be ignored or answered with the same OPN again; another
    OPN (a second connection) or a refusal fails, and the first connection must go on serving."""
    async with await _open(ctx) as peer:
        index = _index(ctx)
        conn = await _handshake(ctx, peer, index, ctx.random.randrange(0x10000))
        ctx.note(f"OPN: {format_packet(conn.opn.packet)}")

        async def duplicate(when: str) -> None:
            frame = peer.send(conn.rfc)
            seen = await peer.collect(
                _scale(ctx, QUIET),
                lambda p: (
                    p.dest_index == index
                    and p.opcode not in (ChaosOp.STS, ChaosOp.SNS)
                    and not is_data(p.opcode)
                ),
            )
            for r in seen:
                p = r.packet
                same = p.opcode == ChaosOp.OPN and p.src_index == conn.remote_index
                if same and p.packet_no != conn.opn_no:
                    ctx.note(f"the OPN sent again {when} has a new packet number: {format_packet(p)}")
                if not same:
                    second = p.opcode == ChaosOp.OPN
                    ctx.fail(
                        f"the duplicate RFC {when} "
                        + ("opened a second connection" if second else "was treated as a new request"),
                        clause="ncp.duplicate-rfc",
                        expected=f"nothing, or the OPN from index {octal(conn.remote_index)} again",
                        seen=showing(_frames(frame, r.raw), format_packet(p)),
                    )

        await duplicate("before the OPN was acknowledged")
        conn.sts(ack=conn.opn_no, window=5)
        initial = await _next_data(ctx, peer, conn, conn.opn_no, "initial RESPONSE after our STS")
        conn.sts(ack=initial.packet.packet_no, window=5)
        await duplicate("on the open connection")
        request = _request(conn, ack=initial.packet.packet_no)
        reply = await _next_data(
            ctx, peer, conn, initial.packet.packet_no, "reply to Here after the duplicate RFCs"
        )
        ctx.expect(
            reply.packet.data[:2] == request.packet_no.to_bytes(2, "little"),
            clause="ncp.duplicate-rfc",
            expected=f"the first connection still serving: a reply quoting request #{request.packet_no}",
            seen=showing(reply.raw, format_packet(reply.packet)),
        )
        conn.sts(ack=reply.packet.packet_no, window=5)


# ------------------------------------------------------------------------------------------ broken


def broken_slack(broken_after: float) -> float:
    """Seconds beyond the target's timer before the broken case looks: timers run on a coarse clock
    (the ITS NCP checks its connections every few seconds)."""
    return max(2.0, 0.25 * broken_after)


def _broken_wait(options: RunOptions) -> float:
    if options.broken_after is None:
        return 0.0
    return options.broken_after + broken_slack(options.broken_after)


@case(
    "server.ncp.broken",
    clauses=["ncp.broken"],
    technique="scripted",
    deadline=15.0,
    waits=_broken_wait,
)
async def broken(ctx: CaseContext) -> None:
    """A connection whose client falls silent is given up after the target's timer: a packet on it
    then draws a LOS, and the robot is free for a new connection.

    Runs only with ``--broken-after SECONDS`` (the target's timer: 90 on manip's NCP, the ITS NCP's
    interval; the 1985 guide sets none, erratum ncp-timers), as it spends that long in silence.  Our side
    answers nothing, not even the target's SNS probes."""
    after = ctx.options.broken_after
    if after is None:
        ctx.not_judged("it waits out the target's broken-connection timer: run with --broken-after SECONDS")
    async with await _open(ctx) as peer:
        index = _index(ctx)
        conn = await _handshake(ctx, peer, index, ctx.random.randrange(0x10000))
        conn.sts(ack=conn.opn_no, window=5)  # the connection is open on both sides; now silence
        silent_from = ctx.clock()
        wait = after + broken_slack(after)
        seen = await peer.collect(wait, lambda p: p.dest_index == index)
        probes = sum(1 for r in seen if r.packet.opcode == ChaosOp.SNS)
        ended = [r for r in seen if r.packet.opcode in (ChaosOp.LOS, ChaosOp.CLS)]
        ctx.note(f"{wait:g} s of silence: {probes} SNS probe(s), {len(seen)} packet(s) in all")
        if ended:
            first = ended[0]
            gave_up = first.time - silent_from
            ctx.note(f"the target said so after {gave_up:.1f} s: {format_packet(first.packet)}")
        last_ack = max((r.packet.packet_no for r in seen if is_data(r.packet.opcode)), default=conn.opn_no)
        request = _request(conn, ack=last_ack)
        answer = await peer.receive(
            lambda p: p.dest_index == index and p.opcode == ChaosOp.LOS, _scale(ctx, LOS_BOUND)
        )
        late = [r for r in peer.inbox if conn.mine(r.packet) and is_data(r.packet.opcode)]
        ctx.expect(
            answer is not None,
            clause="ncp.broken",
            expected=f"a LOS for {format_packet(request)}: the connection given up after {after:g} s "
            "of silence",
            seen=_lines(late) if late else missing("no LOS and no reply"),
        )
    fresh = await ctx.connect()
    here = await fresh.call("here")
    ctx.expect_response(
        here,
        clause="ncp.broken",
        expected="a new connection served (the robot freed when the silent one was given up)",
    )


# ------------------------------------------------------------------------------------------ retransmission


@case("server.ncp.retransmission", clauses=["ncp.retransmission"], technique="scripted", deadline=20.0)
async def retransmission(ctx: CaseContext) -> None:
    """An unreceipted reply is sent again with the same number; a repeated request is not answered
    twice; once receipted, the reply stops coming."""
    async with await _open(ctx) as peer:
        index = _index(ctx)
        conn = await _handshake(ctx, peer, index, ctx.random.randrange(0x10000))
        conn.sts(ack=conn.opn_no, window=5)
        initial = await _next_data(ctx, peer, conn, conn.opn_no, "initial RESPONSE after our STS")
        last = initial.packet.packet_no
        conn.sts(ack=last, window=5)
        request = _request(conn, ack=last)
        reply = await _next_data(ctx, peer, conn, last, "reply to Here")
        number = reply.packet.packet_no

        bound = _scale(ctx, RETRANSMIT_BOUND)
        again = await peer.receive(
            lambda p: conn.mine(p) and p.packet_no == number and is_data(p.opcode), bound
        )
        if again is None:
            ctx.fail(
                f"the reply #{number} was not sent again within {bound:g} s although nothing receipted it",
                clause="ncp.retransmission",
                expected=f"DAT #{number} again within {bound:g} s (retransmission until receipted)",
                seen=missing("nothing", after=reply.raw),
            )
        first, copy = reply.packet, again.packet
        ctx.expect(
            (copy.packet_no, copy.opcode, copy.data) == (first.packet_no, first.opcode, first.data),
            clause="ncp.retransmission",
            expected=f"the same packet again: {format_packet(first)}",
            seen=showing(_frames(reply.raw, again.raw), format_packet(copy)),
        )
        ctx.note(f"retransmitted after {again.time - reply.time:.2f} s")

        repeat = peer.send(request)  # our request again, as if the target's ack had been lost
        conn.sts(ack=number, window=5)
        receipted_at = ctx.clock()
        after = await peer.collect(_scale(ctx, 2 * QUIET), lambda p: conn.mine(p) and is_data(p.opcode))
        # A copy already on its way is read late by as much as the host delays this side's loop.
        allowed = _scale(ctx, IN_FLIGHT) + await host_delay(ctx)
        late = [r for r in after if r.packet.packet_no == number and r.time > receipted_at + allowed]
        if late:
            ctx.fail(
                f"the reply #{number} kept coming after our STS receipted and acknowledged it",
                clause="ncp.retransmission",
                expected=f"no copy of #{number} later than {allowed:.3f} s after the receipt "
                f"({IN_FLIGHT:g} s in flight, the rest this host's measured delay)",
                seen=showing(late[0].raw, _lines(late)),
            )
        echo = request.packet_no
        twice = [
            r
            for r in after
            if r.packet.packet_no != number and r.packet.data[:2] == echo.to_bytes(2, "little")
        ]
        if twice:
            ctx.fail(
                f"the repeated request #{echo} was delivered again and answered a second time",
                clause="ncp.retransmission",
                expected="a repeated packet number delivered to the user once (dropped, at most an STS)",
                seen=showing(_frames(repeat, twice[0].raw), _lines(twice)),
            )


@case("server.ncp.acknowledge", clauses=["ncp.acknowledge"], technique="scripted", deadline=12.0)
async def acknowledge(ctx: CaseContext) -> None:
    """A request we send once, and never again, is acknowledged: in the ack field of a packet the target
    sends on the connection, or in the receipt of an STS (else a client would retransmit it forever)."""
    async with await _open(ctx) as peer:
        conn = await _handshake(ctx, peer, _index(ctx), ctx.random.randrange(0x10000))
        conn.sts(ack=conn.opn_no, window=5)
        initial = await _next_data(ctx, peer, conn, conn.opn_no, "initial RESPONSE after our STS")
        request = _request(conn, ack=initial.packet.packet_no)
        number = request.packet_no

        def acknowledges(p: Packet) -> bool:
            if not conn.mine(p):
                return False
            status = unpack_status(p.data) if p.opcode == ChaosOp.STS else None
            return seq_ge(p.ack_no, number) or (status is not None and seq_ge(status[0], number))

        bound = _scale(ctx, RETRANSMIT_BOUND)
        got = await peer.receive(acknowledges, bound)
        if got is None:
            ctx.fail(
                f"the request #{number} was never acknowledged within {bound:g} s",
                clause="ncp.acknowledge",
                expected=f"a packet of the connection whose ack field (or STS receipt) reaches #{number}",
                seen=showing(
                    initial.raw,
                    f"none: its ack fields stayed below it (initial RESPONSE: #{initial.packet.ack_no})",
                ),
            )
        ctx.exercised("ncp.acknowledge")
        ctx.note(f"acknowledged by {format_packet(got.packet)}")


# ------------------------------------------------------------------------------------------ window


class _WindowWatch:
    """Every data packet of one connection, each checked against the window when it arrives."""

    def __init__(self, ctx: CaseContext, conn: RawConnection) -> None:
        self.ctx = ctx
        self.conn = conn
        self.acked = conn.opn_no
        self.seen: dict[int, Received] = {}

    def ours(self, p: Packet) -> bool:
        return self.conn.mine(p) and (is_data(p.opcode) or p.opcode == ChaosOp.EOF)

    def absorb(self, items: Sequence[Received], when: str) -> None:
        limit = seq_add(self.acked, WINDOW)
        for r in items:
            n = r.packet.packet_no
            if seq_gt(n, limit):
                self.ctx.fail(
                    f"packet #{n} sent with #{self.acked} acknowledged and a window of {WINDOW} ({when})",
                    clause="ncp.window",
                    expected=f"nothing beyond #{limit} ({WINDOW} past the last acknowledged #{self.acked})",
                    seen=showing(r.raw, format_packet(r.packet)),
                )
            self.seen.setdefault(n, r)

    async def watch(self, peer: RawPeer, seconds: float, when: str) -> None:
        self.absorb(await peer.collect(_scale(self.ctx, seconds), self.ours), when)

    async def wait_for(self, peer: RawPeer, number: int) -> None:
        """Wait until packet ``number`` has come (failing after PROGRESS_BOUND)."""
        bound = _scale(self.ctx, PROGRESS_BOUND)
        got = await peer.receive(lambda p: self.ours(p) and p.packet_no == number, bound)
        if got is None:
            relative = sorted(seq_sub(n, self.conn.opn_no) for n in self.seen)
            self.ctx.fail(
                f"packet #{number} never came although the window allowed it",
                clause="ncp.window",
                expected=f"#{number} within {bound:g} s of our acknowledgement of #{self.acked}",
                seen=missing(f"nothing; data packets so far: OPN + {relative}"),
            )
        self.absorb([got], "after our acknowledgement")


@case("server.ncp.window", clauses=["ncp.window"], technique="scripted", deadline=30.0)
async def window(ctx: CaseContext) -> None:
    """With our window at 2 the target never has more than 2 packets beyond our last acknowledgement,
    a receipt alone does not open the window, and each acknowledgement lets the rest out."""
    async with await _open(ctx) as peer:
        conn = await _handshake(ctx, peer, _index(ctx), ctx.random.randrange(0x10000))
        watch = _WindowWatch(ctx, conn)
        conn.sts(ack=conn.opn_no, window=WINDOW)
        last = seq_add(conn.opn_no, 1 + WINDOW_REQUESTS)  # the initial RESPONSE, then one reply each
        for _ in range(WINDOW_REQUESTS):
            _request(conn, ack=conn.opn_no)
        await watch.watch(peer, QUIET + 0.5, "nothing acknowledged yet")
        if watch.seen:
            highest = max(watch.seen, key=lambda n: seq_sub(n, conn.opn_no))
            conn.sts(ack=watch.acked, receipt=highest, window=WINDOW)
            await watch.watch(peer, QUIET, "after a receipt of everything but no acknowledgement")
        while seq_gt(last, watch.acked):
            following = seq_add(watch.acked, 1)
            if following not in watch.seen:
                await watch.wait_for(peer, following)
            watch.acked = following
            conn.sts(ack=following, window=WINDOW)
            await watch.watch(peer, 0.2, f"after acknowledging #{following}")
        ctx.exercised("ncp.window")
        ctx.note(f"{len(watch.seen)} data packets through a window of {WINDOW}")
