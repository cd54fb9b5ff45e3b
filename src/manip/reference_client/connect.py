"""Opening a connection: ``await aconnect(...)`` or ``async with aconnect(...) as arm``.

The source of a connection is one of

* a link address, as a URL string or a :class:`manip.links.LinkAddress`: ``tcp://HOST:PORT``,
  ``chudp://HOST:PORT?addr=OCTAL``, ``chaosd:///PATH`` (see :mod:`manip.links.address`), connected with
  :class:`~manip.reference_client.ncp_transport.NcpTransport`; ``contact=`` (or
  ``ClientOptions.contact``) overrides the URL's contact name;
* a transport (:class:`~manip.reference_client.transport.ManipTransport`), or a factory that makes one
  when called inside the event loop that will run it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Generator
from types import TracebackType
from typing import Any, cast

from manip.links import LinkAddress
from manip.reference_client.background import BackgroundProcess
from manip.reference_client.manipulator import Manipulator
from manip.reference_client.matching import MatchingCore
from manip.reference_client.ncp_transport import NcpTransport
from manip.reference_client.options import ClientOptions
from manip.reference_client.transport import ManipTransport

TransportFactory = Callable[[], ManipTransport]
"""Makes a not-yet-connected transport; called inside the event loop that will run it."""

TransportSource = str | LinkAddress | ManipTransport | TransportFactory


def _transport(source: TransportSource, options: ClientOptions) -> ManipTransport:
    if isinstance(source, str | LinkAddress):
        return NcpTransport(
            source,
            contact=options.contact,
            connect_timeout=options.connect_timeout,
            close_timeout=options.close_timeout,
            wrap_link=options.wrap_link,
            faults=options.faults,
        )
    if options.wrap_link is not None:
        raise ValueError(
            "ClientOptions.wrap_link applies when connecting by URL; give a transport its own "
            "(NcpTransport(..., wrap_link=...))"
        )
    if not isinstance(source, type) and isinstance(source, ManipTransport):
        return source
    factory = cast(TransportFactory, source)  # a class is a factory even though it has the methods
    transport = factory()
    if not isinstance(transport, ManipTransport):
        raise TypeError(f"the transport factory returned {type(transport).__name__}, not a ManipTransport")
    return transport


def with_contact(options: ClientOptions | None, contact: str | None) -> ClientOptions:
    """``options`` (or the defaults) with ``contact`` when one is given."""
    options = options or ClientOptions()
    return options if contact is None else dataclasses.replace(options, contact=contact)


async def open_manipulator(source: TransportSource, options: ClientOptions | None = None) -> Manipulator:
    """Connect, start the background process, wait for the initial RESPONSE; return the manipulator.

    Raises ConnectionLostError (or FatalError, when the server sends one instead of its initial RESPONSE);
    ``manip.links.AddressError`` (a ValueError) for a URL that cannot be parsed.
    """
    options = options or ClientOptions()
    transport = _transport(source, options)
    core = MatchingCore(
        options.registry,
        options.effective_handler_types(),
        expect_initial_response=options.expect_initial_response,
        trivial_errors=options.trivial_errors,
        history=options.history,
        align_args=options.align_args,
        max_reply_bytes=options.max_reply_bytes,
        faults=options.faults,
    )
    process = BackgroundProcess(transport, core, name=options.name, faults=options.faults)
    arm = Manipulator(process, options)  # listens before any packet can arrive
    await process.start(options.connect_timeout)
    return arm


class Connector:
    """What :func:`aconnect` returns: awaitable, and an async context manager that closes on exit."""

    def __init__(self, source: TransportSource, options: ClientOptions | None) -> None:
        self._source = source
        self._options = options
        self._arm: Manipulator | None = None

    def __await__(self) -> Generator[Any, None, Manipulator]:
        return open_manipulator(self._source, self._options).__await__()

    async def __aenter__(self) -> Manipulator:
        self._arm = await open_manipulator(self._source, self._options)
        return self._arm

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._arm is not None:
            await self._arm.aclose()


def aconnect(
    source: TransportSource, options: ClientOptions | None = None, *, contact: str | None = None
) -> Connector:
    """Connect to a manipulator: ``arm = await aconnect(url)`` or ``async with aconnect(url) as arm``."""
    return Connector(source, with_contact(options, contact))
