"""Helpers of the client cases: operations, exact values to send, and the checks of what the harness
reported against what the judging server sent."""

from __future__ import annotations

import random
from collections.abc import Iterable, Mapping
from typing import Any, Final

from manip.codecs.error_string import ErrorMessage, format_joint_mask
from manip.codecs.messages import decode_reply, response_layout
from manip.codecs.pdp11float import u32_to_f
from manip.conformance.client.contract import Op, Result
from manip.conformance.client.runner import ClientContext, Play
from manip.conformance.judge.diagnosis import number_diagnosis
from manip.conformance.judge.violation import Violation, showing
from manip.spec import SPEC
from manip.spec.constants import ServerOp
from manip.spec.model import FieldType, Layout, RequestOpcode

__all__ = [
    "close",
    "connect",
    "error_parts",
    "exact_float",
    "expect_reply",
    "expected_raw",
    "raw_words",
    "reply_mismatches",
    "request",
    "wait",
]

LARGEST: Final = (1 - 2**-24) * 2.0**127
SMALLEST: Final = 2.0**-128


def connect(i: int = 0) -> Op:
    return Op(i, "connect")


def close(i: int) -> Op:
    return Op(i, "close")


def wait(i: int, seconds: float) -> Op:
    return Op(i, "wait", seconds=seconds)


def request(i: int, name: str, args: Mapping[str, Any] | None = None, **kw: Any) -> Op:
    return Op(i, name, args=None if args is None else dict(args), **kw)


def exact_float(rng: random.Random, *, low: int = 100, high: int = 160) -> float:
    """A random PDP-11 F float (exponent in ``low..high``), exact in binary64 and in JSON."""
    sign = rng.getrandbits(1) << 15
    exponent = rng.randint(low, high)
    fraction = rng.getrandbits(23)
    w0 = sign | exponent << 7 | fraction >> 16
    w1 = fraction & 0xFFFF
    return u32_to_f(w0 | w1 << 16)


def field_value(rng: random.Random, ft: FieldType) -> Any:
    """A random value of a spec field type."""
    count = ft.count or rng.randint(0, 6)
    if ft.element == "float":
        items: list[Any] = [exact_float(rng) for _ in range(count)]
    elif ft.element == "int16":
        items = [rng.randint(-32768, 32767) for _ in range(count)]
    elif ft.element == "small":
        items = [rng.randint(0, 255) for _ in range(count)]
    else:
        items = [rng.randint(0, 0xFFFF) for _ in range(count)]
    return items if ft.count != 1 else items[0]


def layout_values(rng: random.Random, layout: Layout) -> dict[str, Any]:
    return {f.name: field_value(rng, f.type) for f in layout.fields}


def expected_raw(layout: Layout, data: bytes) -> dict[str, list[str]]:
    """The contract's ``raw`` of reply data: per element a hex string, a float's sign/exponent word
    first."""
    out: dict[str, list[str]] = {}
    pos = 0
    for f in layout.fields:
        element, count = f.type.element, f.type.count
        if element == "counted":
            count, element = int.from_bytes(data[pos : pos + 2], "little"), "word"
            pos += 2
        items: list[str] = []
        for _ in range(count or 0):
            if element == "float":
                w0 = int.from_bytes(data[pos : pos + 2], "little")
                w1 = int.from_bytes(data[pos + 2 : pos + 4], "little")
                items.append(f"{w0:04X}{w1:04X}")
                pos += 4
            else:
                items.append(f"{int.from_bytes(data[pos : pos + 2], 'little'):04X}")
                pos += 2
        out[f.name] = items
    return out


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


def _same(a: Any, b: Any) -> bool:
    """Equal as the contract means it: numbers exactly (a float to the bit), lists element-wise."""
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, bool) or isinstance(b, bool):
        return False
    if isinstance(a, int | float) and isinstance(b, int | float):
        return float(a) == float(b)
    return bool(a == b)


def raw_words(seen: Any) -> list[str] | None:
    """A ``raw`` field as upper-case hex strings: an array of strings, or a bare string standing for an
    array of one (docs/client-harness.md: a field of one element may be written either way, for every
    opcode); None for anything else."""
    if isinstance(seen, str):
        return [seen.upper()]
    if not isinstance(seen, list) or not all(isinstance(i, str) for i in seen):
        return None
    return [i.upper() for i in seen]


