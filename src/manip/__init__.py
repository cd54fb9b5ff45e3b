"""manip: specification and conformance toolkit for the MIT Puma/Cougar manipulator protocols.

Layers, bottom up (imports point down only; ``lint-imports`` checks it, ``docs/architecture.md`` tells
how a request goes through them):

* ``manip.spec``              the protocols as data: clauses, opcode tables, layouts, errata;
* ``manip.codecs``            exact encoders and decoders driven by the spec: floats, Chaos packets and
  link framings, manip messages, error strings, Lisp text, Cougar words;
* ``manip.arm``               kinematics, trajectories, the simulated arm and its move process (sans-I/O);
* ``manip.ncp``, ``manip.cougar``  sans-I/O cores: the Chaos NCP, the Cougar wrist computer;
* ``manip.links``             asyncio drivers: TCP, CHUDP, chaosd and unix links, the DRV-11J port, the
  virtual clock;
* ``manip.captures``          MCAP recording, reading and recovery;
* ``manip.reference_client``  the Manip system of Part I of the 1985 guide, and ``manip-client``;
* ``manip.decode``, ``manip.reference_server``  ``manip-decode``; the reference Puma;
* ``manip.conformance``       ``manip-conform``: cases, runner, judges, replay and verify.

``manip.connect(url)`` and ``manip.aconnect(url)`` are the reference client's
(:mod:`manip.reference_client`), loaded on first use so that ``import manip`` stays light, with the
notification masks ``NOTIFY_SEGMENTS`` and ``NOTIFY_GUARD_HITS``::

    with manip.connect("tcp://127.0.0.1:42085") as arm:
        print(arm.here())

The exceptions a user catches are here too, loaded on first use as well::

    try:
        arm.set_speed(0.5)
    except manip.NonFatalError as err:      # the server refused: err.code, err.where, err.arguments
        ...
    except manip.ConnectionLostError:       # the connection is gone
        ...

* from the client: :class:`ManipError` (the base of all below), :class:`ServerError` (an error string:
  :class:`FatalError`, :class:`NonFatalError`, :class:`AsynchronousError`,
  :class:`AsynchronousWarning`), :class:`ConnectionLostError`, :class:`RequestTimeout` (also a
  TimeoutError), :class:`ResponseDataError`, :class:`ReplyTooLargeError`, :class:`JointFreedError`,
  :class:`GuardTrippedError`;
* from the codecs: :class:`CodecError` (a ValueError) and its :class:`DecodeError`, :class:`EncodeError`;
* :class:`AddressError` (a link URL that does not parse), :class:`ChaosError` (the Chaos links),
  :class:`CaptureError` (a capture that cannot be read or written), :class:`SpecError`,
  :class:`UnknownClauseError` (a clause id the spec does not have; a KeyError naming close matches).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from manip.captures.recorder import CaptureError
    from manip.codecs.errors import CodecError, DecodeError, EncodeError
    from manip.links.address import AddressError
    from manip.links.errors import ChaosError
    from manip.reference_client import NOTIFY_GUARD_HITS, NOTIFY_SEGMENTS, aconnect, connect
    from manip.reference_client.errors import (
        AsynchronousError,
        AsynchronousWarning,
        ConnectionLostError,
        FatalError,
        GuardTrippedError,
        JointFreedError,
        ManipError,
        NonFatalError,
        ReplyTooLargeError,
        RequestTimeout,
        ResponseDataError,
        ServerError,
    )
    from manip.spec.loader import SpecError, UnknownClauseError

__version__ = "0.1.0"

_CLIENT_ERRORS = (
    "AsynchronousError",
    "AsynchronousWarning",
    "ConnectionLostError",
    "FatalError",
    "GuardTrippedError",
    "JointFreedError",
    "ManipError",
    "NonFatalError",
    "ReplyTooLargeError",
    "RequestTimeout",
    "ResponseDataError",
    "ServerError",
)
_LAZY: dict[str, str] = {
    "aconnect": "manip.reference_client",
    "connect": "manip.reference_client",
    "NOTIFY_GUARD_HITS": "manip.reference_client",
    "NOTIFY_SEGMENTS": "manip.reference_client",
    **dict.fromkeys(_CLIENT_ERRORS, "manip.reference_client.errors"),
    **dict.fromkeys(("CodecError", "DecodeError", "EncodeError"), "manip.codecs.errors"),
    "AddressError": "manip.links.address",
    "ChaosError": "manip.links.errors",
    "CaptureError": "manip.captures.recorder",
    "SpecError": "manip.spec.loader",
    "UnknownClauseError": "manip.spec.loader",
}
"""Name -> the module that defines it, imported when the name is first used (``import manip`` stays
light: the client, numpy and the capture library load only when asked for)."""

__all__ = [
    "NOTIFY_GUARD_HITS",
    "NOTIFY_SEGMENTS",
    "AddressError",
    "AsynchronousError",
    "AsynchronousWarning",
    "CaptureError",
    "ChaosError",
    "CodecError",
    "ConnectionLostError",
    "DecodeError",
    "EncodeError",
    "FatalError",
    "GuardTrippedError",
    "JointFreedError",
    "ManipError",
    "NonFatalError",
    "ReplyTooLargeError",
    "RequestTimeout",
    "ResponseDataError",
    "ServerError",
    "SpecError",
    "UnknownClauseError",
    "__version__",
    "aconnect",
    "connect",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is not None:
        value = getattr(importlib.import_module(module), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'manip' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})
