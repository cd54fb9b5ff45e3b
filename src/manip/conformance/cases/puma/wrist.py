"""The wrist processes (Part II §5.1, §5.3, §6.3): what the Puma sends Cougar, in what order, and how
its requests wait for Cougar's data."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Final

from manip.codecs.messages import decode_reply
from manip.conformance.cases._support import require_response
from manip.conformance.cases.puma._support import (
    SEGMENT_WITHIN,
    TICK,
    angles,
    begin,
    close,
    f_float,
    fmt,
    is_completed,
    move,
    session,
    wait_async,
)
from manip.conformance.judge.violation import missing
from manip.conformance.puma.judge import SENSED, CougarScript, Heard, JudgingCougar
from manip.conformance.suite.case import case
from manip.conformance.suite.context import CaseContext, Probe
from manip.spec import SPEC, RequestName
from manip.spec.constants import CougarCommand, ServerOp

FORCES_DELAY: Final = 12
"""Ticks the judge holds back the forces in ``puma.wrist.waits`` (0.19 s: well within any sensible
give-up time, yet many servo cycles)."""
GIVE_UP_WITHIN: Final = 5.0
"""Seconds a Puma may take to give up on a silent Cougar (erratum wrist-timeout: the reference takes
0.5 s; the 1985 guide says only 'a reasonable amount of time')."""
SENSED_TOL: Final = 1e-3
"""Degrees: the angles in SEN and in the joint-angles reply are the same F floats of the same angles."""


# ------------------------------------------------------------------------------ command layout
_FORWARDED: Final[Mapping[RequestName, tuple[str, Mapping[str, str]]]] = {
    # request -> (Table 1 command, command field -> request field)
    "set-spring": ("NK", {"k": "k"}),
    "set-damping": ("NB", {"b": "b"}),
    "set-joint-damping": ("NBJI", {"bji": "bji"}),
    "set-frame-vector": ("NFV", {"offset": "offset"}),
    "set-weight": ("NEWWC", {"weight": "weight", "cg": "cg"}),
    "set-commanded-force": ("NFC", {"force": "force"}),
    "set-guard": ("GUARDS", {"type_index": "type_index", "dvec": "dvec", "tol": "tol"}),
    "clear-guard": ("GUARDC", {"index": "index"}),
    "set-gauge-offsets": ("WGOV", {"offsets": "offsets"}),
}


def _values(ctx: CaseContext, op: RequestName) -> dict[str, Any]:
    """Random valid values for a configuration request (seeded by the case)."""
    r = ctx.random
    out: dict[str, Any] = {}
    for f in SPEC.request(op).request.fields:
        ft = f.type
        if f.name == "type_index":
            out[f.name] = r.choice((0, 0x8000)) | r.randrange(16)
        elif f.name == "index":
            out[f.name] = r.randrange(16)
        elif f.name == "tol":
            out[f.name] = 1.0e30  # a guard that never trips
        elif ft.element == "float":
            items = [round(r.uniform(0.05, 40.0), 5) for _ in range(ft.count or 1)]
            out[f.name] = items[0] if ft.count == 1 else items
        else:
            items_i = [r.randint(-900, 900) for _ in range(ft.count or 1)]
            out[f.name] = items_i[0] if ft.count == 1 else items_i
    return out


def _as_sent(value: object) -> object:
    """A request value as the Puma passes it on: floats through the F format, sequences as tuples."""
    if isinstance(value, float):
        return f_float(value)
    if isinstance(value, (list, tuple)):
        return tuple(_as_sent(v) for v in value)
    return value


@case(
    "puma.wrist.command-layout",
    clauses=["cougar.command.layout"],
    hazard="config",
    deadline=20.0,
)
async def command_layout(ctx: CaseContext) -> None:
    """Each configuration request reaches Cougar as its Table 1 command, carrying exactly the values sent."""
    probe = await session(ctx, power=False, notify=None)
    judge, mark = begin(ctx)
    expected: list[tuple[str, dict[str, object]]] = []
    for op, (command, fields) in _FORWARDED.items():
        values = _values(ctx, op)
        answer = await probe.call(op, **values)
        require_response(ctx, answer, f"{op} answered done")
        expected.append((command, {cf: _as_sent(values[rf]) for cf, rf in fields.items()}))
    await judge.wait_ticks(4, 4 * GIVE_UP_WITHIN)
    heard = judge.since(mark)
    unreadable = [h for h in heard if h.msg is None]
    ctx.expect(
        not unreadable,
        clause="cougar.command.layout",
        expected="only Table 1 commands of the right length (a code word, then its data words)",
        seen="; ".join(str(h) for h in unreadable[:3]),
    )
    position = 0
    for command, values in expected:
        code = CougarCommand[command]
        found = next((i for i in range(position, len(heard)) if heard[i].code == code), None)
        ctx.expect(
            found is not None,
            clause="cougar.command.layout",
            expected=f"{command} (code {int(code)}) sent for the request, in request order",
            seen="; ".join(str(h) for h in heard[position:][:6]) or "nothing",
        )
        assert found is not None
        msg = heard[found].msg
        assert msg is not None
        got = {name: msg.values[name] for name in values}
        ctx.expect(
            got == values,
            clause="cougar.command.layout",
            expected=f"{command} carrying {values} (floats two words each, sign/exponent word first)",
            seen=f"{heard[found]} = {got}",
        )
        position = found + 1
    ctx.note(f"{len(expected)} configuration commands judged, {len(heard)} commands heard")


# ------------------------------------------------------------------------------ read forces
def _first(heard: Sequence[Heard], code: int) -> int | None:
    return next((i for i, h in enumerate(heard) if h.code == code), None)


@case("puma.wrist.read-forces-angles", clauses=["puma.wrist.read-forces-angles"], deadline=15.0)
async def read_forces_angles(ctx: CaseContext) -> None:
    """Read forces sends Cougar the current joint angles (SEN) before Report Forces."""
    probe = await session(ctx, power=False, notify=None)
    here = await angles(ctx, probe)
    judge, _ = begin(ctx)
    await judge.wait_ticks(3, GIVE_UP_WITHIN)  # what the Puma sends when a connection opens goes first
    mark = judge.mark()
    answer = await probe.call("read-forces")
    require_response(ctx, answer, "read forces answered")
    await judge.wait_ticks(2, GIVE_UP_WITHIN)  # a Puma that answers first still sends RFRC
    heard = judge.since(mark)
    at = _first(heard, CougarCommand.RFRC)
    ctx.expect(
        at is not None,
        clause="puma.wrist.read-forces-angles",
        expected="Report Forces (RFRC) sent to Cougar for read forces",
        seen="; ".join(str(h) for h in heard[:6]) or "nothing",
    )
    assert at is not None
    before = [h for h in heard[:at] if h.code in SENSED]
    sent = before[-1].msg.values["theta_sensed"] if before and before[-1].msg else None
    ctx.expect(
        isinstance(sent, tuple) and close(sent, here, SENSED_TOL),
        clause="puma.wrist.read-forces-angles",
        expected=f"SEN with the current joint angles {fmt(here)} sent after the request and before RFRC",
        seen=str(before[-1]) if before else f"no SEN or NPR between the request and {heard[at]}",
    )


@case("puma.wrist.waits", clauses=["puma.wrist.waits"], deadline=30.0)
async def waits(ctx: CaseContext) -> None:
    """Read forces is answered with Cougar's data once they arrive, requests after it are served after
    it, and a silent Cougar gets a non-fatal error in time."""
    probe = await session(ctx, power=False, notify=None)
    forces = tuple(f_float(round(ctx.random.uniform(-90.0, 90.0), 3)) for _ in range(6))
    judge, _ = begin(ctx, CougarScript(forces=forces, forces_delay=FORCES_DELAY))
    first = await probe.send("read-forces")
    second = await probe.send("joint-angles")
    answer = await probe.reply(first, timeout=GIVE_UP_WITHIN + ctx.options.reply_timeout)
    following = await probe.reply(second)
    said = [s for s in judge.said if s.msg.name == "FORCES"]
    got = (
        decode_reply(answer.data, SPEC.request("read-forces")).values.get("forces")
        if answer.is_response and answer.number == first
        else None
    )
    ctx.expect(
        got == forces,
        clause="puma.wrist.waits",
        expected=f"read forces #{first} answered with the forces Cougar sent {FORCES_DELAY} ticks "
        f"({FORCES_DELAY * TICK:.2f} s) late: {fmt(forces)}",
        seen=f"{answer} = {got}" + (f"; Cougar's FORCES went on tick {said[-1].tick}" if said else ""),
    )
    ctx.expect(
        following.number == second,
        clause="puma.wrist.waits",
        expected=f"joint angles #{second}, sent behind read forces, answered after it",
        seen=following,
    )
    # Cougar stays silent: the request fails in time and what follows is served.
    judge.begin(CougarScript(forces_omitted=True))
    number = await probe.send("read-forces")
    silent = await probe.reply(number, timeout=GIVE_UP_WITHIN + ctx.options.reply_timeout)
    ctx.expect(
        silent.opcode == ServerOp.NON_FATAL_ERROR and silent.number == number,
        clause="puma.wrist.waits",
        expected=f"a non-fatal error (202) for read forces #{number}: Cougar never answered",
        seen=silent,
    )
    judge.begin()
    after = await probe.call("joint-angles")
    ctx.expect_response(
        after, clause="puma.wrist.waits", expected="joint angles served normally after the failed read forces"
    )


# ------------------------------------------------------------------------------ priority
MOVE_QUEUE: Final = 2
USER_QUEUE: Final = 3
_RANK: Final[Mapping[int, int]] = {CougarCommand.NPR: 0, CougarCommand.RST: 1, CougarCommand.SEN: MOVE_QUEUE}
"""Each command's place within a tick: New Position and Rate, Reset Wrist, the move process's packets
(the sensed angles it queues while the arm moves, erratum wrist-move-queue), then the user's
(:data:`USER_QUEUE`)."""
PRIORITY_MOVE_DEG: Final = 12.0
USER_COMMANDS: Final = 6


def _ranks(items: Sequence[Heard]) -> list[int]:
    """The place of each command of one tick; a tick that reads forces has its SEN ranked as the user's
    (§6.3's SEN before Report Forces is the user request's own, on either queue)."""
    reading = any(h.code == CougarCommand.RFRC for h in items)
    out = []
    for h in items:
        rank = _RANK.get(h.code if h.code is not None else -1, USER_QUEUE)
        out.append(USER_QUEUE if reading and rank == MOVE_QUEUE else rank)
    return out


def _expect_priority(ctx: CaseContext, heard: Sequence[Heard]) -> list[set[int]]:
    """Each tick's commands in the order of priority; the places each tick carried."""
    by_tick: dict[int, list[Heard]] = {}
    for h in heard:
        by_tick.setdefault(h.tick, []).append(h)
    carried = []
    for tick, items in sorted(by_tick.items()):
        ranks = _ranks(items)
        carried.append(set(ranks))
        ctx.expect(
            ranks == sorted(ranks),
            clause="puma.wrist.priority",
            expected="New Position and Rate, then Reset Wrist, then the move process's packets (SEN), then "
            "the user's commands, within a tick",
            seen=f"tick {tick}: " + ", ".join(h.msg.name if h.msg else "?" for h in items),
        )
    return carried


