"""What a server run can see of the link and the NCP: well-formed frames, consecutive packet numbers,
and asynchronous warnings in the error format when the arm produces any."""

from __future__ import annotations

from collections import Counter
from itertools import pairwise
from typing import Final

from manip.conformance.cases._support import (
    UNASSIGNED_OPCODES,
    error_of,
    expect_last_processed,
    last_processed,
    power_on,
    read_floats,
    require_response,
    settle,
)
from manip.conformance.judge.checks import WirePacket, check_error_packet, word
from manip.conformance.judge.violation import missing
from manip.conformance.suite.case import CaseFailure, case
from manip.conformance.suite.context import CaseContext, Probe
from manip.conformance.suite.world import SluggishJoint
from manip.links.address import parse_address
from manip.links.base import Link, LinkStats
from manip.spec.constants import ServerOp

_FRAME_CLAUSES = (
    "chaos.header.layout",
    "chaos.header.unused-byte-zero",
    "chaos.header.nbytes",
    "chaos.data.byte-order",
    "chaos.opcode.legal",
)


async def _exchange(probe: Probe) -> None:
    """Traffic of every server packet shape: multi-packet text, data, done, error."""
    await probe.call("describe-self")
    await probe.call("here")
    await probe.call("set-speed", factor=1.0)
    await probe.call_raw(UNASSIGNED_OPCODES[0])


_LINK_FRAMES: Final[tuple[tuple[str, tuple[str, ...]], ...]] = (
    ("tcp", ("link.tcp.framing",)),
    ("chudp", ("chudp.header", "chudp.length", "chudp.word-order", "chudp.trailer", "chudp.checksum")),
    ("chaosd", ("link.chaosd.framing",)),
)
"""Each link framing a server may be reached on, and the clauses of its frames."""


_CLAUSE_OF_ILLEGAL: Final = {"opcode": "chaos.opcode.legal", "oversize": "chaos.data.max-488"}
"""The clause a sound frame with an illegal packet breaks, by the link's counter (``LinkStats.illegal``)."""


def _refused_frames(links: list[Link], clauses: tuple[str, ...]) -> tuple[dict[str, list[str]], LinkStats]:
    """What the frames that came on ``links`` and were refused broke, by the clause a frames case citing
    ``clauses`` reports (one it does not cite counts against the link's own framing, ``clauses[0]``, and
    names its clause); and the links' counters."""
    stats = LinkStats()
    for link in links:
        stats.add(link.stats)
    broken = Counter(stats.bad_clauses)
    broken.update({_CLAUSE_OF_ILLEGAL[reason]: n for reason, n in stats.illegal.items()})
    unnamed = stats.bad_total - sum(stats.bad_clauses.values())
    if unnamed:
        broken[clauses[0]] += unnamed
    said: dict[str, list[str]] = {c: [] for c in (*clauses, *_FRAME_CLAUSES)}
    for clause, count in sorted(broken.items()):
        said[clause if clause in said else clauses[0]].append(f"{count} frame(s) breaking {clause}")
    return said, stats


def _swapped_numbers(probe: Probe) -> list[WirePacket]:
    """The server's packets whose request number reads right only with its two bytes swapped (a number
    with two equal bytes shows nothing)."""
    sent = {p.packet_no for p in probe.packets if p.direction == "c2s"}
    if probe.rfc_packet_no is not None:
        sent.add(probe.rfc_packet_no)
    return [
        p
        for p in probe.packets
        if p.direction == "s2c"
        and (n := word(p.data)) is not None
        and n not in sent
        and int.from_bytes(n.to_bytes(2, "little"), "big") in sent
    ]


FRAMES_DEADLINE: Final = 12.0
"""Seconds for a frames case: a connection that never opens (its frames refused) waits out the connect
timeout before the case judges the link's counters."""


@case.each(_LINK_FRAMES)
def _frames_case(row: tuple[str, tuple[str, ...]]) -> None:
    scheme, clauses = row

    async def frames(ctx: CaseContext) -> None:
        if parse_address(ctx.options.address).framing != scheme:
            ctx.skip(
                f"the target is not on a {scheme} link, so it cannot break {', '.join(clauses)} here"
                f" (a run against its {scheme}:// address judges it)"
            )
        links: list[Link] = []

        def watch(link: Link) -> Link:
            links.append(link)
            return link

        def judged_refused() -> bool:
            """A violation for each rule the refused frames broke; True if there was any."""
            said, stats = _refused_frames(links, clauses)
            for named in (*clauses, *_FRAME_CLAUSES):
                if said[named]:
                    ctx.expect(
                        False,
                        clause=named,
                        expected=f"every frame from the server well formed ({named})",
                        seen=missing(
                            f"{'; '.join(said[named])}, refused by the link (its counters: bad "
                            f"{dict(stats.bad)}, illegal {dict(stats.illegal)}): the packets never came"
                        ),
                    )
            return any(said.values())

        try:
            probe = await ctx.connect(watch=watch)
            await _exchange(probe)
        except CaseFailure:
            if judged_refused():
                return  # the bad frames are why the exchange failed
            raise
        if judged_refused():
            return
        swapped = _swapped_numbers(probe)
        ctx.expect(
            not swapped,
            clause="chaos.data.byte-order",
            expected="each data word's first byte in its low byte: the request numbers quoted as sent",
            seen=swapped,
        )
        ctx.exercised(*clauses, *_FRAME_CLAUSES)  # the link decoded every frame by all of them

    case(
        f"server.link.{scheme}-frames",
        clauses=[*clauses, *_FRAME_CLAUSES],
        summary=f"Every frame the server sends on a {scheme} link decodes (header, length, checksum).",
        deadline=FRAMES_DEADLINE,
    )(frames)


