"""Describe self (E.1 Opcode 200): the multi-packet reply, its alist, and that what it states holds on
the wire (erratum describe-self-truthful): the operations listed are those served, the degrees of
freedom are the joint vectors' length, the joint limits stated are where JOR starts."""

from __future__ import annotations

from typing import Final

from manip.codecs.lisp import LispValue
from manip.codecs.pdp11float import pack_f
from manip.conformance.cases._support import (
    error_of,
    expect_error_numbers,
    expect_refusal,
    floats,
    power_on,
    read_floats,
    require_response,
    stated_limits,
)
from manip.conformance.judge.checks import (
    WirePacket,
    check_description_entries,
    check_reply,
    description_operations,
    multi_text,
    parse_description,
    required_refusal,
    word,
)
from manip.conformance.judge.violation import showing
from manip.conformance.suite.case import case
from manip.conformance.suite.context import Answer, CaseContext, Probe
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from manip.spec.model import Hazard
from manip.spec.notation import octal, octal_words


async def _describe(ctx: CaseContext, probe: Probe) -> Answer:
    answer = await probe.call("describe-self")
    ctx.check(check_reply(answer.request, answer.packets))
    return answer


async def _entries(ctx: CaseContext, probe: Probe | None = None) -> dict[str, LispValue]:
    probe = probe or await ctx.connect()
    answer = await _describe(ctx, probe)
    entries, violations = parse_description(multi_text(answer.packets))
    ctx.check(violations)
    assert entries is not None
    return entries


@case(
    "server.describe.reply-shape",
    clauses=[
        "describe.reply-shape",
        "multi.terminated-by-empty",
        "multi.same-request-number",
        "request.one-reply",
    ],
)
async def reply_shape(ctx: CaseContext) -> None:
    """Text packets with the request number, ended by an empty RESPONSE, and nothing more."""
    probe = await ctx.connect()
    answer = await _describe(ctx, probe)
    ctx.expect(
        answer.terminated,
        clause="multi.terminated-by-empty",
        expected="an empty RESPONSE ending the reply",
        seen=showing(answer.packets[-1], f"{len(answer.packets)} packet(s), no terminator"),
    )
    ctx.note(f"{len(answer.packets) - 1} text packet(s)")
    after = await probe.call("here")  # the next answer belongs to the next request
    ctx.expect_echo(
        after,
        clause="request.one-reply",
        expected=f"the reply to request #{after.request.packet_no} after the terminator",
    )


@case(
    "server.describe.alist",
    clauses=["describe.alist-readable", "describe.alist-shape", "describe.numbers-octal"],
)
async def alist(ctx: CaseContext) -> None:
    """The concatenated text is one alist of keyword entries, numbers in octal."""
    entries = await _entries(ctx)
    ops = description_operations(entries)
    wrong = [o for o in ops if not 0o200 <= o <= 0o377]
    ctx.expect(
        not wrong,
        clause="describe.numbers-octal",
        expected=":operations opcodes in 200-377 read in octal",
        seen=f"{octal_words(wrong)} (written in decimal?)",
    )


@case("server.describe.protocol-version", clauses=["describe.protocol-version"])
async def protocol_version(ctx: CaseContext) -> None:
    """:protocol-version is 1."""
    entries = await _entries(ctx)
    ctx.check(f for f in check_description_entries(entries) if f.clause == "describe.protocol-version")


@case(
    "server.describe.keys",
    clauses=[
        "describe.brand-name",
        "describe.unique-name",
        "describe.degrees-of-freedom",
        "describe.operations",
        "describe.software-version",
    ],
)
async def keys(ctx: CaseContext) -> None:
    """:brand-name, :unique-name, :degrees-of-freedom, :operations, :software-version shaped as E.1 says."""
    entries = await _entries(ctx)
    ctx.check(f for f in check_description_entries(entries) if f.clause != "describe.protocol-version")


# ------------------------------------------------------------------ what describe self states holds
# Erratum describe-self-truthful: an opcode is served unless a request for it is refused as unserved
# (C UOP or C UIM) whatever its data, so each opcode is probed with data of a wrong length: a served one
# is refused as a bad length (C BDL) and nothing runs.  The opcodes are split by hazard, as the
# negative cases split their malformed requests, so that on hardware the motion and power ones are sent
# (even malformed) only with --allow-motion.

