"""What every packet link offers the driver: send a packet, hand over what arrives, close, count.

A link moves whole Chaos packets; it knows framings and sockets, not connections.  Input from the wire
is untrusted, so a link never lets a bad frame escape as an exception: it counts the frame under a short
reason (:data:`BAD_REASONS`), logs it at debug level and drops it.  Only a stream whose framing is lost
is closed, because nothing after the bad length can be trusted.  A packet that names our own address as
its source is bad input too: no other host has it, so its header is laid out wrong (clause
``chaos.header.layout``).

A frame that is sound (framing, checksum and lengths check out) but carries an *illegal* packet (an
illegal opcode, more than 488 data bytes) is not bad input: the NCP must answer it with LOS, so the link
delivers it like any other packet and counts it under ``LinkStats.illegal`` (erratum
``illegal-packet-delivery``; the codec reports it as :class:`~manip.codecs.chaos.IllegalPacketError`).
"""

from __future__ import annotations

import asyncio
import logging
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final

from manip.codecs.chaos import IllegalPacketError
from manip.codecs.errors import DecodeError
from manip.codecs.packet import Packet
from manip.ncp.defects import ChaosDefects

from .defective import defective_frame

log = logging.getLogger("manip.links")

Encoder = Callable[..., bytes]
"""``encode(packet, hw_dest=..., hw_src=...)``, one of the framing module's encoders."""
Receiver = Callable[["Link", Packet], None]
"""Called with each good packet a link receives."""
CloseCallback = Callable[["Link"], None]

_CLAUSE_REASONS: Final = {
    "chudp.checksum": "checksum",
    "chudp.word-order": "word_order",
    "chudp.trailer": "trailer",
    "chudp.length": "short",
    "chaos.header.nbytes": "nbytes",
    "chaos.header.unused-byte-zero": "header",
    "chaos.opcode.legal": "opcode",
    "chaos.data.max-488": "oversize",
    "link.tcp.framing": "framing",
    "link.chaosd.framing": "framing",
}

BAD_REASONS: Final = (
    "checksum",
    "framing",
    "short",
    "version",
    "function",
    "nbytes",
    "header",
    "opcode",
    "oversize",
    "unknown_peer",
    "word_order",
    "trailer",
    "other",
)
"""The names bad input is counted under (``LinkStats.bad``)."""


def bad_reason(exc: DecodeError) -> str:
    """The counter name for a decode failure, from the spec clause it breaks."""
    if exc.path.endswith("word-order"):  # a whole frame in the other byte order (a framing clause)
        return "word_order"
    if exc.clause == "chudp.header":
        return "function" if exc.path.endswith("function") else "version"
    return _CLAUSE_REASONS.get(exc.clause or "", "other")


@dataclass(slots=True)
class LinkStats:
    """Counters of one link.  ``bad`` counts refused input by reason (and ``bad_clauses`` by the clause
    of the spec it breaks, where one says), ``dropped`` refused output, and ``illegal`` the sound frames
    with an illegal packet that were delivered for the NCP to answer with LOS (also counted in
    ``frames_in``), under ``opcode`` or ``oversize``."""

    frames_in: int = 0
    frames_out: int = 0
    bytes_in: int = 0
    bytes_out: int = 0
    bad: Counter[str] = field(default_factory=Counter)
    bad_clauses: Counter[str] = field(default_factory=Counter)
    dropped: Counter[str] = field(default_factory=Counter)
    illegal: Counter[str] = field(default_factory=Counter)

    @property
    def bad_total(self) -> int:
        return sum(self.bad.values())

    def add(self, other: LinkStats) -> None:
        """Add ``other``'s counts to these (a node sums its links, closed ones included)."""
        self.frames_in += other.frames_in
        self.frames_out += other.frames_out
        self.bytes_in += other.bytes_in
        self.bytes_out += other.bytes_out
        self.bad.update(other.bad)
        self.bad_clauses.update(other.bad_clauses)
        self.dropped.update(other.dropped)
        self.illegal.update(other.illegal)