async def _user_commands_each_tick(ctx: CaseContext, probe: Probe, judge: JudgingCougar) -> None:
    """A user setting (set commanded force, zero) sent on each of :data:`USER_COMMANDS` servo ticks."""
    for _ in range(USER_COMMANDS):
        answer = await probe.call("set-commanded-force", force=[0.0] * 6)
        require_response(ctx, answer, "set commanded force answered done")
        await judge.wait_ticks(1, SEGMENT_WITHIN)


@case("puma.wrist.priority", clauses=["puma.wrist.priority"], hazard="motion", deadline=40.0)
async def priority(ctx: CaseContext) -> None:
    """On every tick the Puma sends New Position and Rate first, then Reset Wrist, then the rest: user
    commands sent during a compliant move come after them."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, mark = begin(ctx, CougarScript(ntd=(0.0,) * 6))
    goal = [*here[:5], here[5] + PRIORITY_MOVE_DEG]
    segment = await move(ctx, probe, "compliant-move", joints=goal, scheme=0)
    await judge.wait_for(lambda: bool(judge.commands(mark, CougarCommand.NPR)), SEGMENT_WITHIN)
    await _user_commands_each_tick(ctx, probe, judge)
    await wait_async(ctx, probe, is_completed(segment), SEGMENT_WITHIN)
    mixed = sum(len(places) > 1 for places in _expect_priority(ctx, judge.since(mark)))
    if not mixed:
        ctx.not_judged(
            "no tick carried New Position and Rate or Reset Wrist together with another command, so their "
            "order never showed: puma.compliance.npr-every-cycle judges a New Position and Rate missing "
            "from a tick, puma.wrist.user-during-compliance user commands held back during the move"
        )
    ctx.note(f"{mixed} ticks carried commands of two priorities")


@case("puma.wrist.move-queue-first", clauses=["puma.wrist.priority"], hazard="motion", deadline=40.0)
async def move_queue_first(ctx: CaseContext) -> None:
    """While a plain move runs the move process sends the sensed angles (SEN) every servo cycle; user
    settings sent then, one a cycle, go to Cougar after them within each tick: the move process's queue
    ahead of the user's (erratum wrist-move-queue)."""
    probe, here, (judge, mark), segment = await _long_move(ctx)
    await _user_commands_each_tick(ctx, probe, judge)
    await wait_async(ctx, probe, is_completed(segment), 2 * SEGMENT_WITHIN)
    met = sum({MOVE_QUEUE, USER_QUEUE} <= places for places in _expect_priority(ctx, judge.since(mark)))
    sensed = len(judge.commands(mark, CougarCommand.SEN))
    back = await move(ctx, probe, "set-joint-angles", joints=list(here))
    await wait_async(ctx, probe, is_completed(back), SEGMENT_WITHIN)
    if not met:
        ctx.not_judged(
            "no servo tick carried the move process's sensed angles (SEN) together with a user command, so "
            "the order of its two queues never showed (erratum wrist-move-queue): "
            + (
                f"the Puma sent {sensed} SEN during the move, each on a tick without a user command "
                "(puma.wrist.config-at-once judges a user command held back)"
                if sensed
                else "the Puma sent no SEN while the arm moved"
            )
        )
    ctx.note(f"{met} ticks carried the move process's SEN and a user command")


