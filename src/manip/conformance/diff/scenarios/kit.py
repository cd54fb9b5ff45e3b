"""What every scenario is made of: the requests it sends, the answers it reads, its constants."""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600, forward
from manip.codecs.error_string import ErrorMessage
from manip.codecs.errors import CodecError
from manip.codecs.lispm_text import decode_lispm
from manip.codecs.messages import AsyncResponse
from manip.codecs.pdp11float import pack_f, unpack_f
from manip.conformance.cases._support import error_of
from manip.conformance.cases.server.motion import CONFIGURATION_SEED
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.diff.streams import ScenarioCheck, ScenarioJudge, Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, Pause, RequestStep, Step
from manip.conformance.judge.checks import async_of, parse_description
from manip.conformance.judge.packets import WirePacket
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import RequestName, ServerOp

ANGLE_TOLERANCE: Final = 0.05
"""Degrees within which a joint angle read back is the angle commanded (the arm settles exactly in the
reference model; a real servo within a few hundredths)."""
SETTLE: Final = 30.0
"""Seconds of pause after a motion: a full-range move at speed 1 ends well within it."""
NZI_JOINTS: Final = (2, 3)
"""The joints whose zero index the calibrate-nzi condition hides (its default)."""
POSE: Final = (10.0, -80.0, 100.0, 20.0, 30.0, -40.0)
"""A pose within the PUMA 600's limits whose six angles all differ (a reversed or shifted vector shows)."""

READY_POSE: Final = (0.0, -90.0, 90.0, 0.0, 0.0, 0.0)

Events = dict[int, list[SideEvent]]


def opcode_of(name: RequestName) -> int:
    return SPEC.request(name).opcode


def req(name: RequestName, data: bytes = b"", *, lazy: bool = False) -> RequestStep:
    return RequestStep(opcode_of(name), data, lazy=lazy)


def floats_data(values: Sequence[float]) -> bytes:
    return b"".join(pack_f(v) for v in values)


def scenario_inputs(name: str, groups: Sequence[tuple[str, Sequence[Step]]]) -> tuple[FuzzInput, ...]:
    return tuple(
        FuzzInput(n, f"scenario.{name}", tuple(steps), note) for n, (note, steps) in enumerate(groups)
    )


def scenario_stream(
    name: str,
    groups: Sequence[tuple[str, Sequence[Step]]],
    check: ScenarioCheck | None = None,
    *,
    judge: ScenarioJudge | None = None,
) -> Stream:
    """Scenario ``name``: its groups of steps as inputs numbered from 0, judged by ``check`` (or by
    ``judge``, which also says what it could not judge)."""
    return Stream(None, scenario_inputs(name, groups), scenario=name, check=check, judge=judge)


# What the answers say ------------------------------------------------------------------------------


def answers_to(events: Sequence[SideEvent], opcode: int) -> list[SideEvent]:
    return [e for e in events if e.kind == "packet" and e.request == opcode]


def answer_at(events: Events, number: int, name: RequestName) -> SideEvent | None:
    """The first answer of ``name`` at input ``number``."""
    return next(iter(answers_to(events.get(number, []), opcode_of(name))), None)


def payload(event: SideEvent) -> bytes:
    return event.data[2:]


def error_in(event: SideEvent | None, opcode: int) -> ErrorMessage | None:
    """The error string of ``event`` when it is an error packet of ``opcode``, its numbers read in either
    layout (:func:`~manip.conformance.cases._support.error_of`); None for no event, another packet, or a
    string that reads neither way."""
    if event is None or not is_op(event, opcode):
        return None
    reply = error_of(wire_of(event))
    return reply.error if reply is not None else None


def async_in(event: SideEvent) -> AsyncResponse | None:
    """The fields of an asynchronous response ``event`` (either layout); None for another event, or one
    whose length is neither layout's."""
    return async_of(wire_of(event)) if is_op(event, ServerOp.ASYNCHRONOUS_RESPONSE) else None


