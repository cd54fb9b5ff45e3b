"""The reference client: the 1985 guide's "Manip system" (Part I) as a typed asyncio library.

Layers, bottom up (each module's docstring says more):

* :mod:`~.request`, :mod:`~.registry`, :mod:`~.definitions`: request objects; named request and
  response codes, response-handler types, handlers and data extractors (§3.2), pre-filled from the spec;
* :mod:`~.matching` (with :mod:`~.handlers`, :mod:`~.events`): the sans-I/O core that matches
  responses to requests by the request number in the first data word;
* :mod:`~.transport`: the operations a communication protocol provides (§3.1);
  :mod:`~.ncp_transport` is the Chaos one over ``manip.links`` (what a URL connects with),
  :mod:`~.core_transport` runs a sans-I/O server core in memory on a virtual clock, and
  :mod:`~.memory` is an in-memory one with a server end for scripted test peers;
* :mod:`~.background`: the asyncio background process;
* :mod:`~.manipulator` (:mod:`~.generic`, :mod:`~.puma`): the operations;
  :mod:`~.connect` opens a connection (URL or transport), :mod:`~.sync` is the blocking facade;
* :mod:`~.cli` is ``manip-client URL COMMAND``, printing through :mod:`~.cli_output`.

::

    async with aconnect("tcp://127.0.0.1:42085") as arm:   # a URL, a ManipTransport or a factory
        pose = await arm.here()
        segment = await arm.move(pose @ Transform.trans(0, 0, 10))
        await arm.wait_for_segment(segment)

    with connect("tcp://127.0.0.1:42085") as arm:
        print(arm.joint_angles())
"""

from manip.reference_client.background import BackgroundProcess
from manip.reference_client.connect import (
    Connector,
    TransportFactory,
    TransportSource,
    aconnect,
    open_manipulator,
)
from manip.reference_client.core_transport import CoreTransport, ServerCore, VirtualClock
from manip.reference_client.definitions import (
    DEFAULT_REGISTRY,
    default_registry,
    define_data_extractor,
    define_request_code,
    define_response_code,
    define_response_handler,
    define_response_handler_type,
)
from manip.reference_client.errors import (
    AsynchronousError,
    AsynchronousWarning,
    ConnectionLostError,
    FatalError,
    GuardTrippedError,
    JointFreedError,
    ManipError,
    NonFatalError,
    OutOfSequenceReason,
    OutOfSequenceResponse,
    ReplyTooLargeError,
    RequestTimeout,
    ResponseDataError,
    ServerError,
)
from manip.reference_client.handlers import CHAOS_MANIPULATOR, GENERIC, NOTIFY_TRIVIAL_ERRORS
from manip.reference_client.issuer import DEFAULT
from manip.reference_client.manipulator import NOTIFY_GUARD_HITS, NOTIFY_SEGMENTS, Manipulator
from manip.reference_client.matching import MatchingCore, Phase, ResponseContext
from manip.reference_client.memory import MemoryPeer, MemoryTransport, SentRequest
from manip.reference_client.ncp_transport import NcpTransport
from manip.reference_client.options import ClientOptions
from manip.reference_client.packets import ResponseInfo, ServerPacket, chaos_response_info
from manip.reference_client.policy import TrivialErrors
from manip.reference_client.registry import Registry, ResponseCode
from manip.reference_client.request import Request, RequestCode, RequestState, ResponseType
from manip.reference_client.stream import AsyncResponseStream
from manip.reference_client.sync import SyncManipulator, connect
from manip.reference_client.transport import ManipTransport

__all__ = [
    "CHAOS_MANIPULATOR",
    "DEFAULT",
    "DEFAULT_REGISTRY",
    "GENERIC",
    "NOTIFY_GUARD_HITS",
    "NOTIFY_SEGMENTS",
    "NOTIFY_TRIVIAL_ERRORS",
    "AsyncResponseStream",
    "AsynchronousError",
    "AsynchronousWarning",
    "BackgroundProcess",
    "ClientOptions",
    "ConnectionLostError",
    "Connector",
    "CoreTransport",
    "FatalError",
    "GuardTrippedError",
    "JointFreedError",
    "ManipError",
    "ManipTransport",
    "Manipulator",
    "MatchingCore",
    "MemoryPeer",
    "MemoryTransport",
    "NcpTransport",
    "NonFatalError",
    "OutOfSequenceReason",
    "OutOfSequenceResponse",
    "Phase",
    "Registry",
    "ReplyTooLargeError",
    "Request",
    "RequestCode",
    "RequestState",
    "RequestTimeout",
    "ResponseCode",
    "ResponseContext",
    "ResponseDataError",
    "ResponseInfo",
    "ResponseType",
    "SentRequest",
    "ServerCore",
    "ServerError",
    "ServerPacket",
    "SyncManipulator",
    "TransportFactory",
    "TransportSource",
    "TrivialErrors",
    "VirtualClock",
    "aconnect",
    "chaos_response_info",
    "connect",
    "default_registry",
    "define_data_extractor",
    "define_request_code",
    "define_response_code",
    "define_response_handler",
    "define_response_handler_type",
    "open_manipulator",
]
