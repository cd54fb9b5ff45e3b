"""Bounds and access rules for a server's links: nothing held without a bound, no one in who should not be.

The 1985 protocol authenticates no one and encrypts nothing: whoever reaches the server's port may open
a connection and move the arm, and a Chaos address is whatever the peer writes in its packets.  What a
server can do is choose whom it listens to, and never let a peer hold a resource without a bound.
:class:`LinkGuard` does both for one server:

* **Access** (:class:`AccessList`): rules name IP addresses or networks (checked on each TCP peer when
  it is accepted and on each CHUDP datagram) and Chaos addresses or ranges (checked on each RFC).  A
  kind of rule that is not given restricts nothing; a kind that is given admits only what it names.  A
  TCP peer outside is closed at once, a datagram dropped, an RFC answered with CLS.
* **Frames** (``frame_timeout``): a TCP link must deliver its first frame within that many seconds of
  opening, and every frame within that many seconds of its first byte, or it is closed.  A peer that
  sends nothing, or half a frame, holds a descriptor for no longer than this.
* **Use** (``idle_timeout``): a TCP link that carries no Chaos connection that long (since it opened
  or its last connection ended) is closed; a connection's own silence is the NCP's business
  (``broken_after``).
* **Count** (``max_links``): at most that many TCP links at once.  A new one beyond it displaces the
  oldest link that carries no Chaos connection (so idle sockets cannot lock a real client out); only
  when every link carries a connection is the new one closed at once.  When accepting fails for want
  of descriptors (EMFILE, ENFILE), accepting pauses for ``accept_backoff`` seconds and the link count at
  that moment, less a headroom, becomes the limit from then on.

Everything a peer can cause is counted (:class:`GuardStats`) and logged through a rate limit
(:class:`RateLimitedLog`): at most a few lines per kind of event per interval, then one line with the
count of the rest.  None of it is a traceback.
"""

from __future__ import annotations

import asyncio
import errno
import functools
import ipaddress
import logging
import math
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Final, cast

from manip.spec.notation import octal

from .base import Link

if TYPE_CHECKING:
    from manip.ncp import ConnectionRequested

    from .stream import StreamLink

log = logging.getLogger("manip.links")

IpNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network
Endpoint = tuple[str, int]

DEFAULT_FRAME_TIMEOUT: Final = 10.0
DEFAULT_IDLE_TIMEOUT: Final = 30.0
DEFAULT_MAX_LINKS: Final = 256
DEFAULT_ACCEPT_BACKOFF: Final = 1.0
LOG_INTERVAL: Final = 10.0
"""Seconds over which the log lines of one kind of event are rate limited."""
LOG_BURST: Final = 3
"""Lines of one kind logged one by one per interval; the rest are counted in one line at its end."""
FD_HEADROOM: Final = 16
"""Descriptors kept free below the link count at which accepting first ran out of them (for the
listening sockets, a recording, the Cougar link and the next accepts, which displace idle links)."""
CHAOS_PREFIX: Final = "chaos:"

_OUT_OF_DESCRIPTORS: Final = frozenset({errno.EMFILE, errno.ENFILE})
_OUT_OF_RESOURCES: Final = _OUT_OF_DESCRIPTORS | {errno.ENOBUFS, errno.ENOMEM}


class AccessError(ValueError):
    """An access rule that cannot be used; the message says what is wrong and what is accepted."""


def _chaos_number(text: str, rule: str) -> int:
    try:
        value = int(text, 8)
    except ValueError:
        raise AccessError(f"{rule!r}: {text!r} is not an octal Chaos address (e.g. chaos:0401)") from None
    if not 0 <= value <= 0xFFFF:
        raise AccessError(f"{rule!r}: {text} is outside the 16-bit Chaos address space (0-0177777)")
    return value


def chaos_text(address: int) -> str:
    """A Chaos address as the project writes it: octal with a leading zero (0402)."""
    return octal(address)


