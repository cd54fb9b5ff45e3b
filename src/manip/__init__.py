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
(:mod:`manip.reference_client`), loaded on first use so that ``import manip`` stays light::

    with manip.connect("tcp://127.0.0.1:42085") as arm:
        print(arm.here())
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from manip.reference_client import aconnect, connect

__version__ = "0.1.0"
__all__ = ["__version__", "aconnect", "connect"]

_LAZY = frozenset({"aconnect", "connect"})


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module("manip.reference_client"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'manip' has no attribute {name!r}")
