"""What the diff judges besides the fuzzer's judges: the numbers of an error string (clause
``error-string.arg-values``, erratum ``error-arg-values``), which the transcript checks do not know.

For an input that sends one request, a C UOP must carry the opcode received, a C BDL the data byte
count expected and the count received (in either order, as the suite's negative cases accept).  Each
breach is a :class:`~manip.conformance.fuzz.judge.Sighting` like the fuzzer's own.  Sans-I/O.
"""

from __future__ import annotations

from collections.abc import Sequence

from manip.codecs.error_string import parse_error
from manip.codecs.errors import CodecError
from manip.conformance.diff.pairing import SideEvent
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import FuzzInput, RequestStep
from manip.conformance.judge.violation import Violation
from manip.spec import SPEC
from manip.spec.constants import ServerOp

__all__ = ["arg_value_sightings", "wanted_numbers"]

CLAUSE = "error-string.arg-values"


def wanted_numbers(code: str, opcode: int, data: bytes) -> set[tuple[int, ...]] | None:
    """The numbers a ``code`` error to this request must carry (None: not judged here)."""
    if code == "UOP":
        return {(opcode,)}
    op = SPEC.requests.get(opcode)
    if code != "BDL" or op is None or op.request.fixed_size is None:
        return None
    size = op.request.fixed_size
    small = any(f.type.element == "small" for f in op.request.fields)
    sizes = {size} | ({size - 1} if small else set())
    received = len(data)
    return {pair for s in sizes for pair in ((s, received), (received, s))}


def arg_value_sightings(item: FuzzInput, events: Sequence[SideEvent]) -> list[Sighting]:
    """The breach of ``error-string.arg-values`` in the answer to a one-request input, if any."""
    requests = [s for s in item.steps if isinstance(s, RequestStep)]
    if len(requests) != 1:
        return []
    answer = next(
        (e for e in events if e.kind == "packet" and e.opcode != ServerOp.ASYNCHRONOUS_RESPONSE), None
    )
    if answer is None or answer.opcode != ServerOp.NON_FATAL_ERROR:
        return []
    try:
        error = parse_error(answer.data, body="packet")
    except (CodecError, ValueError):
        return []
    request = requests[0]
    wanted = wanted_numbers(error.code, request.opcode, request.data)
    if wanted is None or not error.args or error.args in wanted:
        return []
    shown = " or ".join(str(list(w)) for w in sorted(wanted))
    message = f"C {error.code} carries the numbers {list(error.args)}, not what the request provoked"
    violation = Violation(message, CLAUSE, None, f"the numbers {shown}", str(list(error.args)), answer.data)
    return [Sighting(violation, item.number)]
