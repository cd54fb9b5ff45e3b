"""What ``manip-client`` prints: each result as aligned text for people and as JSON for scripts.

Every ``*_record`` function returns a JSON-ready dict; every ``*_text`` function the lines a person
reads (millimetres and degrees, as the protocol's units, erratum ``units``).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from manip.arm.oat import xyzoat_from_transform
from manip.arm.transform import Transform
from manip.codecs.lisp import Cons, Keyword, LispValue, Symbol
from manip.codecs.messages import AsyncResponse
from manip.reference_client.errors import (
    AsynchronousError,
    AsynchronousWarning,
    ConnectionLostError,
    FatalError,
    ManipError,
    NonFatalError,
    OutOfSequenceResponse,
    ReplyTooLargeError,
    RequestTimeout,
    ResponseDataError,
    ServerError,
)
from manip.spec import notation
from manip.spec.constants import AsyncCondition

JSONValue = Any
GUARD_STOPS = 1
OCTAL_KEYS = frozenset({"operations"})
"""describe-self entries whose numbers are opcodes, shown in octal as the 1985 guide writes them."""


def dumps(record: Mapping[str, JSONValue]) -> str:
    return json.dumps(record, sort_keys=False, separators=(", ", ": "))


def aligned(rows: Iterable[tuple[str, str]]) -> list[str]:
    """``label  value`` lines with the values in one column."""
    items = list(rows)
    width = max((len(label) for label, _ in items), default=0)
    return [f"{label:<{width}}  {value}".rstrip() for label, value in items]


# ------------------------------------------------------------------ transforms and joints

XYZOAT_NAMES = ("x", "y", "z", "O", "A", "T")
XYZOAT_UNITS = ("mm", "mm", "mm", "deg", "deg", "deg")


def transform_record(pose: Transform) -> dict[str, JSONValue]:
    x, y, z, o, a, t = xyzoat_from_transform(pose)
    return {
        "xyzoat": {"x": x, "y": y, "z": z, "o": o, "a": a, "t": t},
        "transform": list(pose.to_floats()),
        "matrix": [[float(v) for v in row] for row in pose.matrix],
    }


def transform_text(pose: Transform) -> list[str]:
    values = xyzoat_from_transform(pose)
    lines = aligned(
        (name, f"{value:10.3f} {unit}")
        for name, value, unit in zip(XYZOAT_NAMES, values, XYZOAT_UNITS, strict=True)
    )
    lines.append("")
    lines.append("   " + "".join(f"{col:>11}" for col in ("n", "o", "a", "p")))
    for axis, row in zip("xyz", pose.matrix[:3], strict=True):
        lines.append(f"{axis}  " + "".join(f"{float(v):11.4f}" for v in row))
    return lines


def joints_record(joints: Sequence[float]) -> dict[str, JSONValue]:
    return {"joints": [float(q) for q in joints]}


def joints_text(joints: Sequence[float]) -> list[str]:
    return aligned((f"joint {i}", f"{q:10.3f} deg") for i, q in enumerate(joints, 1))


# ------------------------------------------------------------------ describe self


def lisp_json(value: LispValue) -> JSONValue:
    """A Lisp value as JSON: keywords as ``":name"``, symbols by name, dotted pairs as two-item lists."""
    match value:
        case Keyword(name):
            return f":{name}"
        case Symbol(name):
            return name
        case Cons(car, cdr):
            return [lisp_json(car), lisp_json(cdr)]
        case list():
            return [lisp_json(v) for v in value]
        case _:
            return value


def lisp_text(value: LispValue, *, octal: bool = False) -> str:
    match value:
        case bool():
            return str(value)
        case int():
            return notation.octal(value) if octal else str(value)
        case float():
            return f"{value:g}"
        case str():
            return value
        case Keyword(name):
            return f":{name}"
        case Symbol(name):
            return name
        case Cons(car, cdr):
            return f"({lisp_text(car, octal=octal)} . {lisp_text(cdr, octal=octal)})"
        case list():
            inner = " ".join(
                f"({lisp_text(v, octal=octal)})" if isinstance(v, list) else lisp_text(v, octal=octal)
                for v in value
            )
            return inner
    return repr(value)


def describe_record(alist: Mapping[str, LispValue]) -> dict[str, JSONValue]:
    return {key: lisp_json(value) for key, value in alist.items()}


def describe_text(alist: Mapping[str, LispValue]) -> list[str]:
    return aligned((key, lisp_text(value, octal=key in OCTAL_KEYS)) for key, value in alist.items())


# ------------------------------------------------------------------ asynchronous responses


def async_record(response: AsyncResponse) -> dict[str, JSONValue]:
    record: dict[str, JSONValue] = {
        "type": response.condition_name,
        "request_number": response.request_number,
    }
    if response.condition == AsyncCondition.SEGMENT_COMPLETED:
        record["segment"] = response.word3
    elif response.condition == AsyncCondition.GUARD_HIT:
        record["guard"] = response.word3
        record["stops"] = response.word2 == GUARD_STOPS
    else:
        record["word2"] = response.word2
        record["word3"] = response.word3
    return record


def async_text(response: AsyncResponse) -> str:
    if response.condition == AsyncCondition.SEGMENT_COMPLETED:
        return f"segment {response.word3} completed"
    if response.condition == AsyncCondition.GUARD_HIT:
        effect = "motion stopped" if response.word2 == GUARD_STOPS else "motion continues"
        return f"guard {response.word3} hit ({effect})"
    return (
        f"asynchronous response, condition {response.condition}: "
        f"words {notation.octal_words((response.word2, response.word3))}"
    )


def error_kind(error: ManipError) -> str:
    if isinstance(error, AsynchronousWarning):
        return "warning"
    if isinstance(error, AsynchronousError):
        return "asynchronous-error"
    if isinstance(error, OutOfSequenceResponse):
        return "out-of-sequence"
    return type(error).__name__


def report_record(error: ManipError) -> dict[str, JSONValue]:
    record: dict[str, JSONValue] = {"type": error_kind(error), "message": str(error)}
    if isinstance(error, ServerError):
        record.update(
            where=error.where,
            severity=error.severity,
            code=error.code,
            text=error.message,
            arguments=list(error.arguments),
            request_number=error.request_number,
        )
    return record


def report_text(error: ManipError) -> str:
    if isinstance(error, ServerError):
        return f"{error_kind(error)}: {error.rendered}"
    return f"{error_kind(error)}: {error}"


# ------------------------------------------------------------------ errors on stderr


def error_line(error: BaseException) -> str:
    """The one line ``manip-client`` prints on stderr for a failure (without the program name)."""
    if isinstance(error, ServerError):
        meaning = error.meaning or error.message
        fatal = "fatal error " if isinstance(error, FatalError) else ""
        extension = error.unserved_extension
        note = f"; {extension} that this server does not serve" if extension else ""
        return f"{fatal}{error.code}: {meaning} ({error.rendered}){note}"
    if isinstance(error, ConnectionLostError):
        return error.reason if error.reason.startswith("cannot connect") else str(error)
    return str(error)


def _failure_kind(error: BaseException) -> str:
    kinds: tuple[tuple[type[BaseException], str], ...] = (
        (FatalError, "fatal-error"),
        (NonFatalError, "non-fatal-error"),
        (AsynchronousWarning, "warning"),
        (AsynchronousError, "asynchronous-error"),
        (RequestTimeout, "timeout"),
        (ConnectionLostError, "connection-lost"),
        (ResponseDataError, "bad-reply"),
        (ReplyTooLargeError, "reply-too-large"),
    )
    for kind, name in kinds:
        if isinstance(error, kind):
            return name
    return type(error).__name__


def failure_record(
    error: BaseException, exit_status: int, *, kind: str | None = None
) -> dict[str, JSONValue]:
    """A failure as ``--json`` writes it, on stdout like the results: the error string's parts (where,
    severity, code, message with the numbers put in, args as sent) for a server error; for a failure of
    the client's own (``kind``, else ``timeout``, ``connection-lost``...) the same keys, null where the
    server said nothing, and always the exit status."""
    if isinstance(error, ServerError):
        return {
            "error": kind or _failure_kind(error),
            "where": error.where,
            "severity": error.severity,
            "code": error.code,
            "message": error.message,
            "args": list(error.arguments),
            "meaning": error.meaning,
            "request_number": error.request_number,
            "exit": exit_status,
        }
    return {
        "error": kind or _failure_kind(error),
        "where": None,
        "severity": None,
        "code": None,
        "message": error_line(error),
        "args": [],
        "exit": exit_status,
    }
