"""What a fuzz input is: a numbered handful of steps, each sent to the target in one of four ways.

An input is generated from the campaign seed and its number alone (:mod:`.generators`), so the same
seed gives the same inputs and ``--only N,M`` sends exactly inputs N and M again.  Its steps:

* :class:`RequestStep`: a manip request on the batch's Chaos connection (opened by hand, see
  :mod:`.session`).  Its answer is judged with the rest of the connection by the transcript checks
  of :mod:`manip.conformance.judge.checks`, which know what the spec demands for each opcode and data.
* :class:`ConnPacket`: a packet on the connection's link whose number or indices are wrong on purpose
  (out of the window, a duplicate, a wrong source index) or that is no request (SNS, UNC).
* :class:`Stray`: a packet on a side link that belongs to no connection (or is an RFC), possibly
  damaged below the packet (checksum, byte count, header byte, CHUDP header and length).
* :class:`Raw`: bytes on a link of their own (stream links: the link is opened, written and left to
  the target), or one datagram of arbitrary bytes (CHUDP).
* :class:`Pause`: time for the target's arm to move, so that what it reports of motion is seen.
* :class:`Reconnect`: close the connection (once every request on it is answered) and open a new one,
  to see what a connection leaves behind (the diff's scenarios; the generators never make one).
* :class:`Silence`: the connection kept silent, not even receipting, to see whether the target gives it
  up (the diff's silent-peer scenario; the generators never make one).

Each non-request step carries the answer the spec demands (``expect``) and the clause that demands it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from manip.codecs.packet import Packet
from manip.conformance.suite.rawchaos import Damage

__all__ = [
    "ConnPacket",
    "FuzzInput",
    "Pause",
    "Raw",
    "Reconnect",
    "Relative",
    "RequestStep",
    "Silence",
    "Step",
    "Stray",
    "StrayExpect",
]

Relative = Literal["ahead", "behind", "duplicate", "wrong-source", "sns", "unc", "rfc", "lose"]
"""How a :class:`ConnPacket` relates to the connection: numbered past the receive window, numbered
before the next expected packet, the last request again, from a source index that is not the
connection's, a sense-status request, uncontrolled data, the connection's own RFC again (a
retransmitted RFC: its opcode and data are the RFC's, whatever the step says); ``lose`` sends nothing:
the next controlled packet from the target is lost on its way (dropped unreceipted, as a lossy link
drops one), and must come again."""
StrayExpect = Literal["los", "answer", "silence"]
"""A LOS back to the sender, an answer to an RFC (OPN, CLS, ANS or FWD), or nothing at all."""


@dataclass(frozen=True, slots=True)
class RequestStep:
    """A request on the batch's connection: ``opcode`` and ``data`` exactly as given.

    ``chunk``: write the frame in pieces of this many bytes (0: in one write).  ``lazy``: part of a
    pipeline that does not read: the server's packets are not acknowledged until its window stops us.
    """

    opcode: int
    data: bytes
    chunk: int = 0
    lazy: bool = False


@dataclass(frozen=True, slots=True)
class ConnPacket:
    """A packet on the connection's link, placed relative to the connection when it is sent."""

    what: Relative
    opcode: int
    data: bytes = b""
    offset: int = 0
    """ahead: packets past the window; behind: packets before the next one; wrong-source: XORed into
    our index to make the wrong one."""
    clause: str = "ncp.window"


@dataclass(frozen=True, slots=True)
class Stray:
    """A packet to no connection (or an RFC), on the side link.  In ``packet`` a destination host of
    0 means the target's, a source host of 0 ours; the source index is the sender's key for the answer."""

    packet: Packet
    expect: StrayExpect
    clause: str
    damage: Damage = ""
    counted: bool = False
    """The target's link must count it as bad input (it is dropped below the NCP)."""


@dataclass(frozen=True, slots=True)
class Raw:
    """Bytes on a stream link of their own, or one datagram.  ``closes``: the target must drop the link
    (stream framing lost); ``counted``: bad frames the target's link must count."""

    data: bytes
    clause: str
    closes: bool = False
    counted: int = 0
    hold: bool = False
    """Leave the link open until the end of the batch (a peer that stays after a partial frame)."""


@dataclass(frozen=True, slots=True)
class Pause:
    """Let the target's clock run: up to ``seconds``, less if an asynchronous packet comes first (motion
    ending within a batch, so its completion responses are seen)."""

    seconds: float


@dataclass(frozen=True, slots=True)
class Reconnect:
    """Close the connection once its requests are answered, let the target's clock run ``after``
    seconds (the close taken before the next RFC comes), and go on on a new connection."""

    after: float = 0.5


@dataclass(frozen=True, slots=True)
class Silence:
    """Once every request on the connection is answered and receipted, let the target's clock run
    ``seconds`` with the connection silent: nothing sent on it, no receipt of what comes, no answer to the
    target's SNS probes (a peer gone quiet, as ``server.ncp.broken``'s is)."""

    seconds: float


Step = RequestStep | ConnPacket | Stray | Raw | Pause | Reconnect | Silence


@dataclass(frozen=True, slots=True)
class FuzzInput:
    """Input ``number`` of a campaign: its class, its steps, one line saying what it is."""

    number: int
    kind: str
    steps: tuple[Step, ...]
    note: str

    @property
    def requests(self) -> int:
        return sum(isinstance(s, RequestStep) for s in self.steps)
