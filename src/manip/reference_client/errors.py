"""Everything the client raises or reports is a :class:`ManipError`.

Server errors (E.2) keep the parts of the error string a program can act on (``where``, ``severity``,
``code``, the raw ``arguments``) next to the rendered text::

    try:
        await arm.move(target)
    except NonFatalError as err:
        if err.code == "NAP":          # no arm power
            await arm.enable_power()

* :class:`FatalError`: 0201, the server gave up; every pending request fails with it;
* :class:`NonFatalError`: 0202, the reply to one request, which failed;
* :class:`AsynchronousError`: 0204, something went wrong outside any request (motion aborted, ...);
* :class:`AsynchronousWarning`: 0205, worth telling a human, not an error;
* :class:`OutOfSequenceResponse`: a packet that answers nothing we wait for (reported, never raised);
* :class:`ConnectionLostError`: the connection closed or was closed; pending requests fail with it;
* :class:`RequestTimeout`: no reply within the request's timeout (also a :class:`TimeoutError`);
* :class:`ResponseDataError`: a reply whose data do not fit the request;
* :class:`JointFreedError`: a request while a joint is free (the server would discard it);
* :class:`GuardTrippedError`: a stop-the-move guard tripped while waiting for a segment.
"""

from __future__ import annotations

import enum
from typing import TYPE_CHECKING, Any

from manip.codecs.error_string import ErrorMessage
from manip.reference_client.faults import NO_FAULTS, ClientFaults
from manip.spec import SPEC

if TYPE_CHECKING:
    from manip.codecs.messages import AsyncResponse
    from manip.reference_client.packets import ServerPacket
    from manip.reference_client.request import Request


UNSERVED_CODES = frozenset({"UOP", "UIM"})
"""The codes of a refusal for an opcode the server does not serve (unknown, or not on this robot)."""


class ManipError(Exception):
    """Base class of the client's errors."""


class ServerError(ManipError):
    """An error string sent by the server (fatal, non-fatal, asynchronous error or warning)."""

    def __init__(
        self,
        error: ErrorMessage,
        *,
        request_number: int,
        request: Request[Any] | None = None,
        faults: ClientFaults = NO_FAULTS,
    ) -> None:
        self.error = error
        self.request_number = request_number
        self.request = request
        self.faults = faults
        """The fault switches of the client that read it (they may bend :attr:`message`)."""
        super().__init__(self._text())

    @property
    def where(self) -> str:
        return self.error.where

    @property
    def severity(self) -> str:
        return self.error.severity

    @property
    def code(self) -> str:
        return self.error.code

    @property
    def arguments(self) -> tuple[int, ...]:
        """The 16-bit numbers that followed the NUL, unrendered."""
        return self.error.args

    @property
    def template(self) -> str:
        """The message with ``~`` and ``$`` still in it."""
        return self.error.message

    @property
    def message(self) -> str:
        """The message with the numbers substituted."""
        faulty = self.faults.render_message(self.error.message, self.error.args, self.error.has_nul)
        return self.error.render_message() if faulty is None else faulty

    @property
    def rendered(self) -> str:
        """The whole line: ``where: severity code message``."""
        head = f"{self.where}: {self.severity} {self.code}"
        return f"{head} {self.message}" if self.message else head

    @property
    def meaning(self) -> str | None:
        """What the spec says the code means (``NAP`` -> ``No arm power``), if it knows the code."""
        entry = SPEC.error_codes.get(self.code)
        return entry.meaning if entry else None

    @property
    def is_bug(self) -> bool:
        """Severity BF or BE: the server's software is at fault."""
        return self.severity in ("BF", "BE")

    @property
    def is_command_error(self) -> bool:
        """Severity C: the request's format or data were wrong."""
        return self.severity == "C"

    @property
    def unserved_extension(self) -> str | None:
        """When the server refused a request as unserved (UOP, UIM) and its opcode is one of manip's
        Puma extensions, which the 1985 guide does not define: that opcode, named (``0257, request
        notifications, a Puma extension``); else None."""
        if self.code not in UNSERVED_CODES:
            return None
        opcode = self.request.opcode if self.request is not None else None
        if opcode is None and self.code == "UOP" and self.arguments:
            opcode = self.arguments[0]
        op = SPEC.requests.get(opcode) if opcode is not None else None
        if op is None or not op.extension:
            return None
        return f"{op.opcode:04o}, {op.name.replace('-', ' ')}, a Puma extension"

    def _text(self) -> str:
        about = f"{self.request.describe()}: " if self.request is not None else ""
        extension = self.unserved_extension
        note = f" [{extension} the 1985 guide does not define]" if extension else ""
        return f"{about}{self.error.render()}{note}"