@dataclass(frozen=True)
class AccessList:
    """Who may use a server: IP networks for link peers, Chaos address ranges for connections.

    An empty kind restricts nothing (``restricts_ip``, ``restricts_chaos`` say which are in force)."""

    networks: tuple[IpNetwork, ...] = ()
    chaos_ranges: tuple[tuple[int, int], ...] = ()

    @classmethod
    def parse(cls, rules: Iterable[str]) -> AccessList:
        """Rules as ``--allow`` takes them: ``127.0.0.1``, ``10.0.0.0/8``, ``::1``, ``chaos:0401``,
        ``chaos:0400-0477`` (octal).  Raises :class:`AccessError` naming the rule that is wrong."""
        networks: list[IpNetwork] = []
        chaos: list[tuple[int, int]] = []
        for raw in rules:
            rule = raw.strip()
            if rule.lower().startswith(CHAOS_PREFIX):
                body = rule[len(CHAOS_PREFIX) :]
                low_text, dash, high_text = body.partition("-")
                low = _chaos_number(low_text, rule)
                high = _chaos_number(high_text, rule) if dash else low
                if high < low:
                    raise AccessError(f"{rule!r}: the range ends before it starts")
                chaos.append((low, high))
                continue
            try:
                networks.append(ipaddress.ip_network(rule.replace("[", "").replace("]", ""), strict=True))
            except ValueError as exc:
                raise AccessError(
                    f"{rule!r} is neither an IP address or network ({exc}) nor chaos:OCTAL[-OCTAL]; "
                    "host names are not accepted"
                ) from None
        return cls(tuple(networks), tuple(chaos))

    @property
    def restricts_ip(self) -> bool:
        return bool(self.networks)

    @property
    def restricts_chaos(self) -> bool:
        return bool(self.chaos_ranges)

    def allows_ip(self, host: str) -> bool:
        """True if ``host`` (a numeric address as sockets report it) may be a link peer."""
        return not self.networks or _ip_allowed(self.networks, host)

    def allows_chaos(self, address: int) -> bool:
        """True if Chaos host ``address`` may open a connection."""
        return not self.chaos_ranges or any(low <= address <= high for low, high in self.chaos_ranges)

    def __str__(self) -> str:
        parts = [str(net) for net in self.networks]
        parts += [
            CHAOS_PREFIX + (chaos_text(lo) if lo == hi else f"{chaos_text(lo)}-{chaos_text(hi)}")
            for lo, hi in self.chaos_ranges
        ]
        return ", ".join(parts) or "everyone"


@functools.lru_cache(maxsize=4096)  # bounded: UDP sources can be forged in any number
def _ip_allowed(networks: tuple[IpNetwork, ...], host: str) -> bool:
    try:
        ip = ipaddress.ip_address(host.partition("%")[0])
    except ValueError:
        return False
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped  # an IPv4 peer on a dual-stack socket
    return any(ip in net for net in networks)


