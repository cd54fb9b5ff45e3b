"""Record any session without touching the NCP: a :class:`TappedLink` sits between a node and its link.

``TappedLink(inner, tap)`` is a :class:`~manip.links.Link` that delegates everything to ``inner`` and
tells ``tap`` about every packet sent (after the link accepted it) and received (before the node sees
it), with the time, and about the link closing.  The node only ever sees the wrapper: the receiver and
close callbacks are called with it, so the node's routing by link identity is unchanged.

:class:`RecorderTap` is the tap that writes to a :class:`~manip.captures.recorder.Recorder`; its
``side`` says which end of the protocol the tapped node is (``server``: what it receives is client to
server).  Pass ``tap.wrap`` as ``wrap_link`` to :func:`manip.links.open_connection` or
:func:`manip.links.start_server`::

    with Recorder("session.mcap", how="server") as rec:
        server = await start_server(url, "PUMA", handler, wrap_link=RecorderTap(rec, "server").wrap)

A tap that raises is logged and counted (``TappedLink.tap_errors``); the session goes on.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any, Literal, Protocol

from manip.codecs.packet import Direction, Packet
from manip.links import Link, LinkStats
from manip.links.base import CloseCallback, Receiver

from .recorder import Recorder

log = logging.getLogger("manip.captures")

Side = Literal["client", "server"]


class PacketTap(Protocol):
    """What a :class:`TappedLink` reports.  Times are nanoseconds of the tap's clock (Unix time, or a
    simulated run's virtual clock)."""

    def clock_ns(self) -> int: ...

    def link_opened(self, link: TappedLink) -> None: ...

    def packet_sent(self, link: TappedLink, packet: Packet, next_hop: int | None, t_ns: int) -> None: ...

    def packet_received(self, link: TappedLink, packet: Packet, t_ns: int) -> None: ...

    def link_closed(self, link: TappedLink, reason: str, t_ns: int) -> None: ...


class TappedLink(Link):
    """A link that reports its traffic to a tap and otherwise is ``inner`` (see the module docstring)."""

    # Link.__init__ is deliberately not called: every piece of link state (stats, close reason, the
    # closed future, peer address) is the inner link's, read through the properties below.
    def __init__(self, inner: Link, tap: PacketTap) -> None:
        self.inner = inner
        self.tap = tap
        self.kind = inner.kind
        self.point_to_point = inner.point_to_point
        self.tap_errors = 0
        self._receiver: Receiver | None = None
        self._report(tap.link_opened, self)
        inner.on_close(self._inner_closed)

    def __repr__(self) -> str:
        return f"<TappedLink {self.inner!r}>"

    def __getattr__(self, name: str) -> Any:
        # Extras of particular links (peers, local_address, abort, pause_reading...) pass through.
        return getattr(self.inner, name)

    # ------------------------------------------------------------------------------ delegated state

    @property
    def my_addr(self) -> int:
        return self.inner.my_addr

    @my_addr.setter
    def my_addr(self, value: int) -> None:
        self.inner.my_addr = value

    @property
    def peer_addr(self) -> int | None:
        return self.inner.peer_addr

    @peer_addr.setter
    def peer_addr(self, value: int | None) -> None:
        self.inner.peer_addr = value

    @property
    def name(self) -> str:
        return self.inner.name

    @name.setter
    def name(self, value: str) -> None:
        self.inner.name = value

    @property
    def stats(self) -> LinkStats:
        return self.inner.stats

    @stats.setter
    def stats(self, value: LinkStats) -> None:
        self.inner.stats = value

    @property
    def close_reason(self) -> str | None:
        return self.inner.close_reason

    @close_reason.setter
    def close_reason(self, value: str | None) -> None:
        self.inner.close_reason = value

    @property
    def closed(self) -> asyncio.Future[None]:
        return self.inner.closed

    # ------------------------------------------------------------------------------ the driver's side

    def set_receiver(self, receiver: Receiver | None) -> None:
        self._receiver = receiver
        self.inner.set_receiver(None if receiver is None else self._on_packet)

    def on_close(self, callback: CloseCallback) -> None:
        self.inner.on_close(lambda _inner: callback(self))

    def send(self, packet: Packet, next_hop: int | None = None) -> bool:
        sent = self.inner.send(packet, next_hop)
        if sent:
            self._report(self.tap.packet_sent, self, packet, next_hop, self.tap.clock_ns())
        return sent

    def close(self) -> None:
        self.inner.close()

    # ------------------------------------------------------------------------------ internals

    def _on_packet(self, _inner: Link, packet: Packet) -> None:
        self._report(self.tap.packet_received, self, packet, self.tap.clock_ns())
        receiver = self._receiver
        if receiver is not None:
            receiver(self, packet)

    def _inner_closed(self, inner: Link) -> None:
        self._report(self.tap.link_closed, self, inner.close_reason or "closed", self.tap.clock_ns())

    def _report(self, method: Any, *args: Any) -> None:
        try:
            method(*args)
        except Exception:
            self.tap_errors += 1
            if self.tap_errors == 1:  # the first in full; the rest would repeat it for every packet
                log.exception(
                    "%s: capture tap failed (further failures counted in tap_errors)", self.inner.name
                )


class RecorderTap:
    """A :class:`PacketTap` writing to a recorder; ``side`` is the tapped node's end of the protocol."""

    def __init__(self, recorder: Recorder, side: Side) -> None:
        if side not in ("client", "server"):
            raise ValueError(f"side must be 'client' or 'server', not {side!r}")
        self.recorder = recorder
        self.side = side
        self._sent: Direction = "c2s" if side == "client" else "s2c"
        self._received: Direction = "s2c" if side == "client" else "c2s"
        self._ids: dict[int, int] = {}

    def clock_ns(self) -> int:
        return self.recorder.clock_ns()

    def wrap(self, link: Link) -> Link:
        """The ``wrap_link`` hook of :func:`manip.links.open_connection` and ``start_server``."""
        return TappedLink(link, self)

    def link_opened(self, link: TappedLink) -> None:
        self._ids[id(link)] = self.recorder.open_link(link.kind, name=link.name)

    def packet_sent(self, link: TappedLink, packet: Packet, next_hop: int | None, t_ns: int) -> None:
        if self.recorder.closed:
            return
        # The trailer destination each link writes (see the links' send methods).
        if link.kind == "chaosd" or (next_hop is None and link.kind != "tcp"):
            hop: int | None = packet.dest_host
        else:
            hop = next_hop if next_hop is not None else link.peer_addr
        self.recorder.packet(
            self._ids[id(link)], self._sent, packet, hw_dest=hop, hw_src=link.my_addr, t_ns=t_ns
        )

    def packet_received(self, link: TappedLink, packet: Packet, t_ns: int) -> None:
        if self.recorder.closed:
            return
        trailer = packet.trailer
        self.recorder.packet(
            self._ids[id(link)],
            self._received,
            packet,
            hw_dest=trailer.dest if trailer is not None else None,
            hw_src=trailer.source if trailer is not None else None,
            t_ns=t_ns,
        )

    def link_closed(self, link: TappedLink, reason: str, t_ns: int) -> None:
        if not self.recorder.closed:
            self.recorder.close_link(self._ids[id(link)], reason, t_ns)