# ------------------------------------------------------------------------------ at once, during compliance
AT_ONCE_MOVE_DEG: Final = 30.0
"""How far joint 1 moves while the configuration request is sent: many servo cycles."""
AT_ONCE_TICKS: Final = 3
"""Servo cycles within which a configuration request's command reaches Cougar."""


async def _long_move(ctx: CaseContext) -> tuple[Probe, tuple[float, ...], tuple[JudgingCougar, int], int]:
    """A session, where the arm stands, the judge (and its mark), and a plain move of joint 1 by
    :data:`AT_ONCE_MOVE_DEG` (away from the obstacle's side) two servo cycles under way: its segment."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    judge, mark = begin(ctx)
    goal = list(here)
    goal[0] += AT_ONCE_MOVE_DEG if here[0] <= 0 else -AT_ONCE_MOVE_DEG
    segment = await move(ctx, probe, "set-joint-angles", joints=goal)
    await judge.wait_ticks(2, SEGMENT_WITHIN)
    return probe, here, (judge, mark), segment


def _first_after(heard: Sequence[Heard], code: int, tick: int) -> Heard | None:
    return next((h for h in heard if h.code == code and h.tick >= tick), None)


def _expect_at_once(
    ctx: CaseContext, sent: Heard | None, asked: int, ticks: int, *, clause: str, expected: str
) -> bool:
    """``sent`` (the command Cougar heard) went within :data:`AT_ONCE_TICKS` servo cycles of tick
    ``asked``; none by tick ``ticks`` is a command that never came."""
    soon = sent is not None and sent.tick - asked <= AT_ONCE_TICKS
    seen = str(sent) if sent is not None else missing(f"nothing by tick {ticks}")
    return ctx.expect(soon, clause=clause, expected=expected, seen=seen)


@case("puma.wrist.config-at-once", clauses=["puma.wrist.config-at-once"], hazard="motion", deadline=40.0)
async def config_at_once(ctx: CaseContext) -> None:
    """Set weight sent while a long move runs is answered done and reaches Cougar (NEWWC) within a few
    servo cycles, before the move ends: not held for the queued segments (erratum
    wrist-config-immediate)."""
    probe, _, (judge, mark), segment = await _long_move(ctx)
    asked = judge.ticks
    weight = round(ctx.random.uniform(1.0, 20.0), 3)
    answer = await probe.call("set-weight", weight=weight, cg=[0.0] * 3)
    ctx.expect_response(
        answer, clause="puma.wrist.config-at-once", expected="set weight answered done while the move runs"
    )
    await judge.wait_ticks(AT_ONCE_TICKS, SEGMENT_WITHIN)
    sent = _first_after(judge.since(mark), CougarCommand.NEWWC, asked)
    within = f"NEWWC sent to Cougar within {AT_ONCE_TICKS} servo cycles of set weight (tick {asked})"
    running = f"{within}, while segment {segment} still runs"
    _expect_at_once(ctx, sent, asked, judge.ticks, clause="puma.wrist.config-at-once", expected=running)
    await wait_async(ctx, probe, is_completed(segment), 2 * SEGMENT_WITHIN)
    await probe.call("set-weight", weight=0.0, cg=[0.0] * 3)


DURING_MOVE_DEG: Final = 12.0


@case(
    "puma.wrist.user-during-compliance",
    clauses=["puma.wrist.user-during-compliance"],
    hazard="motion",
    deadline=40.0,
)
async def user_during_compliance(ctx: CaseContext) -> None:
    """Read forces during a compliant segment is answered with the forces Cougar sends, a setting sent
    then reaches Cougar within a few servo cycles, and the segment goes on to its end."""
    probe = await session(ctx)
    here = await angles(ctx, probe)
    forces = tuple(f_float(round(ctx.random.uniform(-90.0, 90.0), 3)) for _ in range(6))
    judge, mark = begin(ctx, CougarScript(forces=forces, ntd=(0.0,) * 6))
    goal = [*here[:5], here[5] + DURING_MOVE_DEG]
    segment = await move(ctx, probe, "compliant-move", joints=goal, scheme=0)
    await judge.wait_for(lambda: bool(judge.commands(mark, CougarCommand.NPR)), SEGMENT_WITHIN)
    answer = await probe.call("read-forces", timeout=GIVE_UP_WITHIN)
    got = (
        decode_reply(answer.data, SPEC.request("read-forces")).values.get("forces")
        if answer.is_response
        else None
    )
    ctx.expect(
        got == forces,
        clause="puma.wrist.user-during-compliance",
        expected=f"read forces during the compliant segment answered with Cougar's forces {fmt(forces)}",
        seen=f"{answer} = {got}",
    )
    asked = judge.ticks
    require_response(ctx, await probe.call("set-commanded-force", force=[0.0] * 6), "set commanded force")
    await judge.wait_ticks(AT_ONCE_TICKS, SEGMENT_WITHIN)
    sent = _first_after(judge.since(mark), CougarCommand.NFC, asked)
    within = f"NFC sent to Cougar within {AT_ONCE_TICKS} servo cycles of set commanded force"
    _expect_at_once(
        ctx, sent, asked, judge.ticks, clause="puma.wrist.user-during-compliance", expected=within
    )
    done = await wait_async(ctx, probe, is_completed(segment), SEGMENT_WITHIN)
    ctx.expect(
        done is not None,
        clause="puma.wrist.user-during-compliance",
        expected=f"the compliant segment {segment} going on to its end (reported complete)",
        seen=missing("no segment-completed report"),
    )


OOS_WORD: Final = 0o177
"""The unknown word the judging Cougar says it met (any word that is no command code)."""


@case("puma.wrist.out-of-sync", clauses=["puma.wrist.out-of-sync"], deadline=30.0)
async def out_of_sync(ctx: CaseContext) -> None:
    """Cougar says it lost sync while read forces waits for it: the request is answered with a non-fatal
    error at once (well before the wrist timeout), an asynchronous warning tells the client, and the next
    request is served (erratum wrist-timeout)."""
    probe = await session(ctx, power=False, notify=None)
    judge, mark = begin(ctx, CougarScript(forces_omitted=True))
    number = await probe.send("read-forces")
    await judge.wait_for(lambda: bool(judge.commands(mark, CougarCommand.RFRC)), GIVE_UP_WITHIN)
    judge.inject("OUT-OF-SYNC", after=1, code=OOS_WORD)
    injected = judge.ticks
    answer = await probe.reply(number, timeout=GIVE_UP_WITHIN + ctx.options.reply_timeout)
    late = judge.ticks - injected
    ctx.expect(
        answer.opcode == ServerOp.NON_FATAL_ERROR and late <= AT_ONCE_TICKS + 1,
        clause="puma.wrist.out-of-sync",
        expected=f"read forces #{number} answered with a non-fatal error (202) within {AT_ONCE_TICKS + 1} "
        "servo cycles of Cougar's out-of-sync message",
        seen=f"{answer}, {late} servo cycles after it",
    )
    warning = await wait_async(ctx, probe, lambda p: p.opcode == ServerOp.ASYNCHRONOUS_WARNING, 1.0)
    ctx.expect(
        warning is not None,
        clause="puma.wrist.out-of-sync",
        expected="an asynchronous warning (205) telling the client that the wrist computer lost sync",
        seen=missing("none"),
    )
    judge.begin()
    after = await probe.call("joint-angles")
    ctx.expect_response(
        after,
        clause="puma.wrist.out-of-sync",
        expected="joint angles served normally after the out-of-sync message",
    )


_SETTINGS: Final = frozenset(
    {
        CougarCommand.NK,
        CougarCommand.NB,
        CougarCommand.NBJI,
        CougarCommand.NFV,
        CougarCommand.NEWWC,
        CougarCommand.NFC,
        CougarCommand.WGOV,
    }
)
"""Cougar's settings: a new connection does not send them again (erratum cougar-connection-state)."""
NEWWC: Final = CougarCommand.NEWWC
CONNECTION_WEIGHT: Final = 8.0
"""The weight (oz) the first connection of ``puma.wrist.connection-state`` sets: exact in an F float."""


