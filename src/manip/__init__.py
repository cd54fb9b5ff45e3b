"""manip: specification and conformance toolkit for the MIT Puma/Cougar manipulator protocols.

Layers, bottom up (imports point down only):

* ``manip.spec``    the protocol as data: clauses, opcode tables, layouts, errata.
* ``manip.codecs``  exact encoders/decoders driven by the spec (construct).
* ``manip.ncp``     sans-I/O cores (Chaos NCP, ...).
* ``manip.links``   asyncio drivers that move bytes.
* applications      ``manip.decode``, ``manip.reference_server``, ``manip.reference_client`` (and later
  conformance, capture).

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
