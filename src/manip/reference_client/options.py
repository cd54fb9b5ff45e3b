"""How a client connection behaves: timeouts, handler types, trivial errors, registry."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from manip.links.api import LinkWrapper
from manip.reference_client.definitions import DEFAULT_REGISTRY, PUMA
from manip.reference_client.errors import NonFatalError
from manip.reference_client.faults import NO_FAULTS, ClientFaults
from manip.reference_client.handlers import DEFAULT_HANDLER_TYPES, NOTIFY_TRIVIAL_ERRORS
from manip.reference_client.matching import DEFAULT_HISTORY
from manip.reference_client.policy import TrivialErrors
from manip.reference_client.registry import Registry

DEFAULT_MAX_REPLY_BYTES: Final = 1 << 20
"""The most data one reply may bring (1 MiB; erratum ``reply-size-limit``): a describe-self text is a
few hundred bytes, and 1 MiB is over 2,000 packets of it."""


@dataclass(frozen=True)
class ClientOptions:
    """Options of :func:`~manip.reference_client.connect.aconnect` and ``connect``."""

    timeout: float | None = 30.0
    """Default seconds from queueing a request to its reply (None: no limit).  Motion requests are
    answered when the segment is queued, not when the motion ends, so this is not a motion time."""
    connect_timeout: float | None = 30.0
    """Seconds to wait for the initial RESPONSE after the connection opens."""
    expect_initial_response: bool = True
    """Wait for the server's initial RESPONSE before sending (clause connect.initial-response)."""
    notify_trivial_errors: bool = False
    """Notify trivial non-fatal errors of "done" requests instead of raising them."""
    trivial_errors: Callable[[NonFatalError], bool] = field(default_factory=TrivialErrors)
    """Which non-fatal errors are trivial."""
    handler_types: tuple[str, ...] = DEFAULT_HANDLER_TYPES
    """The response-handler types, in lookup order (notify-trivial-errors is put in front when
    ``notify_trivial_errors`` is on)."""
    manipulator_type: str | None = PUMA
    """Selects request codes by opcode when several manipulator types define the same one."""
    registry: Registry = DEFAULT_REGISTRY
    history: int = DEFAULT_HISTORY
    """How many finished request numbers are remembered to tell duplicates and late replies apart."""
    align_args: bool = True
    """Error-string numbers start at an even offset (erratum error-arg-layout)."""
    name: str = "manipulator"
    """Used in log messages."""
    contact: str | None = None
    """The Chaos contact name to connect to when connecting by URL (None: the URL's, default PUMA)."""
    max_reply_bytes: int | None = DEFAULT_MAX_REPLY_BYTES
    """The most data bytes one reply (all the packets of a multi-packet reply) may bring.  A reply that
    goes past it fails with :class:`~manip.reference_client.errors.ReplyTooLargeError` and the client
    gives up the connection (the server would go on sending); None: no limit.  The bound holds with
    ``timeout=None`` too, so an endless describe-self always ends."""
    close_timeout: float = 2.0
    """Seconds a graceful close of a Chaos connection waits for the server before aborting."""
    wrap_link: LinkWrapper | None = None
    """Put between the Chaos node and its link when connecting by URL (:func:`manip.links.open_connection`):
    ``RecorderTap(recorder, "client").wrap`` (:mod:`manip.captures`) records the session.  A transport
    given ready-made takes its own (``NcpTransport(..., wrap_link=)``)."""
    faults: ClientFaults = NO_FAULTS
    """Fault switches that make the client break one rule on purpose (:mod:`.faults`; none: a
    conforming client).  A transport given ready-made takes its own (``NcpTransport(..., faults=)``)."""

    def effective_handler_types(self, notify_trivial_errors: bool | None = None) -> tuple[str, ...]:
        notify = self.notify_trivial_errors if notify_trivial_errors is None else notify_trivial_errors
        types = tuple(t for t in self.handler_types if t != NOTIFY_TRIVIAL_ERRORS)
        return (NOTIFY_TRIVIAL_ERRORS, *types) if notify else types