@case("server.link.packet-numbers", clauses=["ncp.packet-numbers"])
async def packet_numbers(ctx: CaseContext) -> None:
    """The server's data packets are numbered consecutively (modulo 2^16): none is held back for a number
    that never comes."""
    try:
        probe = await ctx.connect()
        await _exchange(probe)
    except CaseFailure:
        _judge_gap(ctx)
        raise
    _judge_gap(ctx)
    numbers = [p.packet_no for p in probe.packets if p.direction == "s2c" and not p.is_close]
    bad = [(a, b) for a, b in pairwise(numbers) if b != (a + 1) & 0xFFFF]
    ctx.expect(
        not bad,
        clause="ncp.packet-numbers",
        expected="consecutive packet numbers",
        seen=f"jumps {bad[:5]} in {numbers[:20]}",
    )


def _judge_gap(ctx: CaseContext) -> None:
    """Fail when the last connection holds packets numbered beyond one that never came (a gap in the
    server's numbering: its NCP would have sent the missing one again)."""
    if not ctx.probes:
        return
    conn = ctx.probes[-1].conn
    info = conn.info()
    if conn.node.link_stats().bad_total:
        return  # a frame the link refused leaves a gap too: the frames cases judge those
    if info is not None and info.buffered:
        ctx.fail(
            f"{info.buffered} packet(s) of the server held back: #{(info.last_received + 1) & 0xFFFF} never "
            "came",
            clause="ncp.packet-numbers",
            expected=f"packet #{(info.last_received + 1) & 0xFFFF} after #{info.last_received} (numbers "
            "consecutive)",
            seen=missing(
                f"packet #{(info.last_received + 1) & 0xFFFF}; {info.buffered} later packet(s) waiting for it"
            ),
        )


LAGGING_JOINT: Final = SluggishJoint(2, 0.35)
"""The world's condition for a warning: joint 2 trails its command by 0.35 degrees while it moves, over
half the reference server's collision tolerance and within it (a following warning, no collision)."""
WARNING_MOVE_DEG: Final = 20.0


@case(
    "server.async.warning-format",
    clauses=["async-warning.format", "async-error.request-number"],
    hazard="motion",
    deadline=8.0,
)
async def warning_format(ctx: CaseContext) -> None:
    """An asynchronous warning (205) has the error format, severity W and the number of the last request
    processed, and does not interrupt work: the move it warns of ends at its goal and the next is taken.

    The target's world makes a joint lag its command (``sluggish-joint``: the embedded server's world
    always, another target's with ``--world``); without a world the case is not judged."""
    async with ctx.arranged(LAGGING_JOINT):
        probe = await ctx.connect()
        await power_on(ctx, probe)
        start = await read_floats(ctx, probe, "joint-angles")
        goal = list(start)
        goal[1] += WARNING_MOVE_DEG if goal[1] < 0 else -WARNING_MOVE_DEG
        move = await probe.call("set-joint-angles", joints=goal)
        require_response(ctx, move, "a move of joint 2 (set joint angles answered with a segment)")
        reached = await settle(ctx, probe, goal, within=5.0)
    warnings = [
        p for p in probe.packets if p.direction == "s2c" and p.opcode == ServerOp.ASYNCHRONOUS_WARNING
    ]
    if not warnings:
        ctx.not_judged(
            f"no asynchronous warning came while the world arranged {LAGGING_JOINT.describe()}: the "
            "target's warning threshold is not known to the suite, so a missing warning is no failure"
        )
    for packet in warnings:
        _judge_warning(ctx, probe, packet)
    ctx.expect(
        reached is not None,
        clause="async-warning.format",
        expected=f"the move the warning is about to end at its goal {[round(v, 3) for v in goal]}",
        seen="the arm stopped short of it (the warning interrupted the motion)",
    )
    back = await probe.call("set-joint-angles", joints=list(start))
    ctx.expect_response(
        back,
        clause="async-warning.format",
        expected="the next move taken after a warning (a warning does not abort motion)",
    )
    await settle(ctx, probe, start, within=5.0)


def _judge_warning(ctx: CaseContext, probe: Probe, packet: WirePacket) -> None:
    ctx.check(check_error_packet(packet))
    error = error_of(packet)
    ctx.expect(
        error is not None and error.error.severity == "W",
        clause="async-warning.format",
        expected="an error string of severity W",
        seen=packet,
    )
    processed = last_processed(probe.packets, packet)
    expect_last_processed(ctx, packet, processed)