def _check_seconds(name: str, value: float | None) -> None:
    if value is not None and not (value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive number of seconds or None, not {value!r}")


@dataclass(frozen=True, slots=True)
class LinkLimits:
    """The bounds a server puts on its TCP links (module docstring); None switches one off."""

    frame_timeout: float | None = DEFAULT_FRAME_TIMEOUT
    idle_timeout: float | None = DEFAULT_IDLE_TIMEOUT
    max_links: int | None = DEFAULT_MAX_LINKS
    accept_backoff: float = DEFAULT_ACCEPT_BACKOFF
    log_interval: float = LOG_INTERVAL

    def __post_init__(self) -> None:
        _check_seconds("frame_timeout", self.frame_timeout)
        _check_seconds("idle_timeout", self.idle_timeout)
        _check_seconds("accept_backoff", self.accept_backoff)
        _check_seconds("log_interval", self.log_interval)
        if self.max_links is not None and self.max_links < 1:
            raise ValueError(f"max_links must be at least 1 or None, not {self.max_links!r}")

    @classmethod
    def unlimited(cls) -> LinkLimits:
        """No timeouts and no link limit (accept errors still pause and are rate limited)."""
        return cls(frame_timeout=None, idle_timeout=None, max_links=None)


@dataclass(slots=True)
class GuardStats:
    """What a guard refused and closed.  ``refused`` counts by reason: ``address`` (a TCP peer outside
    the IP rules), ``datagram`` (a CHUDP datagram from outside them), ``chaos-host`` (an RFC from a Chaos
    address outside the Chaos rules).  ``idle_closed`` counts by what was missing: ``no frame`` (none
    within the frame timeout of opening), ``partial frame`` (one begun and not finished in time), ``no
    connection``.  ``over_limit`` counts ``displaced`` links and ``refused`` new ones."""

    accepted: int = 0
    refused: Counter[str] = field(default_factory=Counter)
    idle_closed: Counter[str] = field(default_factory=Counter)
    over_limit: Counter[str] = field(default_factory=Counter)
    accept_errors: int = 0

    def add(self, other: GuardStats) -> None:
        self.accepted += other.accepted
        self.refused.update(other.refused)
        self.idle_closed.update(other.idle_closed)
        self.over_limit.update(other.over_limit)
        self.accept_errors += other.accept_errors


class RateLimitedLog:
    """Log lines of one kind (``what``) at most ``burst`` times per ``interval`` seconds; the rest are
    counted and reported in one line when the interval ends, and while they keep coming that line is
    all there is (one per interval).  Create it inside a running loop."""

    def __init__(
        self, logger: logging.Logger, interval: float = LOG_INTERVAL, burst: int = LOG_BURST
    ) -> None:
        self._logger = logger
        self.interval = interval
        self.burst = burst
        self._loop = asyncio.get_running_loop()
        self._windows: dict[str, _Window] = {}

    def log(self, what: str, level: int, msg: str, *args: object, burst: int | None = None) -> None:
        """Log ``msg % args`` unless ``burst`` (default: the limiter's) lines about ``what`` were
        logged in this interval."""
        now = self._loop.time()
        window = self._windows.get(what)
        if window is None or (now - window.start >= self.interval and window.timer is None):
            window = self._windows[what] = _Window(now, level)
        if window.logged < (self.burst if burst is None else burst):
            window.logged += 1
            self._logger.log(level, msg, *args)
            return
        window.held += 1
        if window.timer is None:
            window.timer = self._loop.call_at(window.start + self.interval, self._flush, what, True)

    def _flush(self, what: str, go_on: bool = False) -> None:
        window = self._windows.pop(what, None)
        if window is None:
            return
        window.timer = None
        if window.held:
            self._logger.log(
                window.level,
                "%d more %s in the last %g s (not logged one by one)",
                window.held,
                what,
                self.interval,
            )
            if go_on:  # more may follow: they wait for the next such line
                self._windows[what] = _Window(self._loop.time(), window.level, logged=1 << 30)

    def close(self) -> None:
        """Report what is held back now and stop the timers."""
        for what, window in list(self._windows.items()):
            if window.timer is not None:
                window.timer.cancel()
            self._flush(what)


@dataclass(slots=True)
class _Window:
    start: float
    level: int
    logged: int = 0
    held: int = 0
    timer: asyncio.TimerHandle | None = None


@dataclass(slots=True)
class _Tracked:
    seen_as: Link
    """The link as the node knows it (a wrapper, when the server wraps its links)."""
    last_used: float
    """Loop time the link was last seen carrying a connection, or first seen without one after that
    (at first: when it opened); an idle link is never closed before its time."""
    busy: bool = False


InUse = Callable[[], "set[Link]"]
"""The links (as the node knows them) that carry at least one live Chaos connection."""


class LinkGuard:
    """Applies one server's :class:`LinkLimits` and :class:`AccessList` (module docstring).

    The listener asks :meth:`admit` for every accepted socket and :meth:`accept_failed` for every
    failed accept; the server gives it each new link (:meth:`track`), every CHUDP sender
    (:meth:`admit_datagram`) and every RFC (:meth:`admit_rfc`).  ``in_use`` tells it which links carry
    a Chaos connection.  Create it inside a running loop."""

    def __init__(
        self,
        limits: LinkLimits | None = None,
        access: AccessList | None = None,
        *,
        in_use: InUse | None = None,
        name: str = "server",
    ) -> None:
        self.limits = limits or LinkLimits()
        self.access = access or AccessList()
        self.name = name
        self.stats = GuardStats()
        self.log = RateLimitedLog(log, self.limits.log_interval)
        self.ceiling: int | None = None
        """The link limit learnt from running out of descriptors (see the module docstring)."""
        self._in_use = in_use or set
        self._loop = asyncio.get_running_loop()
        self._links: dict[StreamLink, _Tracked] = {}  # oldest first
        self._closing: set[StreamLink] = set()  # displaced, and their descriptors not yet freed
        self._sweeper: asyncio.TimerHandle | None = None
        self._closed = False
        timeouts = [t for t in (self.limits.frame_timeout, self.limits.idle_timeout) if t is not None]
        self._sweep_every = min(1.0, max(0.02, min(timeouts) / 4)) if timeouts else None

    def __repr__(self) -> str:
        return f"<LinkGuard {self.name} links={len(self._links)} {self.access}>"

    @property
    def links(self) -> int:
        """TCP links open now."""
        return len(self._links)

    @property
    def closing(self) -> int:
        """Links displaced to make room whose descriptors are not free yet (they are at the next turn
        of the loop: a listener stops accepting until then, or the descriptors could run out)."""
        return len(self._closing)

    @property
    def max_links(self) -> int | None:
        """The link limit in force: ``limits.max_links``, or lower once descriptors ran out."""
        limit = self.limits.max_links
        if self.ceiling is not None:
            return self.ceiling if limit is None else min(limit, self.ceiling)
        return limit

    # ---------------------------------------------------------------- the listener's side

    def admit(self, peer: Endpoint | None, opening: int = 0) -> bool:
        """May the link just accepted from ``peer`` stay?  ``opening`` links were admitted and are not
        yet tracked.  False: close its socket at once (counted and logged here).  A peer of None (a
        unix socket's, which the file's permissions guard) is not checked against the IP rules."""
        host, port = peer or ("", 0)
        where = f"[{host}]:{port}" if ":" in host else f"{host}:{port}" if peer else "a unix socket peer"
        if peer is not None and not self.access.allows_ip(host):
            self.stats.refused["address"] += 1
            self.log.log(
                "TCP peers refused by address",
                logging.WARNING,
                "%s: refused TCP peer %s: not in the allowed addresses (%s)",
                self.name,
                where,
                self.access,
            )
            return False
        limit = self.max_links
        if limit is not None and len(self._links) + opening >= limit and not self._displace(limit - opening):
            self.stats.over_limit["refused"] += 1
            self.log.log(
                "TCP peers refused over the link limit",
                logging.WARNING,
                "%s: refused TCP peer %s: %d links open, each carrying a Chaos connection (limit %d)",
                self.name,
                where,
                len(self._links),
                limit,
            )
            return False
        self.stats.accepted += 1
        return True

    def accept_failed(self, exc: OSError, opening: int = 0) -> float:
        """Count a failed accept and return how long to pause accepting (0: go on at once).  Out of
        descriptors, the links open now (``opening`` of them admitted and not yet tracked) less a
        headroom become the limit, and idle links beyond it are closed to make room."""
        self.stats.accept_errors += 1
        pause = self.limits.accept_backoff if exc.errno in _OUT_OF_RESOURCES else 0.0
        held = len(self._links) + opening
        if exc.errno in _OUT_OF_DESCRIPTORS and held > FD_HEADROOM:
            ceiling = held - FD_HEADROOM
            if self.ceiling is None or ceiling < self.ceiling:
                self.ceiling = ceiling
                self.log.log(
                    "lowerings of the link limit",
                    logging.WARNING,
                    "%s: out of file descriptors with %d links open: at most %d from now on "
                    "(raise the descriptor limit, or lower max_links, manip-server --max-links)",
                    self.name,
                    held,
                    ceiling,
                    burst=1,
                )
            self._displace(self.ceiling - opening)
        self.log.log(
            "accept failures",
            logging.WARNING,
            "%s: accepting a TCP connection failed: %s%s",
            self.name,
            exc.strerror or exc,
            f"; accepting again in {pause:g} s" if pause else "",
            burst=1,
        )
        return pause

    def track(self, link: StreamLink, seen_as: Link | None = None) -> None:
        """Watch a new TCP link; ``seen_as`` is the link the node was given (default: ``link``)."""
        if self._closed:
            return
        self._links[link] = _Tracked(seen_as or link, self._loop.time())
        link.on_close(self._forget)
        if self._sweeper is None and self._sweep_every is not None:
            self._sweeper = self._loop.call_later(self._sweep_every, self._sweep)

    # ---------------------------------------------------------------- the server's side

    def admit_datagram(self, sender: Endpoint) -> bool:
        """May a CHUDP datagram from ``sender`` be read?  False: drop it (counted and logged here)."""
        if self.access.allows_ip(sender[0]):
            return True
        self.stats.refused["datagram"] += 1
        self.log.log(
            "CHUDP datagrams dropped by address",
            logging.WARNING,
            "%s: dropped a CHUDP datagram from %s:%d: not in the allowed addresses (%s)",
            self.name,
            sender[0],
            sender[1],
            self.access,
        )
        return False

    def admit_rfc(self, request: ConnectionRequested) -> str | None:
        """The CLS reason refusing ``request`` if its Chaos host is not allowed, else None."""
        host = request.peer_host
        if self.access.allows_chaos(host):
            return None
        self.stats.refused["chaos-host"] += 1
        reason = f"Access refused: Chaos host {chaos_text(host)} not allowed"
        self.log.log(
            "RFCs refused by Chaos address",
            logging.WARNING,
            "%s: refused RFC for %s from %s/%s: %s",
            self.name,
            request.contact,
            chaos_text(host),
            octal(request.peer_index),
            reason,
        )
        return reason

    def close(self) -> None:
        """Stop watching (the links themselves are closed by their node)."""
        self._closed = True
        if self._sweeper is not None:
            self._sweeper.cancel()
            self._sweeper = None
        self.log.close()

    # ---------------------------------------------------------------- internals

    def _forget(self, link: Link) -> None:
        stream = cast("StreamLink", link)  # only stream links are tracked
        self._links.pop(stream, None)
        self._closing.discard(stream)

    def _displace(self, limit: int) -> bool:
        """Close the oldest links that carry no Chaos connection until fewer than ``limit`` remain;
        False if not even one could be closed to make room."""
        excess = len(self._links) - limit + 1
        if excess <= 0:
            return True
        in_use = self._in_use()
        victims = [link for link, t in self._links.items() if t.seen_as not in in_use][:excess]
        for link in victims:
            del self._links[link]
            self._closing.add(link)
            self.stats.over_limit["displaced"] += 1
            self.log.log(
                "idle TCP links displaced over the link limit",
                logging.INFO,
                "%s: closed to make room: no Chaos connection, and the link limit was reached",
                link.name,
            )
            link.abort("displaced by a new link: the link limit was reached and this one had no connection")
        return bool(victims)

    def _sweep(self) -> None:
        """Close the links past a timeout; re-arm while there are links to watch."""
        self._sweeper = None
        if self._closed:
            return
        now = self._loop.time()
        frame_timeout, idle_timeout = self.limits.frame_timeout, self.limits.idle_timeout
        in_use = self._in_use() if idle_timeout is not None else set()
        for link, tracked in list(self._links.items()):
            if link.is_closed:
                continue
            since = link.waiting_since
            if frame_timeout is not None and since is not None and now - since >= frame_timeout:
                never = link.stats.frames_in == 0 and not link.stats.bad
                what = "no frame" if never else "partial frame"
                detail = "of opening" if never else "of its first byte"
                self._idle(link, what, f"no complete frame within {frame_timeout:g} s {detail}")
            elif idle_timeout is not None:
                if tracked.seen_as in in_use or tracked.busy:
                    tracked.last_used = now
                    tracked.busy = tracked.seen_as in in_use
                elif now - tracked.last_used >= idle_timeout:
                    self._idle(link, "no connection", f"no Chaos connection for {idle_timeout:g} s")
        if self._links and self._sweep_every is not None:
            self._sweeper = self._loop.call_later(self._sweep_every, self._sweep)

    def _idle(self, link: StreamLink, what: str, reason: str) -> None:
        self._links.pop(link, None)
        self.stats.idle_closed[what] += 1
        self.log.log("idle TCP links closed", logging.INFO, "%s: closed: %s", link.name, reason)
        link.abort(reason)
