"""A sans-I/O Chaosnet NCP: Chaos packets and the time in, packets to send and user events out.

``Ncp`` is one host's NCP (see :mod:`manip.ncp.node`), the state table is in :mod:`manip.ncp.states`,
the events in :mod:`manip.ncp.events`.  :class:`LossyChannel` and :class:`Simulation` let tests run two
NCPs against each other over a bad network on a simulated clock.
"""

from __future__ import annotations

from .config import NcpConfig
from .connection import ConnectionInfo, NcpStats
from .defects import ChaosDefects
from .errors import InvalidStateError, NcpError, NoFreeIndexError, UnknownConnectionError, WindowFullError
from .events import (
    Answered,
    Broken,
    Closed,
    ConnectionRequested,
    DataReceived,
    EofReceived,
    Event,
    Forwarded,
    Lost,
    Opened,
    UncontrolledReceived,
)
from .lossy import ChannelStats, LossyChannel
from .node import Ncp
from .sim import Simulation
from .states import ConnState

__all__ = [
    "Answered",
    "Broken",
    "ChannelStats",
    "ChaosDefects",
    "Closed",
    "ConnState",
    "ConnectionInfo",
    "ConnectionRequested",
    "DataReceived",
    "EofReceived",
    "Event",
    "Forwarded",
    "InvalidStateError",
    "LossyChannel",
    "Lost",
    "Ncp",
    "NcpConfig",
    "NcpError",
    "NcpStats",
    "NoFreeIndexError",
    "Opened",
    "Simulation",
    "UncontrolledReceived",
    "UnknownConnectionError",
    "WindowFullError",
]
