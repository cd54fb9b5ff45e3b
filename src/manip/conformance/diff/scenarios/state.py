"""The diff's scenarios of reading the arm back: describe self, limits, read back, ready, speeds, no
power, free joint."""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from typing import Final

from manip.arm.kinematics import PUMA600
from manip.codecs.pdp11float import pack_f
from manip.conformance.diff.scenarios.kit import (
    POSE,
    READY_POSE,
    SETTLE,
    Events,
    all_of,
    answer_at,
    answers_to,
    close_to,
    description_at,
    error_in,
    floats_data,
    floats_of,
    opcode_of,
    payload,
    read_back,
    req,
    scenario_inputs,
    scenario_stream,
    shown_angles,
    sighting,
    swapped_words,
)
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import Pause, RequestStep, Step
from manip.spec import SPEC
from manip.spec.constants import ServerOp

# The checks ----------------------------------------------------------------------------------------


def _check_read_back(at: int, pose: Sequence[float]) -> Callable[[Events], list[Sighting]]:
    """Joint angles read at input ``at`` after the arm was set to ``pose`` and came to rest."""

    def check(events: Events) -> list[Sighting]:
        got = read_back(events, at)
        if got is None or close_to(got[1], pose):
            return []
        answer, angles = got
        expected = f"the angles set, {shown_angles(pose)}, one per joint from the base"
        if close_to(swapped_words(payload(answer)), pose):
            message = f"joint angles read {shown_angles(angles)}: the angles set with their two words swapped"
            return [sighting(at, "float.format", message, expected, answer)]
        message = f"joint angles read {shown_angles(angles)} after the arm was set to {shown_angles(pose)}"
        return [sighting(at, "joint-angles.reply", message, expected, answer)]

    return check


def _check_ready(described: int, before: int, after: int) -> Callable[[Events], list[Sighting]]:
    """After move to ready, the arm is at the stated :ready-position (``describe.ready-position``); a
    wrist left where it stood before is ``ready.pose`` broken (the ready position moves every joint)."""

    def check(events: Events) -> list[Sighting]:
        entries, got, prior = (
            description_at(events, described),
            read_back(events, after),
            read_back(events, before),
        )
        stated = entries.get("ready-position") if entries is not None else None
        if (
            got is None
            or not isinstance(stated, list)
            or not all(isinstance(x, (int, float)) for x in stated)
        ):
            return []
        want = [float(x) for x in stated]
        answer, angles = got
        if close_to(angles, want):
            return []
        if prior is not None and close_to(angles[3:], prior[1][3:]) and not close_to(prior[1][3:], want[3:]):
            message = f"after move to ready the wrist joints stayed at {shown_angles(angles[3:])}"
            return [
                sighting(after, "ready.pose", message, f"the ready position {shown_angles(want)}", answer)
            ]
        message = f"after move to ready the arm is at {shown_angles(angles)}, not the stated ready position"
        return [sighting(after, "describe.ready-position", message, shown_angles(want), answer)]

    return check


def _check_description(at: int) -> Callable[[Events], list[Sighting]]:
    """What describe self states at input ``at``: :joint-limits one (lower upper) pair per degree of
    freedom, lower not above upper (``describe.joint-limits-count``)."""

    def check(events: Events) -> list[Sighting]:
        entries = description_at(events, at)
        limits, dof = (entries or {}).get("joint-limits"), (entries or {}).get("degrees-of-freedom")
        if not isinstance(limits, list) or not isinstance(dof, int):
            return []
        pairs = [p for p in limits if isinstance(p, list) and len(p) == 2 and p[0] <= p[1]]
        if len(pairs) == len(limits) == dof:
            return []
        first = answers_to(events.get(at, []), opcode_of("describe-self"))[0]
        message = f":joint-limits holds {len(pairs)} well-formed pair(s) of {len(limits)} for {dof} joints"
        return [sighting(at, "describe.joint-limits-count", message, f"{dof} (lower upper) pairs", first)]

    return check


def _stated_limits(events: Events, at: int) -> tuple[tuple[float, float], ...]:
    entries = description_at(events, at) or {}
    stated = entries.get("joint-limits")
    pairs = stated if isinstance(stated, list) else []
    if len(pairs) == 6 and all(isinstance(p, list) and len(p) == 2 for p in pairs):
        return tuple((float(p[0]), float(p[1])) for p in pairs)
    return tuple(zip(PUMA600.limits.lower, PUMA600.limits.upper, strict=True))