def angles_of(event: SideEvent) -> list[float] | None:
    body = payload(event)
    if event.opcode != ServerOp.RESPONSE or len(body) % 4 or not body:
        return None
    try:
        return [unpack_f(body[i : i + 4]) for i in range(0, len(body), 4)]
    except (CodecError, ValueError):
        return None


def read_back(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    answer = answer_at(events, number, "joint-angles")
    angles = angles_of(answer) if answer is not None else None
    return (answer, angles) if answer is not None and angles is not None else None


def description_at(events: Events, number: int) -> dict[str, object] | None:
    packets = answers_to(events.get(number, []), opcode_of("describe-self"))
    text = "".join(decode_lispm(payload(p)) for p in packets if p.opcode == ServerOp.RESPONSE)
    entries, problems = parse_description(text) if packets else (None, [])
    return dict(entries) if entries is not None and not problems else None


def sighting(number: int, clause: str, message: str, expected: str, event: SideEvent) -> Sighting:
    return Sighting(Violation(message, clause, None, expected, event.show(), event.data), number)


def close_to(got: Sequence[float], want: Sequence[float]) -> bool:
    return len(got) == len(want) and all(
        math.isclose(g, w, abs_tol=ANGLE_TOLERANCE) for g, w in zip(got, want, strict=True)
    )


def _floats_or_nan(body: bytes) -> list[float]:
    """The floats of ``body``, 4 bytes each, NaN where 4 bytes are no F value."""
    out: list[float] = []
    for at in range(0, len(body) - 3, 4):
        try:
            out.append(unpack_f(body[at : at + 4]))
        except (CodecError, ValueError):
            out.append(math.nan)
    return out


def swapped_words(body: bytes) -> list[float]:
    """The floats of ``body`` read with the two words of each swapped (NaN where that is no F value)."""
    whole = len(body) - len(body) % 4
    return _floats_or_nan(b"".join(body[at + 2 : at + 4] + body[at : at + 2] for at in range(0, whole, 4)))


def swap_word_bytes(data: bytes) -> bytes:
    """``data`` with the two bytes of each whole word swapped (an odd last byte as it is)."""
    whole = len(data) & ~1
    return bytes(data[i ^ 1] for i in range(whole)) + data[whole:]


def byte_swapped(event: SideEvent) -> list[float]:
    """The floats of ``event``'s payload read with the two bytes of each word swapped (NaN where that is
    no F value; none when the payload is not whole floats)."""
    body = payload(event)
    if len(body) % 4:
        return []
    return _floats_or_nan(swap_word_bytes(body))


def shown_angles(angles: Sequence[float]) -> str:
    return "(" + " ".join(f"{a:g}" for a in angles) + ")"


def is_op(event: SideEvent, opcode: int) -> bool:
    return event.kind == "packet" and event.opcode == opcode


def wire_of(event: SideEvent) -> WirePacket:
    return WirePacket("s2c", event.opcode, 0, 0, event.data)


def all_of(*checks: Callable[[Events], list[Sighting]]) -> Callable[[Events], list[Sighting]]:
    def check(events: Events) -> list[Sighting]:
        return [s for c in checks for s in c(events)]

    return check


def floats_of(steps: Sequence[Step]) -> tuple[float, ...]:
    step = steps[0]
    assert isinstance(step, RequestStep)
    return tuple(unpack_f(step.data[i : i + 4]) for i in range(0, len(step.data), 4))


# What a connection leaves behind, and the arm's pose after a request --------------------------------

REST: Final = 5.0
"""Seconds of pause after a move of these scenarios (a few tens of degrees: well within it)."""
SEED_ANGLES: Final = CONFIGURATION_SEED
"""Joint angles whose transform has a lefty and a righty solution in range (the configuration cases')."""
SLOW: Final = 0.25
"""The slow speed factor: the one a first connection leaves behind, and the one a swing is timed at."""
SWING_DEG: Final = 30.0
"""How far joint 1 swings in a timed move (from the ready position)."""
MIDWAY: Final = 0.4
"""Seconds after a timed move is answered that the scenario reads the joints: mid-move at factor 1."""
STILL: Final = 1.0
"""Seconds between two reads that show the arm at rest (the same both times) before it is judged."""
INCREMENT: Final = ((0.0, 0.0, -30.0), (25.0, 0.0, 0.0))
"""The deltas (mm) of the two incremental moves queued back to back."""
OAT_TURN: Final = (12.0, 0.0, 0.0)
"""dO dA dT of the incremental turn (dO alone: added to T instead, it shows)."""


def _seed_transform() -> tuple[float, ...]:
    return forward(SEED_ANGLES, PUMA600.geometry).to_floats()


def solve_seed() -> RequestStep:
    return req("solve-forwards", floats_data(_seed_transform()) + floats_data(SEED_ANGLES))


def word(value: int) -> bytes:
    return struct.pack("<H", value)


def _responses(events: Events, number: int, name: RequestName) -> list[SideEvent]:
    return [e for e in answers_to(events.get(number, []), opcode_of(name)) if e.opcode == ServerOp.RESPONSE]


def solution_at(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    """The first solve forwards answered with six angles at input ``number``."""
    for answer in _responses(events, number, "solve-forwards"):
        angles = angles_of(answer)
        if angles is not None and len(angles) == 6:
            return answer, angles
    return None


def segments_at(events: Events, number: int) -> list[tuple[SideEvent, int]]:
    """Every set joint angles of input ``number`` answered with a segment number, and the number."""
    return [
        (answer, int.from_bytes(answer.data[2:4], "little"))
        for answer in _responses(events, number, "set-joint-angles")
        if len(answer.data) >= 4
    ]


def segment_at(events: Events, number: int) -> tuple[SideEvent, int] | None:
    """The first segment number a set joint angles was answered with at input ``number``."""
    return next(iter(segments_at(events, number)), None)


def floats_at(events: Events, number: int, name: RequestName) -> list[tuple[SideEvent, list[float]]]:
    """Every answer of ``name`` at input ``number`` read as floats, in order."""
    out = []
    for answer in _responses(events, number, name):
        values = angles_of(answer)
        if values is not None:
            out.append((answer, values))
    return out


def all_done(events: Events, number: int, count: int) -> bool:
    """Whether the ``count`` incremental moves of input ``number`` were each answered with a segment."""
    names: tuple[RequestName, ...] = ("incremental-move", "incremental-straight-move")
    answers = [e for n in names for e in answers_to(events.get(number, []), opcode_of(n))]
    return len(answers) == count and all(e.opcode == ServerOp.RESPONSE for e in answers)


def at_rest(events: Events, number: int) -> bool:
    """Whether the last two Here answers of input ``number``, :data:`STILL` seconds apart, agree."""
    got = floats_at(events, number, "here")
    return len(got) >= 2 and close_to(got[-2][1], got[-1][1])


def read_here(events: Events, number: int) -> tuple[SideEvent, list[float]] | None:
    got = floats_at(events, number, "here")
    return got[-1] if got and len(got[-1][1]) == 12 else None


def timed_move(goal: Sequence[float]) -> list[Step]:
    return [req("set-joint-angles", floats_data(goal)), Pause(MIDWAY), req("joint-angles"), Pause(REST)]


def _progress(start: float, goal: float, at: float) -> float:
    return (at - start) / (goal - start)


def midway_at(events: Events, timed: int) -> tuple[float, float, SideEvent] | None:
    """How far joint 1 got midway through a swing from the ready position (read before it) and midway
    through the one back (read at its goal): the joint angles read four times at input ``timed``."""
    reads = floats_at(events, timed, "joint-angles")
    if len(reads) != 4:
        return None
    start, first, goal, second = (r[1][0] for r in reads)
    there = READY_POSE[0] + SWING_DEG
    if not (close_to([start], [READY_POSE[0]]) and close_to([goal], [there])):
        return None
    return _progress(start, there, first), _progress(there, start, second), reads[1][0]


def rest_at(angles: Sequence[float]) -> tuple[str, Sequence[Step]]:
    """An input that powers the arm, sets its joints to ``angles``, lets it come to rest and reads Here."""
    return (
        "enable power, set joint angles, rest, here",
        [req("enable-power"), req("set-joint-angles", floats_data(angles)), Pause(REST), req("here")],
    )
