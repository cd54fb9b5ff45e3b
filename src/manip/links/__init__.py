"""asyncio drivers for the sans-I/O NCP: packet links, the node that drives the core, and the user API.

* :func:`open_connection`, :func:`start_server`, :class:`ChaosConnection`, :class:`ChaosServer`:
  what an application uses;
* :class:`Node`: one NCP on one or more links (:mod:`~manip.links.ncp_driver` explains the routing);
* links: :mod:`~manip.links.tcp` (manip's own, the default), :mod:`~manip.links.chudp`,
  :mod:`~manip.links.chaosd`, all :class:`Link`;
* :mod:`~manip.links.guard`: a server's bounds on its links (:class:`LinkLimits`) and who may use it
  (:class:`AccessList`);
* :mod:`~manip.links.errors`: everything raised is a :class:`ChaosError`.
"""

from manip.ncp import NcpConfig

from .address import AddressError, LinkAddress, parse_address
from .api import ChaosServer, Handler, open_connection, start_server
from .base import Link, LinkStats
from .chaos_connection import ChaosConnection, ConnectionStats
from .errors import (
    ChaosError,
    ConnectionAnswered,
    ConnectionBroken,
    ConnectionClosed,
    ConnectionForwarded,
    ConnectionLost,
    ConnectionRefused,
    ConnectTimeout,
    LinkError,
)
from .guard import AccessError, AccessList, GuardStats, LinkGuard, LinkLimits
from .ncp_driver import Node, NodeStats

__all__ = [
    "AccessError",
    "AccessList",
    "AddressError",
    "ChaosConnection",
    "ChaosError",
    "ChaosServer",
    "ConnectTimeout",
    "ConnectionAnswered",
    "ConnectionBroken",
    "ConnectionClosed",
    "ConnectionForwarded",
    "ConnectionLost",
    "ConnectionRefused",
    "ConnectionStats",
    "GuardStats",
    "Handler",
    "Link",
    "LinkAddress",
    "LinkError",
    "LinkGuard",
    "LinkLimits",
    "LinkStats",
    "NcpConfig",
    "Node",
    "NodeStats",
    "open_connection",
    "parse_address",
    "start_server",
]