def _check_jor(described: int, probes: dict[int, tuple[float, ...]]) -> Callable[[Events], list[Sighting]]:
    """Set joint angles beyond a limit (the stated ones, else the PUMA 600's) is refused E JOR, whose
    number is the mask of the joints beyond (erratum error-arg-values)."""

    def check(events: Events) -> list[Sighting]:
        limits = _stated_limits(events, described)
        out: list[Sighting] = []
        for number, angles in probes.items():
            mask = sum(
                1 << j
                for j, (a, (lo, hi)) in enumerate(zip(angles, limits, strict=True))
                if not lo <= a <= hi
            )
            answer = answer_at(events, number, "set-joint-angles")
            if not mask or answer is None:
                continue
            if answer.opcode == ServerOp.RESPONSE:
                message = "set joint angles beyond a joint's limit was accepted"
                out.append(sighting(number, "motion.checked-before-queue", message, "E JOR", answer))
            if (error := error_in(answer, ServerOp.NON_FATAL_ERROR)) is None:
                continue
            if error.code != "JOR":
                message = f"set joint angles beyond a joint's limit was refused {error.code}, not JOR"
                out.append(sighting(number, "motion.checked-before-queue", message, "E JOR", answer))
            elif error.args and error.args != (mask,):
                message = f"E JOR carries {list(error.args)}, not the mask of the joints beyond their limits"
                out.append(sighting(number, "error-string.arg-values", message, f"the mask {mask}", answer))
        return out

    return check


# The scenarios -------------------------------------------------------------------------------------


def _probe_data(opcode: int) -> bytes:
    op = SPEC.requests.get(opcode)
    size = op.request.fixed_size if op is not None else None
    return bytes((size or 0) + 2)


def _describe_probe() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [("describe self", [req("describe-self")])]
    groups += [
        (f"opcode 0{op:o} with a wrong length", [RequestStep(op, _probe_data(op))])
        for op in range(0o200, 0o300)
    ]
    return Stream(
        None,
        scenario_inputs("describe-probe", groups),
        scenario="describe-probe",
        check=_check_description(0),
    )


def _limits() -> Stream:
    """Each joint just inside and just beyond the PUMA 600's upper limit (the outer side only, as the
    describe cases probe): inside is done on an arm of those limits, beyond is JOR, and either one
    judged against the limits describe self stated."""
    upper = PUMA600.limits.upper
    groups: list[tuple[str, Sequence[Step]]] = [
        ("describe self, enable power", [req("describe-self"), req("enable-power")])
    ]
    for joint in range(6):
        for past in (-1.0, 1.0):
            angles = list(READY_POSE)
            angles[joint] = upper[joint] + past
            where = "inside" if past < 0 else "beyond"
            groups.append(
                (
                    f"joint {joint + 1} one degree {where} its limit",
                    [req("set-joint-angles", floats_data(angles))],
                )
            )
    probes = {n: floats_of(steps) for n, (_, steps) in enumerate(groups) if n and n % 2 == 0}
    check = all_of(_check_description(0), _check_jor(0, probes))
    return scenario_stream("joint-limits", groups, check)


def _read_back_scenario() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "enable power, set joint angles, rest",
            [req("enable-power"), req("set-joint-angles", floats_data(POSE)), Pause(SETTLE)],
        ),
        ("joint angles", [req("joint-angles")]),
    ]
    return Stream(
        None, scenario_inputs("read-back", groups), scenario="read-back", check=_check_read_back(1, POSE)
    )


def _ready() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("describe self", [req("describe-self")]),
        (
            "enable power, set joint angles, rest",
            [req("enable-power"), req("set-joint-angles", floats_data(POSE)), Pause(SETTLE)],
        ),
        ("joint angles", [req("joint-angles")]),
        ("move to ready, rest", [req("ready"), Pause(SETTLE)]),
        ("joint angles", [req("joint-angles")]),
    ]
    check = all_of(_check_description(0), _check_read_back(2, POSE), _check_ready(0, 2, 4))
    return scenario_stream("ready", groups, check)


def _speeds() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (f"set speed {v:g}", [req("set-speed", pack_f(v))]) for v in (0.0, -0.5, 1.5, 100.0, 0.5)
    ]
    return scenario_stream("speed-range", groups)


def _no_power() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        (
            "set joint angles without power (the preamble killed it)",
            [req("set-joint-angles", floats_data(POSE))],
        ),
        ("move to ready without power", [req("ready")]),
        ("here", [req("here")]),
    ]
    return scenario_stream("no-power", groups)


def _free_joint() -> Stream:
    groups: list[tuple[str, Sequence[Step]]] = [
        ("enable power, free joint 3", [req("enable-power"), req("free-joint", struct.pack("<H", 3))]),
        ("joint angles (discarded)", [req("joint-angles")]),
        ("here, kill power", [req("here"), req("kill-power")]),
    ]
    return scenario_stream("free-joint", groups)


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    "describe-probe": _describe_probe,
    "joint-limits": _limits,
    "read-back": _read_back_scenario,
    "ready": _ready,
    "speed-range": _speeds,
    "no-power": _no_power,
    "free-joint": _free_joint,
}
"""This module's scenarios by name, in the order a diff sends them."""
