"""Helpers of the Cougar cases (no cases are declared here): constants a case relies on, reading
Cougar memory and forces, and the expectations every Cougar case shares (a well-formed response of a
name, nothing more on the link)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Final

from manip.arm import READY
from manip.arm.units import MM_PER_UNIT
from manip.codecs.cougar import encode
from manip.conformance.cougar.probe import (
    DEFAULT_WITHIN,
    CougarProbe,
    WordReply,
    floats_of,
    layout_words,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.context import CaseContext
from manip.cougar.memory import Region
from manip.spec import SPEC
from manip.spec.constants import CougarCommand, CougarResponse
from manip.spec.notation import octal

GUARDS: Final = 16
STOP_BIT: Final = 0x8000
SETTLE_TICKS: Final = 40
"""Ticks for the gauge filter (pole 0.75 per tick) to settle after the arm moves: 0.75**40 < 1e-5."""
NEVER: Final = 1.0e30
"""A guard tolerance no dot product reaches (a guard that must not trip)."""
ALWAYS: Final = -1.0
"""With a zero dvec the dot product is 0 > -1: a guard that trips at the first check."""
POSE_B: Final = tuple(a + d for a, d in zip(READY, (15.0, 10.0, -10.0, 20.0, 30.0, 25.0), strict=True))

GUARD_DVEC_ZERO: Final = (0.0,) * 6
NO_MAP: Final = "declare the Cougar's memory map with --memory-map FILE (its format is in docs/drv11j.md)"


# ------------------------------------------------------------------------------------------ the memory map
def mapped(ctx: CaseContext, *names: str) -> list[Region]:
    """The objects ``names`` of the run's memory map; the case is not judged without a map, or when the
    map does not name them (the 1985 guide gives no map: erratum cougar-memory-map)."""
    memory_map = ctx.options.cougar_map
    if memory_map is None:
        ctx.not_judged(
            f"the case reads or writes Cougar memory ({', '.join(names)}) and no map says where: {NO_MAP}"
        )
    missing = [n for n in names if memory_map.get(n) is None]
    if missing:
        ctx.not_judged(
            f"the memory map ({memory_map.source}) does not name {', '.join(missing)}: "
            "add them to judge the case"
        )
    return [memory_map.objects[n] for n in names]


def any_address(ctx: CaseContext) -> int:
    """An even address any Cougar can examine (a case that needs some memory words, whichever): the
    version word of the map, or 0 without one (the PDP-11's first word is always memory)."""
    memory_map = ctx.options.cougar_map
    version = memory_map.get("version") if memory_map is not None else None
    return version.address if version is not None else 0


def in_unit(ctx: CaseContext, mm: Sequence[float]) -> tuple[float, ...]:
    """Lengths given in millimetres, in the run's length unit (``--length-unit``, erratum
    cougar-length-unit)."""
    scale = MM_PER_UNIT[ctx.options.length_unit]
    return tuple(v / scale for v in mm)


# ------------------------------------------------------------------------------------------ helpers
async def clean(probe: CougarProbe) -> None:
    """Disarm all 16 guards and drop whatever the previous user left in flight."""
    words: list[int] = []
    for index in range(GUARDS):
        words += (CougarCommand.GUARDC, index)
    await probe.send_words(words)
    await probe.run(2)


def response_code(name: str) -> int:
    """The code of a Table 1 response named as the spec names it (``EXMN-DATA``)."""
    return CougarResponse[name.replace("-", "_")].value


def expect_reply(ctx: CaseContext, reply: WordReply, name: str, clause: str, *, after: str = "") -> WordReply:
    """``reply`` is a well-formed ``name`` response (code and data length of Table 1, stated)."""
    code = response_code(name)
    where = f" to {after}" if after else ""
    ctx.expect(
        not reply.problem,
        clause="cougar.response.layout",
        expected=f"a Table 1 response{where} ({name}, {layout_words(SPEC.cougar_responses[code])})",
        seen=reply,
    )
    ctx.expect(reply.name == name, clause=clause, expected=f"{name} (code {code}){where}", seen=reply)
    return reply


async def answer_words(probe: CougarProbe, name: str) -> tuple[list[WordReply], tuple[int, ...]]:
    """Send command ``name`` (no data) and tick until a whole response has come, at most DEFAULT_WITHIN
    ticks: the responses, and every word Cougar sent meanwhile as it came (a response may span ticks),
    for a case that judges the words themselves, whatever response they make."""
    first = probe.event_count
    await probe.send(name)
    replies: list[WordReply] = []
    for _ in range(DEFAULT_WITHIN):
        replies += await probe.run(1)
        if replies:
            break
    since = probe.event_count - first  # the events are a bounded window: the last ``since`` of them
    recent = list(probe.events)[-since:] if since else []
    return replies, tuple(w for e in recent if e.direction == "cougar" for w in e.words)


def expect_names(
    ctx: CaseContext, replies: Sequence[WordReply], names: Sequence[str], *, clause: str, expected: str
) -> bool:
    """``replies`` are responses named ``names``, in that order, and no others."""
    named = [r.name for r in replies] == list(names)
    return ctx.expect(named, clause=clause, expected=expected, seen=replies)


def expect_none(ctx: CaseContext, replies: Sequence[WordReply], clause: str, why: str) -> None:
    """No response came (``why`` says why none should)."""
    ctx.expect_none(replies, clause=clause, expected=f"no response ({why})")


async def expect_quiet(ctx: CaseContext, probe: CougarProbe, clause: str, why: str, ticks: int = 2) -> None:
    """Nothing more comes in the next ``ticks`` ticks (no extra words after a response)."""
    expect_none(ctx, await probe.run(ticks), clause, why)


async def expect_examine(ctx: CaseContext, probe: CougarProbe, address: int, count: int) -> tuple[int, ...]:
    """EXMN that must return ``count`` words (an address inside memory)."""
    await probe.send("EXMN", address=address, count=count)
    return await expect_examined(ctx, probe, address, count)


async def expect_examined(ctx: CaseContext, probe: CougarProbe, address: int, count: int) -> tuple[int, ...]:
    """The next response, the answer to an EXMN of ``count`` words at ``address`` already sent, which
    must return them (an address inside memory)."""
    reply = expect_reply(
        ctx,
        await probe.reply(f"EXMN ({octal(address)}, {count})"),
        "EXMN-DATA",
        "cougar.exmn.reply",
        after="EXMN",
    )
    words = tuple(int(w) for w in reply.data_words[1:])
    ctx.expect(
        reply.data_words[:1] == (count,),
        clause="cougar.exmn.reply",
        expected=f"EXMN of {count} word(s) at {octal(address)}: count word {count}",
        seen=reply,
    )
    ctx.expect(
        len(words) == count,
        clause="cougar.exmn.reply",
        expected=f"EXMN of {count} word(s) at {octal(address)}: {count} words after the count word",
        seen=reply,
    )
    return words


async def examine_region(ctx: CaseContext, probe: CougarProbe, obj: Region) -> tuple[int, ...]:
    return await expect_examine(ctx, probe, obj.address, obj.words)


async def region_floats(ctx: CaseContext, probe: CougarProbe, obj: Region) -> tuple[float, ...]:
    """An object's floats; the case cannot go on without all of them (``ctx.fail``)."""
    words = await examine_region(ctx, probe, obj)
    if len(words) != obj.words:
        ctx.fail(
            f"EXMN did not return the {obj.words} words of {obj.name}: the case cannot go on",
            clause="cougar.exmn.reply",
            expected=f"{obj.words} words at {octal(obj.address)}",
            seen=f"{len(words)} words",
        )
    return floats_of(words)


async def peek_words(
    ctx: CaseContext, probe: CougarProbe, address: int, words: int, name: str
) -> tuple[int, ...]:
    """Memory words for a case that only needs them (to send them back unchanged): judges nothing, and
    leaves the case not judged when EXMN does not return them (a wrong answer, which
    ``cougar.reply.exmn`` judges: never a skip)."""
    reply = await probe.examine(address, words)
    if reply.problem or reply.name != "EXMN-DATA" or reply.data_words[:1] != (words,):
        ctx.not_judged(
            f"the case needs Cougar's {name} words ({words} at {octal(address)}), which EXMN did not "
            f"return: {reply} (cougar.reply.exmn judges EXMN's answer)"
        )
    return tuple(int(w) for w in reply.data_words[1:])


async def peek_region(ctx: CaseContext, probe: CougarProbe, obj: Region) -> tuple[int, ...]:
    """An object's words, as :func:`peek_words`."""
    return await peek_words(ctx, probe, obj.address, obj.words, obj.name)


def int16(words: Iterable[int]) -> list[int]:
    return [w - 0x10000 if w & 0x8000 else w for w in words]


async def settle(probe: CougarProbe, pose: Sequence[float] = READY) -> None:
    """Tell Cougar where the arm is and let the gauge filter settle there."""
    await probe.send("SEN", theta_sensed=tuple(pose))
    await probe.run(SETTLE_TICKS)


async def read_forces(ctx: CaseContext, probe: CougarProbe) -> tuple[float, ...]:
    reply = expect_reply(ctx, await probe.call("RFRC"), "FORCES", "cougar.rfrc.reply", after="RFRC")
    values = reply.floats()
    ctx.expect_finite(
        values, 6, clause="cougar.rfrc.reply", expected="six finite floats", seen=showing(reply, str(values))
    )
    return values


def guard_words(index_word: int, dvec: Sequence[float] = GUARD_DVEC_ZERO, tol: float = ALWAYS) -> list[int]:
    return encode("command", "GUARDS", type_index=index_word, dvec=tuple(dvec), tol=tol)


def guard_trips(replies: Iterable[WordReply]) -> list[tuple[str, int]]:
    """(response name, guard index) of every guard response."""
    out: list[tuple[str, int]] = []
    for r in replies:
        if r.name in ("GUARD-STOP", "GUARD-CONTINUE"):
            out.append((r.name, int(r.data_words[0]) if r.data_words else -1))
    return out


def others(replies: Iterable[WordReply]) -> list[WordReply]:
    return [r for r in replies if r.name not in ("GUARD-STOP", "GUARD-CONTINUE")]


def expect_trips(
    ctx: CaseContext,
    replies: Sequence[WordReply],
    trips: Sequence[tuple[str, int]],
    *,
    clause: str,
    expected: str,
) -> bool:
    """The guard responses among ``replies`` are ``trips`` ((name, index), in order), none when empty."""
    return ctx.expect(guard_trips(replies) == list(trips), clause=clause, expected=expected, seen=replies)


def expect_close(
    ctx: CaseContext,
    got: Sequence[float],
    want: Sequence[float],
    *,
    rel: float,
    floor: float = 1e-6,
    clause: str,
    expected: str,
) -> bool:
    """``got`` matches ``want`` element-wise (:func:`close_to`), the evidence ``got``."""
    near = close_to(got, want, rel=rel, floor=floor)
    return ctx.expect(near, clause=clause, expected=expected, seen=fmt(got))


def close_to(a: Sequence[float], b: Sequence[float], *, rel: float, floor: float) -> bool:
    """Element-wise closeness with a tolerance relative to the larger vector's size."""
    scale = max([abs(x) for x in (*a, *b)], default=0.0)
    tol = rel * scale + floor
    return len(a) == len(b) and all(abs(x - y) <= tol for x, y in zip(a, b, strict=True))


def fmt(values: Iterable[float]) -> str:
    return "(" + ", ".join(f"{v:.6g}" for v in values) + ")"
