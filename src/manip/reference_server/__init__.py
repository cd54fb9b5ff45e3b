"""The reference Puma server: a simulated arm that implements the whole Chaos manipulator protocol.

This package is the sans-I/O core: :class:`ServerSession` (one connection's protocol state machine, fed
packets and time, returning packets to send), the fault switches that bend it for testing conformance
suites (:mod:`~manip.reference_server.faults`), the describe-self text and the seam for the Cougar wrist.
The simulated arm itself is :class:`manip.arm.sim.ArmSim`.
"""

from manip.reference_server.describe import Description, describe_text
from manip.reference_server.errors import RequestError
from manip.reference_server.faults import FAULTS, Fault, FaultInfo, FaultSet
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
    "FAULTS",
    "HANDLERS",
    "TRANSITIONS",
    "WRIST_OPERATIONS",
    "Description",
    "Fault",
    "FaultInfo",
    "FaultSet",
    "Input",
    "NoWrist",
    "Outgoing",
    "Output",
    "RequestError",
    "ServerConfig",
    "ServerSession",
    "SessionUsageError",
    "State",
    "Wrist",
    "describe_text",
]
