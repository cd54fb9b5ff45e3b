"""Which request a server packet answers: the one pairing rule of every offline reader (erratum
``capture-pairing``).

The capture view (``manip-capture info``), the transcript checks (``manip-conform verify`` and the live
cases) and replay's answer sorter all feed one connection's packets, in the order seen, to a
:class:`ReplyPairing` and read its :class:`Placement` of each server packet, so they cannot disagree.

The rule, from the 1985 guide (Part I §3, Appendix E): the server's main process takes one request at a
time and sends its reply before it reads the next, so answers come in request order.

* **By position.**  An answer (RESPONSE 0200, fatal error 0201, non-fatal error 0202) belongs to the
  oldest request not yet fully answered; with :meth:`ReplyPairing.rfc` the RFC is the oldest, answered
  by the initial RESPONSE.  The request-number word is *not* used to pair: a wrong echo is the checker's
  violation (``response.echoes-request-number``), never a re-pairing, so one bad word cannot shift every
  later answer.
* **Multi-packet replies.**  The RESPONSE to a well-formed request whose reply is ``multi`` (describe
  self) leaves the request open until a RESPONSE with no text (the terminator).  An error arriving
  while such a reply is open ends it and answers the same request (:attr:`Placement.cut_short`): the
  server was still working on that request, and the reply stays unterminated for the checker.
* **Free joint.**  A request that arrives after free joint was answered with a RESPONSE is discarded by
  the server, which answers it with one packet whatever it was.
* **Not answers.**  Asynchronous packets (0203-0205) answer nothing; an answer with nothing outstanding,
  or any answer after a fatal error, is an *extra*; other opcodes are *other*.

Nothing here does I/O; a request is fed with any tag the caller wants back (an index, a packet, a
record of its own).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Final, Generic, Literal, TypeVar

from manip.codecs.errors import DecodeError
from manip.codecs.messages import decode_request
from manip.spec import SPEC
from manip.spec.constants import ANSWER_OPS, ASYNC_OPS, ServerOp

__all__ = ["ANSWER_OPCODES", "UNSOLICITED_OPCODES", "Placement", "ReplyPairing", "Role", "opens_multi"]

T = TypeVar("T")

Role = Literal["answer", "async", "extra", "other"]
"""What a server packet is to the exchange: an answer to a request, an asynchronous packet, an answer
to nothing (an extra), or an opcode that is neither (arm-specific or unknown)."""

ANSWER_OPCODES: Final = ANSWER_OPS
UNSOLICITED_OPCODES: Final = ASYNC_OPS
_RESPONSE: Final = int(ServerOp.RESPONSE)
_FATAL: Final = int(ServerOp.FATAL_ERROR)
_MULTI_OPCODES: Final = frozenset(op.opcode for op in SPEC.requests.values() if op.response.form == "multi")
_FREE_JOINT: Final = SPEC.request("free-joint").opcode


def _well_formed(opcode: int, data: bytes) -> bool:
    try:
        decode_request(opcode, data)
    except DecodeError:
        return False
    return True


def opens_multi(opcode: int, data: bytes) -> bool:
    """Whether a RESPONSE to this request starts a multi-packet reply (a malformed one is refused with a
    single error, so only a well-formed request of a ``multi`` opcode does)."""
    return opcode in _MULTI_OPCODES and _well_formed(opcode, data)


@dataclass(frozen=True, slots=True)
class Placement(Generic[T]):
    """Where one server packet goes."""

    role: Role
    request: T | None = None
    """The tag of the request it answers (role ``answer`` only)."""
    final: bool = False
    """It ends its request's answer (role ``answer`` only)."""
    cut_short: bool = False
    """An error that ended a multi-packet reply before its terminator."""


@dataclass(slots=True)
class _Entry(Generic[T]):
    tag: T
    multi: bool = False
    free_joint: bool = False
    started: bool = False


_ASYNC: Final[Placement[object]] = Placement("async")
_EXTRA: Final[Placement[object]] = Placement("extra")
_OTHER: Final[Placement[object]] = Placement("other")


class ReplyPairing(Generic[T]):
    """One connection's pairing state (see the module docstring).  Feed :meth:`request` (and
    :meth:`rfc`) and :meth:`server` in the order the packets were seen; :meth:`close` at the end."""

    __slots__ = ("_fatal", "_free_wait", "_max_pending", "_pending", "completed", "forgotten")

    def __init__(self, max_pending: int | None = None) -> None:
        self._pending: deque[_Entry[T]] = deque()
        self._max_pending = max_pending
        self._free_wait = False
        self._fatal = False
        self.completed = 0
        """How many requests (the RFC included) are fully answered."""
        self.forgotten = 0
        """How many unanswered requests were let go to keep at most ``max_pending`` outstanding (a
        reader of an endless stream keeps a bound; a server answers long before that many wait)."""

    def _append(self, entry: _Entry[T]) -> None:
        self._pending.append(entry)
        if self._max_pending is not None and len(self._pending) > self._max_pending:
            self._pending.popleft()
            self.forgotten += 1

    def rfc(self, tag: T) -> None:
        """The RFC was seen: the next answer (the initial RESPONSE) is its."""
        self._append(_Entry(tag))

    def request(self, tag: T, opcode: int, data: bytes) -> bool:
        """A request was seen.  Returns True when the server discards it (sent after free joint was
        granted): it is then answered by one packet, an empty done, without being executed."""
        if self._free_wait:
            self._free_wait = False
            self._append(_Entry(tag))
            return True
        free = opcode == _FREE_JOINT and _well_formed(opcode, data)
        self._append(_Entry(tag, opens_multi(opcode, data), free))
        return False

    def server(self, opcode: int, data: bytes) -> Placement[T]:
        """Place one server packet (a close is :meth:`close`, not this)."""
        if opcode not in ANSWER_OPCODES:
            return _ASYNC if opcode in UNSOLICITED_OPCODES else _OTHER  # type: ignore[return-value]
        pending = self._pending
        if not pending or self._fatal:
            return _EXTRA  # type: ignore[return-value]
        entry = pending[0]
        if opcode == _RESPONSE:
            if entry.multi and len(data) > 2:
                entry.started = True
                return Placement("answer", entry.tag, False)
            cut_short = False
        else:
            cut_short = entry.started
            self._fatal = opcode == _FATAL
        pending.popleft()
        self.completed += 1
        if entry.free_joint:
            self._free_wait = opcode == _RESPONSE
        return Placement("answer", entry.tag, True, cut_short)

    def close(self) -> T | None:
        """The connection ended: returns the tag of the request whose multi-packet reply it cut off (no
        longer outstanding), if any."""
        if self._pending and self._pending[0].started:
            return self._pending.popleft().tag
        return None

    @property
    def in_progress(self) -> T | None:
        """The request whose multi-packet reply has started but not ended."""
        return self._pending[0].tag if self._pending and self._pending[0].started else None

    @property
    def head(self) -> T | None:
        """The request the next answer would go to (None: it would be an extra)."""
        return None if self._fatal or not self._pending else self._pending[0].tag

    def outstanding(self) -> list[T]:
        """The requests not yet fully answered, oldest first."""
        return [e.tag for e in self._pending]