NOT_SERVED_CODES: Final = ("UOP", "UIM")
"""Error codes that say an opcode is not served (erratum unknown-opcode; UIM: not on this robot)."""
REQUEST_OPCODES: Final = range(0o200, 0o300)
"""The request opcodes a client may send (8-bit data opcodes 0200-0277)."""
LIMIT_MARGIN_DEG: Final = 0.5
"""How far beyond a stated joint limit the joint-limits case asks a joint to go."""


def _hazard_of(opcode: int) -> Hazard:
    op = SPEC.requests.get(opcode)
    return op.hazard if op is not None else "read-only"  # an unknown opcode is refused (or judged) as one


def malformed(opcode: int) -> bytes:
    """Data of a length the opcode's layout refuses (any data for an opcode the spec does not define)."""
    op = SPEC.requests.get(opcode)
    if op is None:
        return b""
    size = op.request.fixed_size
    for data in ((bytes((size or 0) + 1),) if size is not None else ()) + (b"", b"\0", bytes(3)):
        if required_refusal(opcode, data) is not None:
            return data
    raise AssertionError(f"no malformed data for {op.name}")


def _served(answer: Answer, not_served: tuple[str, ...] = NOT_SERVED_CODES) -> bool | None:
    """Whether the answer says the opcode is served (None: an error string too broken to tell)."""
    if answer.opcode != ServerOp.NON_FATAL_ERROR:
        return True
    error = error_of(answer)
    if error is None:
        return None
    return error.error.code not in not_served


async def _unserved_codes(ctx: CaseContext, probe: Probe) -> tuple[str, ...]:
    """UOP and UIM, and the code the target refuses an opcode no spec defines with: the 1985 guide names
    none for it, so a server written from the guide picks its own (erratum unnamed-error-codes)."""
    unknown = next(code for code in REQUEST_OPCODES if code not in SPEC.requests)
    answer = await probe.call_raw(unknown, b"")
    error = error_of(answer) if answer.opcode == ServerOp.NON_FATAL_ERROR else None
    if error is None or error.error.severity != "C" or error.error.code in NOT_SERVED_CODES:
        return NOT_SERVED_CODES
    ctx.note(f"the target refuses an opcode it does not know ({octal(unknown)}) with C {error.error.code}")
    return (*NOT_SERVED_CODES, error.error.code)


_OPERATIONS_CASES: Final[tuple[tuple[str, tuple[Hazard, ...], str], ...]] = (
    (
        "server.describe.operations-served",
        ("read-only", "config"),
        "Every read-only/config opcode listed under :operations is served, every one served is listed.",
    ),
    (
        "server.describe.operations-motion",
        ("motion", "power"),
        "Every motion/power opcode listed under :operations is served, every one served is listed.",
    ),
)


@case.each(_OPERATIONS_CASES)
def _operations_case(row: tuple[str, tuple[Hazard, ...], str]) -> None:
    case_id, hazards, summary = row

    async def operations(ctx: CaseContext) -> None:
        probe = await ctx.connect()
        entries = await _entries(ctx, probe)
        listed = set(description_operations(entries))
        probed = [code for code in REQUEST_OPCODES if _hazard_of(code) in hazards]
        not_served = await _unserved_codes(ctx, probe)
        served: list[int] = []
        for opcode in probed:
            answer = await probe.call_raw(opcode, malformed(opcode))
            verdict = _served(answer, not_served)
            if verdict is None:
                ctx.note(f"opcode {octal(opcode)}: the error string does not decode; not judged")
                continue
            if verdict:
                served.append(opcode)
            operations = f":operations {' '.join(octal(o) for o in sorted(listed))}"
            ctx.expect(
                verdict or opcode not in listed,
                clause="describe.operations-answered",
                expected=f"opcode {octal(opcode)}, listed under :operations, served",
                seen=showing(answer, f"refused as unserved: {answer}"),
            )
            ctx.expect(
                not verdict or opcode in listed,
                clause="describe.operations-complete",
                expected=f"opcode {octal(opcode)} listed under :operations: it is served "
                "(not refused unserved)",
                seen=showing(answer, f"answered with {answer}; {operations}"),
            )
        ctx.note(f"served: {' '.join(octal(o) for o in served)} ({len(served)} of {len(probed)} probed)")

    case(
        case_id,
        clauses=["describe.operations-answered", "describe.operations-complete"],
        summary=summary,
        hazard=hazards[-1],
        deadline=10.0,
    )(operations)


