"""The asyncio driver of one sans-I/O NCP: links in and out, the event loop's clock, one timer.

``Node`` owns an :class:`~manip.ncp.Ncp` and does only what the core cannot: it feeds packets from its
links to ``ncp.receive``, sends what ``packets_to_send`` returns on the right link, keeps one timer
armed at ``next_deadline``, and turns events into the state of :class:`ChaosConnection` objects and
calls to listeners.  Every protocol decision stays in the core.

Routing (which link, and which neighbour on it, gets an outgoing packet), first match wins:

1. a packet produced while the core handles a packet from host H, addressed to H, goes back the way
   that packet came (this is how a server answers clients it has no route to);
2. a packet of a connection goes on the link its connection was made over;
3. the host routes given to :meth:`Node.attach` (a point-to-point link routes its peer's address), then
   the default route;
4. otherwise it is dropped and counted (``stats.no_route``).

Because connections are bound to a link, two clients on two TCP links may even use the same Chaos
address: a packet naming a connection that arrived on another link is dropped (``wrong_link``), and an
RFC whose (host, index) is in use on another open link is refused.  A connection whose link closes is
aborted at once (ConnectionBroken) rather than waiting ``broken_after``.

The timer: one ``call_at`` handle, armed at ``ncp.next_deadline()`` after every call into the core.
Asking the core costs a scan of its connections, so it is skipped while the armed time is no later than
the ``now`` of the latest call into the core plus the shortest of the NCP's intervals: every deadline
the core sets is at least that far after the call that sets it, so none can be earlier than the armed
one.  A timer that fires before anything is due just re-arms itself.
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Final

from manip.codecs.packet import MAX_DATA, Packet
from manip.ncp import (
    Answered,
    Broken,
    Closed,
    ConnectionRequested,
    ConnState,
    DataReceived,
    EofReceived,
    Event,
    Forwarded,
    Lost,
    Ncp,
    NcpConfig,
    NcpError,
    Opened,
    UncontrolledReceived,
)
from manip.spec.constants import ChaosOp
from manip.spec.notation import octal

from .base import Link, LinkStats
from .chaos_connection import ChaosConnection
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
    chaos_host,
)

log = logging.getLogger("manip.links")

Route = tuple[Link, int | None]
"""A link and the neighbour on it (the trailer destination; None: the link decides)."""
AcceptPolicy = Callable[[ConnectionRequested], str | None]
"""Return a CLS reason to refuse a request, or None to accept it."""
OnOpen = Callable[[ChaosConnection], None]

_FINAL: Final = frozenset({ConnState.CLOSED, ConnState.LOST, ConnState.INCOMPLETE})
_RFC: Final = int(ChaosOp.RFC)  # a plain int: enum attribute reads are slow on the per-packet path
NO_SERVER: Final = "No server for this contact name"
BUSY: Final = "Busy: the robot already has a client"


def _cls_text(reason: str) -> str:
    """A reason the core can put in a CLS: Latin-1, at most 488 bytes."""
    return reason.encode("latin-1", "replace")[:MAX_DATA].decode("latin-1")


@dataclass(slots=True)
class NodeStats:
    """Driver counters: packets moved, dropped for want of a route or from the wrong link."""

    packets_in: int = 0
    packets_out: int = 0
    links_attached: int = 0
    links_closed: int = 0
    no_route: int = 0
    wrong_link: int = 0
    refused_conflicts: int = 0
    core_errors: int = 0


@dataclass(slots=True)
class _Listener:
    contact: str
    on_open: OnOpen
    policy: AcceptPolicy | None
    max_connections: int | None
    busy_reason: str
    active: set[int] = field(default_factory=set)


class Node:
    """One Chaos host on one or more links.  Create it inside a running event loop.

    ``uniquizer`` seeds the high byte of connection indices and ``first_slot`` the low byte of the first
    one; by default both are random, so two clients that share a Chaos address (every client defaults
    to 0401) share an index only once in 65,280 (the server refuses the second, see above).
    """

    def __init__(
        self,
        address: int,
        options: NcpConfig | None = None,
        *,
        uniquizer: int | None = None,
        first_slot: int | None = None,
    ) -> None:
        self._loop = asyncio.get_running_loop()
        self.options = options or NcpConfig()
        # The driver acknowledges a packet only when the user has taken it with ``receive()``, so the
        # receive window is what makes a sender wait.
        self.ncp = Ncp(
            address,
            config=replace(self.options, auto_read=False),
            uniquizer=random.randrange(256) if uniquizer is None else uniquizer,
            first_slot=random.randrange(1, 256) if first_slot is None else first_slot,
        )
        self.address = address
        self.stats = NodeStats()
        self.links: list[Link] = []
        self._closed_link_stats = LinkStats()
        self._routes: dict[int, Route] = {}
        self._default: Route | None = None
        self._conns: dict[int, ChaosConnection] = {}
        self._by_conn: dict[int, Route] = {}
        self._peer_conn: dict[tuple[int, int], int] = {}
        self._listeners: dict[str, _Listener] = {}
        self._send_waiting: set[ChaosConnection] = set()
        self._watching: set[ChaosConnection] = set()  # connections with a poller's wake-up callback
        self._rx: tuple[Link, int, int] | None = None  # link, source host and neighbour of the input
        self._pumping = False
        self._windows_due = False
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at = 0.0
        self._min_interval = self.options.shortest_interval
        self._last_now = 0.0
        self._closed = False

    def __repr__(self) -> str:
        return f"<Node {octal(self.address)} links={len(self.links)} connections={len(self._conns)}>"

    # ---------------------------------------------------------------- links and routes

    def attach(self, link: Link, *, hosts: Iterable[int] = (), default: bool = False) -> None:
        """Use ``link``: its packets come to this node; ``hosts`` (and everything, if ``default``)
        are routed to it.  A point-to-point link whose peer address is known routes that address."""
        if self._closed:
            link.close()
            return
        self.links.append(link)
        self.stats.links_attached += 1
        link.set_receiver(self._on_packet)
        link.on_close(self._on_link_closed)
        for host in hosts:
            self._routes[host] = (link, host)
        if link.point_to_point and link.peer_addr is not None:
            self._routes.setdefault(link.peer_addr, (link, link.peer_addr))
        if default:
            self._default = (link, None)

    def add_route(self, host: int, link: Link, next_hop: int | None = None) -> None:
        """Send packets for ``host`` over ``link`` to neighbour ``next_hop`` (default: ``host`` itself)."""
        self._routes[host] = (link, host if next_hop is None else next_hop)

    # ---------------------------------------------------------------- connections

    async def connect(
        self, host: int, contact: str, args: bytes | str = b"", *, timeout: float | None = 10.0
    ) -> ChaosConnection:
        """Send an RFC for ``contact`` to ``host`` and wait for the OPN.

        Raises ConnectionRefused (CLS, with its reason), ConnectionLost (LOS), ConnectionAnswered,
        ConnectionForwarded, ConnectTimeout, or LinkError when no link leads to ``host``."""
        if self._closed:
            raise LinkError("the node is closed")
        route = self._routes.get(host) or self._default
        if route is None or route[0].is_closed:
            raise LinkError(f"no route to {chaos_host(host)}")
        raw_args = args.encode("latin-1") if isinstance(args, str) else bytes(args)
        try:
            conn_id = self.ncp.connect(self._now(), host, contact, raw_args)
        except NcpError as exc:  # every connection slot in use
            raise ChaosError(f"cannot open another connection: {exc}") from exc
        conn = ChaosConnection(
            self, conn_id, peer_host=host, peer_index=0, contact=contact, rfc_args=raw_args, client=True
        )
        self._conns[conn_id] = conn
        self._by_conn[conn_id] = route
        self._pump()
        try:
            async with asyncio.timeout(timeout):
                await conn._wait_opened()
        except TimeoutError:
            if conn._end is None:
                self._abandon(
                    conn,
                    ConnectTimeout(
                        f"no answer to the RFC for contact {contact!r} from {chaos_host(host)} "
                        f"within {timeout:.3g} s"
                    ),
                )
        except BaseException:
            self._abandon(conn, ConnectionClosed("connect cancelled", by_peer=False))
            raise
        if conn._end is not None:
            raise conn._fresh_end()
        return conn

    def listen(
        self,
        contact: str,
        on_open: OnOpen,
        *,
        policy: AcceptPolicy | None = None,
        max_connections: int | None = None,
        busy_reason: str = BUSY,
    ) -> None:
        """Accept RFCs for ``contact``; ``on_open(conn)`` runs once each connection is open.

        A request is refused (CLS) with ``busy_reason`` while ``max_connections`` of this listener's
        connections are live, or with the reason ``policy`` returns."""
        self.ncp.listen(contact)
        self._listeners[contact] = _Listener(contact, on_open, policy, max_connections, busy_reason)

    def unlisten(self, contact: str) -> None:
        self.ncp.unlisten(contact)
        self._listeners.pop(contact, None)

    def link_stats(self) -> LinkStats:
        """The counters of every link this node has had, summed (closed links included)."""
        total = LinkStats()
        total.add(self._closed_link_stats)
        for link in self.links:
            total.add(link.stats)
        return total

    @property
    def connections(self) -> list[ChaosConnection]:
        """The live connections (requested, opening or open)."""
        return list(self._conns.values())

    def link_of(self, conn: ChaosConnection) -> Link | None:
        """The link that carries ``conn`` (None once it has ended)."""
        route = self._by_conn.get(conn.conn_id)
        return None if route is None else route[0]

    def links_in_use(self) -> set[Link]:
        """The links that carry at least one live connection (a server's guard closes idle others)."""
        return {route[0] for route in self._by_conn.values()}

    # ---------------------------------------------------------------- shutting down

    def close(self, reason: str = "Node shutting down") -> None:
        """Abort every connection (CLS with ``reason``), stop the timer and close every link."""
        if self._closed:
            return
        for contact in list(self._listeners):
            self.unlisten(contact)
        for conn in list(self._conns.values()):
            if not self._closed:
                conn.abort(reason)  # its CLS goes out before the links close
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        for link in list(self.links):
            link.close()

    async def wait_closed(self) -> None:
        """Wait until every link has closed."""
        pending = [link.closed for link in self.links if not link.closed.done()]
        if pending:
            await asyncio.wait(pending)

    async def aclose(self, reason: str = "Node shutting down") -> None:
        self.close(reason)
        await self.wait_closed()

    @property
    def is_closed(self) -> bool:
        return self._closed

    # ---------------------------------------------------------------- the core's clock and output

    def _now(self) -> float:
        now = self._loop.time()
        if now < self._last_now:
            return self._last_now
        self._last_now = now
        return now

    def _pump(self, windows: bool = True, conn_id: int = 0) -> None:
        """Drain the core: route its packets, dispatch its events (which may call it again), re-arm.

        Then the watched connections' send windows are checked (:meth:`ChaosConnection.set_wakeup`),
        unless ``windows`` is False: a pump after our own send or read, which cannot open a window (only
        an acknowledgement from the peer, or a timer, can; the sender notes its own window itself).
        With ``conn_id`` only that connection's: a pump after a packet for it, which touches no other."""
        if self._pumping:
            self._windows_due = self._windows_due or windows
            return  # the outer pump drains whatever this call would have (and checks the windows)
        self._pumping = True
        ncp = self.ncp
        route = self._route
        try:
            while True:  # packets first: a connection's last packet leaves before its end forgets its route
                for packet in ncp.packets_to_send():
                    route(packet)
                event = ncp.next_event()
                if event is None:
                    break
                self._dispatch(event)
        finally:
            self._pumping = False
        if self._timer is None or self._timer_at > self._last_now + self._min_interval:
            self._arm_timer()  # (the test is _arm_timer's first one, inlined: it usually says "no")
        if self._send_waiting:
            self._wake_senders()
        watching = self._watching
        if not watching or not (windows or self._windows_due):
            return
        if conn_id and not self._windows_due:
            conn = self._conns.get(conn_id)
            if conn is not None and conn in watching:
                conn._check_window()
            return
        self._windows_due = False
        for conn in watching:
            conn._check_window()

    def _route(self, packet: Packet) -> None:
        rx = self._rx
        route: Route | None
        if rx is not None and packet.dest_host == rx[1]:
            route = (rx[0], rx[2])
        else:
            route = self._by_conn.get(packet.src_index) if packet.src_index else None
            if route is None:
                route = self._routes.get(packet.dest_host) or self._default
        if route is None or route[0].close_reason is not None:  # (no route, or its link is closed)
            self.stats.no_route += 1
            log.debug("node %s: no route for %r", octal(self.address), packet)
            return
        if route[0].send(packet, route[1]):
            self.stats.packets_out += 1

    def _arm_timer(self) -> None:
        handle = self._timer
        if handle is not None and self._timer_at <= self._last_now + self._min_interval:
            return  # armed no later than any deadline the core can have set since (module docstring)
        deadline = self.ncp.next_deadline()
        if deadline is None or not math.isfinite(deadline):
            if handle is not None:
                handle.cancel()
                self._timer = None
            return
        if handle is not None:
            if self._timer_at <= deadline:
                return  # fires no later than needed; it re-arms itself
            handle.cancel()
        self._timer_at = deadline
        self._timer = self._loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        if self._closed:
            return
        # asyncio may run a timer a clock tick early; the core must see its deadline reached.
        self._last_now = max(self._last_now, self._timer_at)
        try:
            self.ncp.timer(self._now())
            self._pump()
        except Exception:
            self.stats.core_errors += 1
            log.exception("node %s: timer processing failed", octal(self.address))

    def _wake_senders(self) -> None:
        ncp = self.ncp
        for conn in list(self._send_waiting):
            if conn._end is not None or ncp.can_send(conn.conn_id):
                self._send_waiting.discard(conn)
                conn._wake_senders()

    # ---------------------------------------------------------------- input

    def _on_packet(self, link: Link, packet: Packet) -> None:
        """A link's receiver: whatever the packet, this returns normally."""
        self.stats.packets_in += 1
        if self._closed:
            return
        index = packet.dest_index
        if index:
            bound = self._by_conn.get(index)
            if bound is not None and bound[0] is not link:
                self.stats.wrong_link += 1
                return
        if packet.opcode == _RFC and self._rfc_conflict(link, packet):
            return
        trailer = packet.trailer
        hop = trailer.source if trailer is not None and trailer.source else packet.src_host
        self._rx = (link, packet.src_host, hop)
        try:
            self.ncp.receive(self._now(), packet)
            self._pump(conn_id=index)
        except Exception:
            self.stats.core_errors += 1
            log.exception("node %s: processing %r failed", octal(self.address), packet)
        finally:
            self._rx = None

    def _rfc_conflict(self, link: Link, rfc: Packet) -> bool:
        """True (and the RFC refused) if its (host, index) belongs to a connection on another open link."""
        conn_id = self._peer_conn.get((rfc.src_host, rfc.src_index))
        bound = self._by_conn.get(conn_id) if conn_id is not None else None
        if bound is None or bound[0] is link or bound[0].is_closed:
            return False
        self.stats.refused_conflicts += 1
        reason = f"Chaos address {octal(rfc.src_host)} index {octal(rfc.src_index)} is in use on another link"
        refusal = Packet(
            opcode=ChaosOp.CLS,
            dest_host=rfc.src_host,
            dest_index=rfc.src_index,
            src_host=self.address,
            data=reason.encode("latin-1"),
        )
        if link.send(refusal):
            self.stats.packets_out += 1
        return True

    def _on_link_closed(self, link: Link) -> None:
        if link in self.links:
            self.links.remove(link)
            self.stats.links_closed += 1
            self._closed_link_stats.add(link.stats)
        for host, route in list(self._routes.items()):
            if route[0] is link:
                del self._routes[host]
        if self._default is not None and self._default[0] is link:
            self._default = None
        victims = [c for c in self._conns.values() if (r := self._by_conn.get(c.conn_id)) and r[0] is link]
        for conn in victims:
            self._abandon(conn, ConnectionBroken(f"link {link.name} closed: {link.close_reason}"))

    # ---------------------------------------------------------------- events

    def _dispatch(self, event: Event) -> None:
        if type(event) is DataReceived:  # the common case first
            conn = self._conns.get(event.conn_id)
            if conn is not None:
                conn._on_data(event.packet)
            return
        if isinstance(event, ConnectionRequested):
            self._on_request(event)
            return
        conn = self._conns.get(event.conn_id)
        if conn is None:
            return
        if isinstance(event, DataReceived):
            conn._on_data(event.packet)
        elif isinstance(event, Opened):
            self._peer_conn[(event.peer_host, event.peer_index)] = conn.conn_id
            conn._on_opened(event.peer_index)
            listener = conn._listener
            if listener is not None:
                try:
                    listener.on_open(conn)
                except Exception:
                    log.exception("node %s: on_open for %s failed", octal(self.address), listener.contact)
        elif isinstance(event, EofReceived):
            conn._on_eof(event.packet)
        elif isinstance(event, UncontrolledReceived):
            conn._on_uncontrolled(event.packet)
        else:
            self._finish(conn, self._end_error(conn, event))

    @staticmethod
    def _end_error(conn: ChaosConnection, event: Event) -> ChaosError:
        opening = conn.is_client and not conn.opened
        if isinstance(event, Closed):
            if opening and event.by_peer:
                return ConnectionRefused(event.reason)
            return ConnectionClosed(event.reason or "closed", by_peer=event.by_peer)
        if isinstance(event, Lost):
            return ConnectionLost(event.reason)
        if isinstance(event, Broken):
            return ConnectTimeout(event.reason) if opening else ConnectionBroken(event.reason)
        if isinstance(event, Answered):
            return ConnectionAnswered(event.data)
        if isinstance(event, Forwarded):
            return ConnectionForwarded(event.host, event.contact)
        return ChaosError(f"unexpected event {event!r}")  # pragma: no cover - every event is handled

    def _on_request(self, event: ConnectionRequested) -> None:
        now = self._now()
        listener = self._listeners.get(event.contact)
        reason: str | None = NO_SERVER if listener is None else None
        if listener is not None:
            if listener.max_connections is not None and len(listener.active) >= listener.max_connections:
                reason = listener.busy_reason
            elif listener.policy is not None:
                try:
                    reason = listener.policy(event)
                except Exception:
                    log.exception("node %s: accept policy failed", octal(self.address))
                    reason = "Server error"
        if reason is not None or listener is None:
            self.ncp.refuse(now, event.conn_id, _cls_text(reason or NO_SERVER))
            return
        conn = ChaosConnection(
            self,
            event.conn_id,
            peer_host=event.peer_host,
            peer_index=event.peer_index,
            contact=event.contact,
            rfc_args=event.args,
            rfc=event.rfc,
            listener=listener,
        )
        self._conns[event.conn_id] = conn
        if self._rx is not None:
            self._by_conn[event.conn_id] = (self._rx[0], self._rx[2])
        self._peer_conn[(event.peer_host, event.peer_index)] = event.conn_id
        listener.active.add(event.conn_id)
        self.ncp.accept(now, event.conn_id)

    # ---------------------------------------------------------------- for ChaosConnection

    def _finish(self, conn: ChaosConnection, error: ChaosError) -> None:
        """Forget ``conn`` and give it its final error (called once its packets have been routed)."""
        conn_id = conn.conn_id
        if self._conns.get(conn_id) is conn:
            del self._conns[conn_id]
        self._by_conn.pop(conn_id, None)
        key = conn.peer
        if self._peer_conn.get(key) == conn_id:
            del self._peer_conn[key]
        if conn._listener is not None:
            conn._listener.active.discard(conn_id)
        self._send_waiting.discard(conn)
        self._watching.discard(conn)
        conn._set_end(error)

    def _abandon(self, conn: ChaosConnection, error: ChaosError, cls_reason: str | None = None) -> None:
        """End ``conn`` from our side: abort it in the core (CLS with ``cls_reason``, default the
        error's reason, if it was open), then finish it."""
        if conn._end is not None:
            return
        try:
            if self.ncp.state(conn.conn_id) not in _FINAL:
                reason = error.reason if cls_reason is None else cls_reason
                self.ncp.abort(self._now(), conn.conn_id, _cls_text(reason))
        except (NcpError, ValueError):
            pass
        self._pump()
        self._finish(conn, error)

    def _core_finished(self, conn_id: int) -> bool:
        try:
            return self.ncp.state(conn_id) in _FINAL
        except NcpError:
            return True

    def _read(self, conn_id: int, packet_no: int) -> None:
        """Tell the core the user has read up to ``packet_no`` (this is what opens the peer's window)."""
        try:
            self.ncp.read_ack(self._now(), conn_id, packet_no)
        except NcpError:
            return  # the connection ended meanwhile: nothing left to acknowledge
        self._pump(windows=False)
