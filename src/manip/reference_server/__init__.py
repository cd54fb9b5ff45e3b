"""The reference Puma server: a simulated arm that implements the whole Chaos manipulator protocol.

This package is the sans-I/O core: :class:`ServerSession` (one connection's protocol state machine, fed
packets and time, returning packets to send), the fault switches that bend it for testing conformance
suites (:mod:`~manip.reference_server.faults`; the conditions of the arm's world are
:mod:`~manip.reference_server.conditions`) at the hook points of :mod:`~manip.reference_server.defects`,
the describe-self text and the seam for the Cougar wrist.
The simulated arm itself is :class:`manip.arm.sim.ArmSim`.  :func:`serve` (:mod:`~.driver`) runs it over
Chaos links with asyncio; ``manip-server`` (:mod:`~.cli`) is the command.
"""

from manip.reference_server.conditions import WorldCondition, WorldConditions
from manip.reference_server.describe import Description, describe_text
from manip.reference_server.driver import ReferenceServer, ServerStats, serve
from manip.reference_server.errors import RequestError
from manip.reference_server.faults import Fault, FaultSet
from manip.reference_server.session import (
    HANDLERS,
    TRANSITIONS,
    WRIST_OPERATIONS,
    Input,
    Outgoing,
    Output,
    ServerConfig,
    ServerSession,
    SessionUsageError,
    State,
)
from manip.reference_server.wrist import NoWrist, Wrist

__all__ = [
    "HANDLERS",
    "TRANSITIONS",
    "WRIST_OPERATIONS",
    "Description",
    "Fault",
    "FaultSet",
    "Input",
    "NoWrist",
    "Outgoing",
    "Output",
    "ReferenceServer",
    "RequestError",
    "ServerConfig",
    "ServerSession",
    "ServerStats",
    "SessionUsageError",
    "State",
    "WorldCondition",
    "WorldConditions",
    "Wrist",
    "describe_text",
    "serve",
]