async def _stated_dof(ctx: CaseContext, probe: Probe) -> int:
    entries = await _entries(ctx, probe)
    value = entries.get("degrees-of-freedom")
    value = value[0] if isinstance(value, list) and len(value) == 1 else value
    if not isinstance(value, int) or isinstance(value, bool) or value <= 0:
        ctx.not_judged(f"no usable :degrees-of-freedom ({value!r}; server.describe.keys judges it)")
    return value


def _float_count(answer: Answer) -> int | None:
    body = len(answer.data) - 2
    return body // 4 if answer.is_response and body >= 0 and body % 4 == 0 else None


@case("server.describe.degrees-of-freedom", clauses=["describe.dof-joint-vectors"])
async def degrees_of_freedom(ctx: CaseContext) -> None:
    """:degrees-of-freedom is the number of joint angles that joint angles and solve forwards return."""
    probe = await ctx.connect()
    dof = await _stated_dof(ctx, probe)
    joints = await probe.call("joint-angles")
    if not joints.is_response:
        require_response(ctx, joints, "joint angles")  # refused: not judged
    ctx.expect(
        _float_count(joints) == dof,
        clause="describe.dof-joint-vectors",
        expected=f"{dof} joint angles (:degrees-of-freedom {dof})",
        seen=showing(joints, f"{len(joints.data) - 2} data bytes after the request number"),
    )
    require_response(ctx, joints, "joint angles")  # a reply off the layout is the transcript invariant's
    pose = await read_floats(ctx, probe, "here")
    solved = await probe.call("solve-forwards", transform=list(pose), current=list(floats(joints)))
    if not solved.is_response:
        ctx.note(f"solve forwards of the arm's own pose was refused ({solved}); its length not judged")
        return
    ctx.expect(
        _float_count(solved) == dof,
        clause="describe.dof-joint-vectors",
        expected=f"{dof} joint angles from solve forwards (:degrees-of-freedom {dof})",
        seen=showing(solved, f"{len(solved.data) - 2} data bytes after the request number"),
    )


@case("server.describe.dof-set-joint-angles", clauses=["describe.dof-joint-vectors"], hazard="motion")
async def dof_set_joint_angles(ctx: CaseContext) -> None:
    """Set joint angles takes :degrees-of-freedom floats as well formed and refuses other counts.

    Sent on a fresh connection (arm power off: the well-formed request draws NAP), to where the arm
    stands; no request here can move a conforming arm."""
    probe = await ctx.connect()
    dof = await _stated_dof(ctx, probe)
    here = list(await read_floats(ctx, probe, "joint-angles"))
    opcode = SPEC.request("set-joint-angles").opcode
    for count in (dof, dof + 1, dof - 1):
        if count <= 0:
            continue
        angles = (here + [0.0] * count)[:count]
        answer = await probe.call_raw(opcode, b"".join(pack_f(a) for a in angles))
        error = error_of(answer)
        command_error = error is not None and error.error.severity == "C"
        ctx.expect(
            command_error != (count == dof),
            clause="describe.dof-joint-vectors",
            expected=f"set joint angles with {count} floats "
            + ("taken as well formed (no command error)" if count == dof else "refused as a bad length (C)")
            + f": :degrees-of-freedom is {dof}",
            seen=showing(answer, str(answer) if error is None else repr(error.error.render())),
        )


def _is_range(pair: LispValue) -> bool:
    """A (lower upper) pair of numbers, lower not above upper."""
    if not isinstance(pair, list) or len(pair) != 2:
        return False
    lo, hi = pair
    numbers = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (lo, hi))
    return numbers and float(lo) <= float(hi)  # type: ignore[arg-type]