class Link(ABC):
    """One packet link.  Subclasses implement :meth:`send` and :meth:`close` and call the helpers.

    ``point_to_point`` links reach exactly one neighbour (``peer_addr`` once known); a multi-peer link
    (CHUDP) needs the ``next_hop`` argument of :meth:`send` to choose the neighbour.
    """

    kind: str = "link"
    point_to_point: bool = True

    def __init__(
        self,
        *,
        my_addr: int,
        peer_addr: int | None = None,
        name: str = "",
        defects: ChaosDefects | None = None,
    ) -> None:
        self.my_addr = my_addr
        self.defects = defects or ChaosDefects()
        """How this host departs from the Chaosnet rules (none, but for the reference server's faults)."""
        self._framed_by_the_rules = self.defects.frames_by_the_rules
        self.peer_addr = peer_addr
        self.name = name or self.kind
        self.stats = LinkStats()
        self.close_reason: str | None = None
        self._receiver: Receiver | None = None
        self._close_callbacks: list[CloseCallback] = []
        self._closed: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    def __repr__(self) -> str:
        state = f" closed: {self.close_reason}" if self.close_reason is not None else ""
        return f"<{type(self).__name__} {self.name}{state}>"

    # ---------------------------------------------------------------- the driver's side

    def set_receiver(self, receiver: Receiver | None) -> None:
        """Register the callback that gets every good packet (None: drop them)."""
        self._receiver = receiver

    def on_close(self, callback: CloseCallback) -> None:
        """Call ``callback(link)`` once when the link closes (at once if it already has)."""
        if self.close_reason is not None:
            callback(self)
        else:
            self._close_callbacks.append(callback)

    @property
    def closed(self) -> asyncio.Future[None]:
        """Done once the link is closed, for whatever reason (see ``close_reason``)."""
        return self._closed

    @property
    def is_closed(self) -> bool:
        return self.close_reason is not None

    @abstractmethod
    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        """Queue ``packet`` for the wire without blocking; False (and counted) if it had to be dropped.

        ``next_hop`` is the Chaos address of the neighbour that should get it (the trailer destination);
        None means the link's peer, or the packet's destination host."""

    @abstractmethod
    def close(self) -> None:
        """Close the link; queued output is still flushed where the transport can."""

    # ---------------------------------------------------------------- helpers for subclasses

    def _frame(self, encode: Encoder, packet: Packet, hop: int | None) -> bytes:
        """``packet``'s frame for neighbour ``hop``: as ``encode`` (the codec's) lays it out, or with this
        link's framing defects."""
        if self._framed_by_the_rules:
            return encode(packet, hw_dest=hop, hw_src=self.my_addr)
        return defective_frame(self.kind, packet, hop, self.my_addr, self.defects)

    def _deliver(self, packet: Packet) -> None:
        if packet.src_host == self.my_addr:  # no other host has our address: its header is laid out wrong
            self._bad(
                "header", f"source host {packet.src_host:o} is our own: {packet!r}", "chaos.header.layout"
            )
            return
        self.stats.frames_in += 1
        receiver = self._receiver
        if receiver is None:
            self.stats.dropped["no_receiver"] += 1
            return
        try:
            receiver(self, packet)
        except Exception:  # the driver must survive anything; a bug there must not kill the link
            log.exception("%s: receiver failed on %r", self.name, packet)

    def _illegal(self, exc: IllegalPacketError, detail: object = "") -> Packet:
        """Count a sound frame holding an illegal packet; return the packet, which is to be delivered."""
        self.stats.illegal[bad_reason(exc)] += 1
        log.debug("%s: illegal packet passed on for a LOS: %s%s", self.name, exc, detail)
        return exc.packet

    def _bad(self, reason: str, detail: object, clause: str | None = None) -> None:
        self.stats.bad[reason] += 1
        if clause is not None:
            self.stats.bad_clauses[clause] += 1
        log.debug("%s: dropped bad input (%s): %s", self.name, reason, detail)

    def _drop(self, reason: str, packet: Packet) -> bool:
        self.stats.dropped[reason] += 1
        log.debug("%s: dropped outgoing packet (%s): %r", self.name, reason, packet)
        return False

    def _set_closed(self, reason: str) -> None:
        """Record the close once and tell the callbacks; later calls do nothing."""
        if self.close_reason is not None:
            return
        self.close_reason = reason
        log.debug("%s: closed (%s)", self.name, reason)
        if not self._closed.done():
            self._closed.set_result(None)
        callbacks, self._close_callbacks = self._close_callbacks, []
        for callback in callbacks:
            try:
                callback(self)
            except Exception:
                log.exception("%s: close callback failed", self.name)
