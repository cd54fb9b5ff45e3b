"""What the matching core reports.  The background process turns each event into an action.

=======================  ===========================================================================
event                    the background process ...
=======================  ===========================================================================
InitialResponse          lets requests go out (the connection is ready)
RequestAnswered          completes the request's future with ``value``
RequestFailed            fails the request's future with ``error``
AsyncResponseReceived    calls the asynchronous-response listeners and feeds the async iterators
AsyncErrorReceived       logs it and calls the error listeners
WarningReceived          logs it and calls the error listeners
TrivialErrorNotified     logs it and calls the error listeners (the request itself succeeded)
FatalErrorReceived       logs it, calls the error listeners, then ends the connection
OutOfSequence            logs it and calls the error listeners
ConnectionEnded         ends the connection
PacketKept               does not return the packet to the transport (a handler kept it)
=======================  ===========================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from manip.codecs.messages import AsyncResponse
from manip.reference_client.errors import (
    AsynchronousError,
    AsynchronousWarning,
    FatalError,
    ManipError,
    NonFatalError,
    OutOfSequenceResponse,
)
from manip.reference_client.packets import ServerPacket
from manip.reference_client.request import Request


@dataclass(frozen=True, slots=True)
class InitialResponse:
    """The RESPONSE the server sends when the connection opens; its number is not matched."""

    request_number: int


@dataclass(frozen=True, slots=True)
class RequestAnswered:
    request: Request[Any]
    value: Any


@dataclass(frozen=True, slots=True)
class RequestFailed:
    request: Request[Any]
    error: ManipError


@dataclass(frozen=True, slots=True)
class AsyncResponseReceived:
    response: AsyncResponse


@dataclass(frozen=True, slots=True)
class AsyncErrorReceived:
    error: AsynchronousError


@dataclass(frozen=True, slots=True)
class WarningReceived:
    warning: AsynchronousWarning


@dataclass(frozen=True, slots=True)
class TrivialErrorNotified:
    """A non-fatal error judged trivial: its request was answered with ``None`` instead of failing."""

    error: NonFatalError


@dataclass(frozen=True, slots=True)
class FatalErrorReceived:
    error: FatalError


@dataclass(frozen=True, slots=True)
class OutOfSequence:
    error: OutOfSequenceResponse


@dataclass(frozen=True, slots=True)
class ConnectionEnded:
    """The connection ended (closed, or lost: then ``cause`` is the transport's error)."""

    reason: str
    cause: BaseException | None = None
    """The transport's error that ended the connection, if it has one (chained to ConnectionLostError)."""


@dataclass(frozen=True, slots=True)
class PacketKept:
    packet: ServerPacket


Event = (
    InitialResponse
    | RequestAnswered
    | RequestFailed
    | AsyncResponseReceived
    | AsyncErrorReceived
    | WarningReceived
    | TrivialErrorNotified
    | FatalErrorReceived
    | OutOfSequence
    | ConnectionEnded
    | PacketKept
)