def reply_expectation(
    op: RequestOpcode, payload: bytes, number: int
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The ``values`` and ``raw`` a reply carrying ``payload`` must be reported with."""
    kind = op.response.form
    if kind == "done":
        return {}, {}
    if kind == "segment":
        segment = int.from_bytes(payload[:2], "little")
        return {"segment": segment}, {"segment": f"{segment:04X}"}
    reply = decode_reply(number.to_bytes(2, "little") + payload, op)
    values = {k: _plain(v) for k, v in reply.values.items()}
    return values, expected_raw(response_layout(op), payload)


def reply_mismatches(
    op: RequestOpcode, payload: bytes, number: int, data: Mapping[str, Any]
) -> list[tuple[str, str]]:
    """How the ``values`` and ``raw`` of a reply result (``data``) differ from what ``payload`` says,
    as (expected, seen) pairs: empty when the reply is reported exactly."""
    out: list[tuple[str, str]] = []
    values, raw = reply_expectation(op, payload, number)
    got_values = data.get("values") or {}
    for name, value in values.items():
        if not _same(_plain(got_values.get(name)), value):
            out.append((f"{op.name} {name} = {value!r} (what the judge sent)", f"{got_values.get(name)!r}"))
    got_raw = data.get("raw") or {}
    for name, words in raw.items():
        want = raw_words(words)
        if raw_words(got_raw.get(name)) != want:
            out.append((f"{op.name} {name} raw words {want}", f"{got_raw.get(name)!r}"))
    return out


def expect_reply(
    ctx: ClientContext,
    play: Play,
    op_id: int,
    op: RequestOpcode,
    payload: bytes,
    number: int,
    *,
    clause: str,
) -> Result:
    """The op's result is a reply with exactly the values and raw words the judge sent."""
    answer = play.answer(op_id)
    ctx.expect(
        answer is not None and answer.type == "reply",
        clause=clause,
        expected=f"a reply to op {op_id} ({op.name})",
        seen=str(answer) if answer is not None else f"no result for op {op_id}:\n{play.describe()}",
    )
    assert answer is not None
    if any(f.type.element == "float" for f in response_layout(op).fields):
        ctx.exercised("float.format")  # every value is compared exactly, so the floats' decoding is judged
    for expected, seen in reply_mismatches(op, payload, number, answer.data):
        ctx.expect(False, clause=clause, expected=expected, seen=showing(payload, seen))
    return answer


def expect_wire(ctx: ClientContext, violations: Iterable[Violation], *, clause: str) -> None:
    """A wire judge's verdict on ``clause`` (``client.wire``): the clause is reached whatever it found
    (a clean client's judged packets are a pass, not "not exercised"), and each violation is reported
    with its packet."""
    ctx.exercised(clause)
    for violation in violations:
        ctx.expect(
            False,
            clause=clause,
            expected=violation.expected,
            seen=showing(violation.packet, violation.actual),
        )


ORIGIN_OPCODES: Final = {
    "fatal-error": ServerOp.FATAL_ERROR,
    "non-fatal-error": ServerOp.NON_FATAL_ERROR,
    "asynchronous-error": ServerOp.ASYNCHRONOUS_ERROR,
    "asynchronous-warning": ServerOp.ASYNCHRONOUS_WARNING,
}
"""The server opcode of each ``origin`` of an error result the server caused."""


def sent_numbers(play: Play, opcode: int, text: bytes) -> set[int]:
    """The request numbers (first data word) of the server's packets of ``opcode`` carrying ``text``."""
    return {
        int.from_bytes(r.packet.data[:2], "little")
        for r in play.wire
        if r.dir == "s2c" and r.packet.opcode == opcode and text in r.packet.data[2:]
    }


def expect_error_parts(
    ctx: ClientContext,
    result: Result | None,
    error: ErrorMessage,
    origin: str,
    *,
    clause: str,
    play: Play,
    ops: tuple[int | None, ...],
) -> None:
    """An ``error`` result with ``origin`` and the error string's parts, rendered as the contract says;
    its ``op`` one of ``ops`` and its ``request_number`` the first data word of the error packet the
    judging server sent (docs/client-harness.md section 5)."""
    ctx.expect(
        result is not None and result.type == "error" and result.get("origin") == origin,
        clause=clause,
        expected=f"an error result of origin {origin}",
        seen=str(result),
    )
    assert result is not None
    ctx.expect(
        result.op in ops,
        clause=clause,
        expected=f"op {' or '.join('null' if o is None else str(o) for o in ops)}",
        seen=f"op {result.op!r} in {result}",
    )
    numbers = sent_numbers(play, ORIGIN_OPCODES[origin], error.message.encode("latin-1"))
    ctx.expect(
        result.get("request_number") in numbers,
        clause=clause,
        expected=f"request_number {' or '.join(str(n) for n in sorted(numbers))}: the first data word "
        "of the error packet",
        seen=f"request_number {result.get('request_number')!r} in {result}",
    )
    for key, value in error_parts(error).items():
        cause = _arguments_cause(result.get(key), list(error.args)) if key == "arguments" else None
        ctx.expect(
            result.get(key) == value,
            clause=clause,
            expected=f"{key} = {value!r}",
            seen=f"{key} = {result.get(key)!r} in {result}",
            message=f"expected {key} = {value!r}; {cause}" if cause else None,
        )


def error_parts(error: ErrorMessage) -> dict[str, Any]:
    """The parts of an ``error`` result for a server's error string, as the contract reports them."""
    message = render(error)
    return {
        "where": error.where,
        "severity": error.severity,
        "code": error.code,
        "template": error.message,
        "arguments": list(error.args),
        "message": message,
        "rendered": f"{error.where}: {error.severity} {error.code}" + (f" {message}" if message else ""),
    }


def _arguments_cause(got: object, want: list[int]) -> str | None:
    """Why the numbers reported differ from the error string's: each one off, or byte-swapped."""
    if not isinstance(got, list) or len(got) != len(want) or not all(isinstance(g, int) for g in got):
        return None
    early = b"\0" + b"".join(w.to_bytes(2, "little") for w in want)  # the pad byte, then the numbers
    if got == [int.from_bytes(early[i : i + 2], "little") for i in range(0, 2 * len(want), 2)]:
        return "the numbers were read one byte early (the pad byte taken for the first number's low byte)"
    causes = {number_diagnosis(g, w, what="argument") for g, w in zip(got, want, strict=True) if g != w}
    if len(causes) != 1 or None in causes:
        return None
    (cause,) = causes
    return f"each number read differs the same way: {cause}"


def render(error: ErrorMessage) -> str:
    """The message as the contract renders it (~ unsigned decimal, $ joints in English)."""
    if not error.has_nul:
        return error.message
    it = iter(error.args)
    out: list[str] = []
    for ch in error.message:
        if ch in "~$":
            arg = next(it, None)
            if arg is not None:
                out.append(str(arg) if ch == "~" else format_joint_mask(arg))
                continue
        out.append(ch)
    return "".join(out)


def spec_request(name: str) -> RequestOpcode:
    return SPEC.requests_by_name[name]
