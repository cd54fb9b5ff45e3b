"""Capture and replay of manip sessions in MCAP files (Foxglove opens them).

* :class:`Recorder` writes a capture (:mod:`~manip.captures.format` describes the file);
* :class:`TappedLink` / :class:`RecorderTap` record any node's traffic through the ``wrap_link`` hook
  of :func:`manip.links.open_connection` and :func:`manip.links.start_server`;
* :mod:`~manip.captures.proxy`: a transparent recording proxy (TCP link, CHUDP);
* :func:`read_capture`, :func:`read_sessions`, :func:`read_session`, :func:`iter_packets` read it back
  as typed records (sessions, pairs, events) for replay and offline verification;
* :func:`recover` rebuilds a valid file from a truncated one (a killed recorder).
"""

from manip.codecs.packet import Direction

from .bounds import CaptureDamagedError
from .reader import (
    Capture,
    CapturedEvent,
    CapturedPacket,
    CaptureTruncatedError,
    LinkInfo,
    Pair,
    Session,
    iter_packets,
    read_capture,
    read_session,
    read_sessions,
)
from .recorder import CaptureError, Recorder
from .recover import RecoveryReport, recover
from .tap import PacketTap, RecorderTap, TappedLink
from .view import Annotation, Annotator

__all__ = [
    "Annotation",
    "Annotator",
    "Capture",
    "CaptureDamagedError",
    "CaptureError",
    "CaptureTruncatedError",
    "CapturedEvent",
    "CapturedPacket",
    "Direction",
    "LinkInfo",
    "PacketTap",
    "Pair",
    "Recorder",
    "RecorderTap",
    "RecoveryReport",
    "Session",
    "TappedLink",
    "iter_packets",
    "read_capture",
    "read_session",
    "read_sessions",
    "recover",
]
