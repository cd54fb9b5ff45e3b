"""The built-in response handlers and the handler types they belong to.

=========================  ======  ===================================================================
handler type               code    handler
=========================  ======  ===================================================================
``generic``                0       :func:`handle_normal_response` (the 1985 guide's four generic codes ...)
``generic``                1       :func:`handle_fatal_error`
``generic``                2       :func:`handle_non_fatal_error`
``generic``                4       :func:`handle_asynchronous_error`
``chaos-manipulator``      3       :func:`handle_asynchronous_response` (... and the two more codes of
``chaos-manipulator``      5       :func:`handle_asynchronous_warning`   Appendix E.3)
``notify-trivial-errors``  2       :func:`notify_trivial_error` (passes anything not trivial on)
=========================  ======  ===================================================================

A manipulator's handler-type list is ``("chaos-manipulator", "generic")``, with
``"notify-trivial-errors"`` in front when trivial errors are notified.
"""

from __future__ import annotations

import struct
from typing import Any, Final

from manip.codecs.messages import AsyncResponse
from manip.reference_client.errors import (
    AsynchronousError,
    AsynchronousWarning,
    FatalError,
    NonFatalError,
    OutOfSequenceReason,
    ReplyTooLargeError,
)
from manip.reference_client.events import (
    AsyncErrorReceived,
    AsyncResponseReceived,
    FatalErrorReceived,
    TrivialErrorNotified,
    WarningReceived,
)
from manip.reference_client.faults import ClientFault
from manip.reference_client.matching import ResponseContext
from manip.reference_client.request import Request, ResponseType

GENERIC: Final = "generic"
CHAOS_MANIPULATOR: Final = "chaos-manipulator"
NOTIFY_TRIVIAL_ERRORS: Final = "notify-trivial-errors"

DEFAULT_HANDLER_TYPES: Final = (CHAOS_MANIPULATOR, GENERIC)

_ASYNC_BODY = struct.Struct("<3H")
_GUIDE_ASYNC_BODY = struct.Struct("<2H")
"""What follows the first word of the 1985 guide's asynchronous response (the condition code)."""


def handle_normal_response(ctx: ResponseContext) -> None:
    """Code 0: the reply (or one packet of the reply) to the request with the packet's number."""
    request = ctx.find_matching_request()
    if request is None:
        ctx.out_of_sequence()
        return
    payload = ctx.payload
    if request.response_type is ResponseType.MULTI and ClientFault.MULTI_FIRST_PACKET not in ctx.core.faults:
        if payload:
            request.responses.append(payload)
            request.reply_bytes += len(payload)
            _hold_to_limit(ctx, request)
            return
    else:
        request.responses.append(payload)
    ctx.extract(request)


def _hold_to_limit(ctx: ResponseContext, request: Request[Any]) -> None:
    """A reply past the size limit fails its request, and the connection is given up: the server would
    go on sending (an endless describe-self), and each packet would be out of sequence."""
    limit = ctx.core.max_reply_bytes
    if limit is None or request.reply_bytes <= limit:
        return
    request.responses.clear()
    error = ReplyTooLargeError(request, limit)
    ctx.fail(request, error)
    for event in ctx.core.connection_lost(f"given up: a reply went past {limit} data bytes"):
        ctx.emit(event)


def handle_non_fatal_error(ctx: ResponseContext) -> None:
    """Code 2: the request with the packet's number failed."""
    request = ctx.find_matching_request()
    if request is None:
        ctx.out_of_sequence(detail=f"non-fatal error {ctx.error_message().render()!r}")
        return
    error = NonFatalError(
        ctx.error_message(), request_number=ctx.request_number, request=request, faults=ctx.core.faults
    )
    ctx.fail(request, error)


def handle_fatal_error(ctx: ResponseContext) -> None:
    """Code 1: every pending request fails at once; the number is the last packet the server got."""
    faults = ctx.core.faults
    if ClientFault.FATAL_AS_NON_FATAL in faults:
        handle_non_fatal_error(ctx)
        return
    message = ctx.error_message()
    number = ctx.request_number
    first = FatalError(message, request_number=number, request=ctx.find_matching_request(), faults=faults)
    ctx.emit(FatalErrorReceived(first))
    ctx.fail_all(lambda request: FatalError(message, request_number=number, request=request, faults=faults))


def handle_asynchronous_error(ctx: ResponseContext) -> None:
    """Code 4: an error outside any request."""
    error = AsynchronousError(ctx.error_message(), request_number=ctx.request_number, faults=ctx.core.faults)
    ctx.emit(AsyncErrorReceived(error))


def handle_asynchronous_warning(ctx: ResponseContext) -> None:
    """Code 5: a warning for the human."""
    warning = AsynchronousWarning(
        ctx.error_message(), request_number=ctx.request_number, faults=ctx.core.faults
    )
    ctx.emit(WarningReceived(warning))


def handle_asynchronous_response(ctx: ResponseContext) -> None:
    """Code 3: condition code and two words, after the request number (manip's layout, 8 bytes) or with
    none (the 1985 guide's, 6 bytes: what was read as the request number is the condition); erratum
    async-request-number.  The two are told apart by length."""
    payload = ctx.payload
    if len(payload) not in (_ASYNC_BODY.size, _GUIDE_ASYNC_BODY.size):
        ctx.out_of_sequence(
            OutOfSequenceReason.MALFORMED,
            f"asynchronous response needs {_ASYNC_BODY.size} bytes after the request number "
            f"(or {_GUIDE_ASYNC_BODY.size} in the 1985 guide's layout, which has none), got {len(payload)}",
        )
        return
    if ClientFault.IGNORE_ASYNC in ctx.core.faults:
        return
    if ClientFault.ASYNC_AS_REPLY in ctx.core.faults and ctx.core.pending:
        request = next(iter(ctx.core.pending.values()))
        request.responses.append(payload)
        ctx.extract(request)
        return
    response: AsyncResponse
    if len(payload) == _GUIDE_ASYNC_BODY.size:
        word2, word3 = _GUIDE_ASYNC_BODY.unpack(payload)
        response = AsyncResponse(None, ctx.request_number, word2, word3)
    else:
        condition, word2, word3 = _ASYNC_BODY.unpack(payload)
        response = AsyncResponse(ctx.request_number, condition, word2, word3)
    ctx.emit(AsyncResponseReceived(response))


def notify_trivial_error(ctx: ResponseContext) -> None:
    """Code 2, ahead of ``generic``: answer a trivial error's request with None and only notify it."""
    request = ctx.find_matching_request()
    policy = ctx.core.trivial_errors
    if request is None or policy is None or not request.value_optional:
        ctx.pass_on()
        return
    error = NonFatalError(
        ctx.error_message(), request_number=ctx.request_number, request=request, faults=ctx.core.faults
    )
    if not policy(error):
        ctx.pass_on()
        return
    ctx.answer(request, None)
    ctx.emit(TrivialErrorNotified(error))