class FatalError(ServerError):
    """0201: the server cannot go on; it closes the connection.  ``request_number`` is the number of
    the packet it received last; ``request`` is the failed request this copy was given to, if any."""


class NonFatalError(ServerError):
    """0202: the reply to ``request``, which could not be performed; the connection stays usable."""


class AsynchronousError(ServerError):
    """0204: an error outside any request; ``request_number`` is the last request the server processed."""


class AsynchronousWarning(ServerError):  # noqa: N818 - the 1985 guide's name for opcode 0205
    """0205: a condition a human should hear about; it does not stop anything."""


class OutOfSequenceReason(enum.Enum):
    UNMATCHED = "unmatched"
    """No request with this number is pending, and none was answered recently."""
    DUPLICATE = "duplicate"
    """The request with this number was already answered."""
    LATE = "late"
    """The request with this number was given up (timed out or cancelled) before the reply came."""
    UNEXPECTED = "unexpected"
    """The request with this number was sent with response type none."""
    UNKNOWN_OPCODE = "unknown-opcode"
    """No handler of the manipulator's handler types takes this response code."""
    MALFORMED = "malformed"
    """The packet could not be read at all (no request number, bad asynchronous layout)."""
    HANDLER_FAILED = "handler-failed"
    """A response handler raised (the exception is the ``__cause__``); the connection goes on."""


class OutOfSequenceResponse(ManipError):  # noqa: N818 - the 1985 guide's name (signal-error-for-out-of-sequence-request)
    """A packet from the server that answers nothing the client waits for.

    Reported to the error listeners and the log, never raised into a request (the 1985 guide's
    ``signal-error-for-out-of-sequence-request``).
    """

    def __init__(
        self,
        reason: OutOfSequenceReason,
        packet: ServerPacket,
        *,
        request_number: int | None = None,
        detail: str = "",
    ) -> None:
        self.reason = reason
        self.packet = packet
        self.request_number = request_number
        self.detail = detail
        number = "" if request_number is None else f" number {request_number}"
        extra = f": {detail}" if detail else ""
        super().__init__(
            f"out-of-sequence response ({reason.value}): opcode 0{packet.opcode:o}{number}{extra}"
        )


class ConnectionLostError(ManipError):
    """The connection is gone (closed by either end, broken, or failed before it opened)."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(f"connection lost: {reason}")


class RequestTimeout(ManipError, TimeoutError):  # noqa: N818 - also a TimeoutError
    """No reply within ``timeout`` seconds.  A reply that comes later is reported as out of sequence.

    ``wait_for_segment`` raises it too, with ``request`` None and ``what`` naming the segment.
    """

    def __init__(self, request: Request[Any] | None, timeout: float, what: str | None = None) -> None:
        self.request = request
        self.timeout = timeout
        if what is None:
            what = f"{request.describe()}: no reply" if request is not None else "no reply"
        super().__init__(f"{what} within {timeout:g} s")


class ResponseDataError(ManipError):
    """A reply whose data could not be read as the request's result (the cause is chained)."""

    def __init__(self, request: Request[Any], detail: str) -> None:
        self.request = request
        self.detail = detail
        super().__init__(f"{request.describe()}: bad reply data: {detail}")


class ReplyTooLargeError(ManipError):
    """A reply brought more data than ``ClientOptions.max_reply_bytes``; the client gave up the connection."""

    def __init__(self, request: Request[Any], limit: int) -> None:
        self.request = request
        self.limit = limit
        super().__init__(
            f"{request.describe()}: the reply goes past {limit} data bytes (ClientOptions.max_reply_bytes, "
            "--max-reply); the connection was given up"
        )


class JointFreedError(ManipError):
    """A joint is free: the server discards the next packet, so only ``release_joint`` may be sent."""

    def __init__(self, joint: int) -> None:
        self.joint = joint
        super().__init__(f"joint {joint} is free; call release_joint() before any other request")


class GuardTrippedError(ManipError):
    """A guard that stops the move tripped while a segment was awaited."""

    def __init__(self, response: AsyncResponse) -> None:
        self.response = response
        self.guard = response.word3
        super().__init__(f"guard {response.word3} tripped and stopped the move")