@case(
    "server.describe.joint-limits",
    clauses=["describe.joint-limits", "describe.joint-limits-count", "error-string.arg-values"],
    hazard="power",
    deadline=10.0,
)
async def joint_limits(ctx: CaseContext) -> None:
    """:joint-limits holds one (lower upper) pair per degree of freedom, and a joint just beyond a stated
    limit is refused with JOR naming that joint (the others stay where the arm stands); only the outer
    side is probed, so a conforming arm never moves."""
    probe = await ctx.connect()
    entries = await _entries(ctx, probe)
    if "joint-limits" not in entries:
        ctx.skip("the description states no :joint-limits")
    stated = entries["joint-limits"]
    dof = await _stated_dof(ctx, probe)
    count = len(stated) if isinstance(stated, list) else None
    ctx.expect(
        count == dof,
        clause="describe.joint-limits-count",
        expected=f":joint-limits with {dof} (lower upper) pairs, one per degree of freedom",
        seen=f"{count} entries: {stated!r}" if count is not None else repr(stated),
    )
    ctx.expect(
        isinstance(stated, list) and all(_is_range(pair) for pair in stated),
        clause="describe.joint-limits-count",
        expected="each entry a (lower upper) pair of numbers, lower not above upper",
        seen=repr(stated),
    )
    limits = stated_limits(stated)
    if limits is None:
        ctx.skip(f"JOR is probed on six-joint arms only: :joint-limits {stated!r}")
    await power_on(ctx, probe)  # without power, NAP may come first (erratum abort-before-power)
    here = await read_floats(ctx, probe, "joint-angles")
    for joint, (lower, upper) in enumerate(zip(limits.lower, limits.upper, strict=True)):
        for side, goal in (("lower", lower - LIMIT_MARGIN_DEG), ("upper", upper + LIMIT_MARGIN_DEG)):
            angles = list(here)
            angles[joint] = goal
            answer = await probe.call("set-joint-angles", joints=angles)
            what = f"joint {joint + 1} at {goal:g} degrees, beyond its stated {side} limit"
            error = expect_refusal(
                ctx,
                answer,
                clause="describe.joint-limits",
                severities=("E", "C"),
                codes=("JOR",),
                what=what,
            )
            expect_error_numbers(ctx, answer, error, [(1 << joint,)], what=what)


SPLIT_MOVES: Final = 4
"""Short moves queued so that segment-completed reports fall due around the describe-self requests."""
SPLIT_STEP_DEG: Final = 0.5
SPLIT_DESCRIBES: Final = 6
"""Describe-self requests sent while the moves run."""
SPLIT_IDLE_S: Final = 3.0
"""Seconds the case sends nothing once the moves are queued, so their reports fall due between requests."""


@case(
    "server.describe.not-split",
    clauses=["multi.not-split"],
    hazard="motion",
    deadline=30.0,
    extensions=["request-notifications"],
)
async def not_split(ctx: CaseContext) -> None:
    """No asynchronous packet comes between the packets of a describe-self reply: with segment-completed
    reports asked for, describe self is asked while short moves complete, and again right after the case
    has sent nothing while they all completed (a server that holds the other processes' reports for its
    next request must still send them before or after the whole reply)."""
    probe = await ctx.connect()
    await power_on(ctx, probe)
    require_response(ctx, await probe.call("request-notifications", mask=1 << 1), "segment notifications")
    start = await read_floats(ctx, probe, "joint-angles")
    sign = 1.0 if start[0] <= 0 else -1.0
    try:
        for n in range(1, SPLIT_MOVES + 1):
            goal = list(start)
            goal[0] += sign * SPLIT_STEP_DEG * n
            require_response(
                ctx, await probe.call("set-joint-angles", joints=goal), "a short move of joint 1"
            )
        for _ in range(SPLIT_DESCRIBES):
            await probe.call("describe-self")
        for n in range(SPLIT_MOVES - 1, -1, -1):
            goal = list(start)
            goal[0] += sign * SPLIT_STEP_DEG * n
            require_response(ctx, await probe.call("set-joint-angles", joints=goal), "a short move back")
        await probe.drain(SPLIT_IDLE_S)
        await probe.call("describe-self")
    finally:
        await probe.call("request-notifications", mask=0)
    for inside in _inside_replies(probe, SPEC.request("describe-self").opcode):
        ctx.expect(
            not inside,
            clause="multi.not-split",
            expected="the packets of a describe-self reply one after the other, up to its terminator",
            seen=inside,
        )


def _inside_replies(probe: Probe, opcode: int) -> list[list[WirePacket]]:
    """For each request of ``opcode`` on ``probe`` (sent one at a time), the packets other than responses
    that came between the first packet of its reply and the last (a response numbered wrongly is
    a violation of multi.same-request-number, not an intruder)."""
    out: list[list[WirePacket]] = []
    numbers = {p.packet_no for p in probe.packets if p.direction == "c2s" and p.opcode == opcode}
    sent = [p for p in probe.packets if p.direction == "s2c"]
    for number in sorted(numbers):
        mine = [i for i, p in enumerate(sent) if p.opcode == ServerOp.RESPONSE and word(p.data) == number]
        if mine:
            out.append([p for p in sent[mine[0] : mine[-1] + 1] if p.opcode != ServerOp.RESPONSE])
    return out
