"""Exceptions the NCP raises at its user.  Packets from the network never raise: bad ones draw a LOS or
are dropped."""

from __future__ import annotations


class NcpError(Exception):
    """Base class of the NCP's errors."""


class UnknownConnectionError(NcpError, KeyError):
    """No connection has this id (never had, or it was finished long ago and its slot reused)."""


class InvalidStateError(NcpError):
    """The call is not allowed in the connection's current state."""


class WindowFullError(NcpError):
    """The peer's receive window is full: wait for an acknowledgement (see ``Ncp.can_send``)."""


class NoFreeIndexError(NcpError):
    """Every connection slot is in use."""
