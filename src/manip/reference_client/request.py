"""The request object: what the user wants sent, how its reply is read, and where it stands.

This is the 1985 guide's request defstruct (Part I §2: ``REQUEST-CODE``,
``REQUEST-RESPONSE-TYPE``, ``REQUEST-RESPONSE-DATA-EXTRACTOR``, ``REQUEST-DATA``,
``REQUEST-PACKET-NUMBER``) as a Python object.  The data bytes are built when the request is made,
not when it is sent, so a bad argument is reported in the caller's task (the 1985 guide's advice for a
``:before :queue-request`` daemon).

Data extractor contract
    ``extractor(request, payloads) -> value``.  ``payloads`` are the response data after the request
    number: exactly one item for a single-packet response, the non-empty packets in order (terminator
    left out) for a multi-packet one.  Whatever the extractor returns is the request's result; whatever
    it raises fails the request with :class:`~manip.reference_client.errors.ResponseDataError`.  An
    extractor of ``None`` means "the data do not matter": the result is ``None`` (the 1985 guide's ``NIL``).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Generic, TypeVar

from manip.spec import RequestOpcode
from manip.spec.notation import octal

if TYPE_CHECKING:
    from manip.reference_client.errors import ManipError

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)


class ResponseType(enum.Enum):
    """How many packets answer a request."""

    NONE = "none"
    """No reply is expected: the request counts as answered once it is sent.  (Every request of the
    Chaos manipulator protocol is answered, so its requests never use this; it exists for protocols
    that have unanswered requests.)"""
    SINGLE = "single"
    """One packet."""
    MULTI = "multi"
    """Several packets with the same request number, ended by an empty one."""


class RequestState(enum.Enum):
    QUEUED = "queued"
    """Made and waiting in the user request queue."""
    SENT = "sent"
    """Handed to the transport; its packet number is known; waiting for the reply."""
    ANSWERED = "answered"
    """The reply arrived and the extractor produced the result."""
    FAILED = "failed"
    """An error reply, a bad reply, a timeout, a fatal error or a lost connection ended it."""


DataExtractor = Callable[["Request[Any]", Sequence[bytes]], T_co]
"""Reads a request's result out of its response payloads (see the module docstring)."""


def normalise_name(name: str) -> str:
    """Registry names are case-insensitive and ``_`` is the same as ``-``: ``SET_SPEED`` = ``set-speed``."""
    return name.strip().lower().replace("_", "-")


@dataclass(frozen=True, slots=True)
class RequestCode:
    """A named request opcode (``define_request_code``)."""

    name: str
    opcode: int
    manipulator_type: str | None = None
    """``None`` for a generic code; otherwise the kind of manipulator that implements it (``"puma"``)."""
    default_extractor: str | DataExtractor[Any] | None = None
    """A registered extractor name or a function; ``None`` lets the response type decide."""
    response_type: ResponseType = ResponseType.SINGLE
    spec: RequestOpcode | None = None
    """The spec's entry when the code is one of the spec's opcodes (it gives the request layout)."""

    def __str__(self) -> str:
        return f"{self.name} ({octal(self.opcode)})"


@dataclass(eq=False)
class Request(Generic[T]):
    """One request.  Identity matters (two requests with equal fields are still two requests)."""

    code: RequestCode
    data: bytes = b""
    response_type: ResponseType = ResponseType.SINGLE
    extractor: DataExtractor[T] | None = None
    timeout: float | None = None
    """Seconds from queueing to the reply; ``None`` waits for ever (until the connection ends)."""
    value_optional: bool = False
    """The result is ``None`` anyway (a "done" reply): only such requests may have a trivial error
    notified instead of raised (see :class:`~manip.reference_client.policy.TrivialErrors`)."""
    packet_number: int | None = None
    """Set by the transport's ``send_user_request``: the number the reply will carry."""
    state: RequestState = RequestState.QUEUED
    result: T | None = None
    error: ManipError | None = None
    responses: list[bytes] = field(default_factory=list)
    """Response payloads received so far (one for single responses, the chunks of a multi response)."""
    reply_bytes: int = 0
    """Data bytes of the response payloads so far (held to ``ClientOptions.max_reply_bytes``)."""

    @property
    def opcode(self) -> int:
        return self.code.opcode

    @property
    def name(self) -> str:
        return self.code.name

    @property
    def done(self) -> bool:
        return self.state in (RequestState.ANSWERED, RequestState.FAILED)

    def describe(self) -> str:
        """``here (0201, packet 5)``: how errors and logs name this request."""
        number = "not sent" if self.packet_number is None else f"packet {self.packet_number}"
        return f"{self.code.name} ({octal(self.opcode)}, {number})"

    def __repr__(self) -> str:
        return f"<Request {self.describe()} {self.state.value}>"