@case("puma.wrist.connection-state", clauses=["puma.wrist.connection-state"], hazard="config", deadline=30.0)
async def connection_state(ctx: CaseContext) -> None:
    """A connection arms a guard (one that never trips) and sets a weight, then closes; when the next
    connection opens the Puma clears that guard on Cougar (GUARDC) and sends none of Cougar's settings
    again (erratum cougar-connection-state)."""
    first = await session(ctx, power=False, notify=None)
    judge, mark = begin(ctx)
    index = ctx.random.randrange(16)
    require_response(
        ctx,
        await first.call("set-guard", type_index=index, dvec=[0.0, 0.0, 1.0, 0.0, 0.0, 0.0], tol=1.0e30),
        "a continue guard that never trips",
    )
    require_response(
        ctx, await first.call("set-weight", weight=CONNECTION_WEIGHT, cg=[0.0] * 3), "set weight"
    )

    def weighed() -> bool:  # this connection's weight has reached Cougar (not an earlier case's)
        return any(h.msg and h.msg.values["weight"] == CONNECTION_WEIGHT for h in judge.commands(mark, NEWWC))

    await judge.wait_for(weighed, GIVE_UP_WITHIN)
    await first.close()
    opened = judge.mark()
    second = await session(ctx, power=False, notify=None)
    await second.call("joint-angles")
    await judge.wait_ticks(AT_ONCE_TICKS, GIVE_UP_WITHIN)
    heard = judge.since(opened)
    cleared = [
        h for h in heard if h.code == CougarCommand.GUARDC and h.msg and h.msg.values["index"] == index
    ]
    ctx.expect(
        bool(cleared),
        clause="puma.wrist.connection-state",
        expected=f"GUARDC for guard {index}, which the last connection left armed, once the next one opens",
        seen="; ".join(str(h) for h in heard[:6]) or "nothing sent to Cougar",
    )
    resent = [h for h in heard if h.code in _SETTINGS]
    ctx.expect(
        not resent,
        clause="puma.wrist.connection-state",
        expected="none of Cougar's settings sent again when a connection opens",
        seen="; ".join(str(h) for h in resent[:6]),
    )
    await second.call("set-weight", weight=0.0, cg=[0.0] * 3)
