"""The NCP's settings, defined once: :class:`NcpConfig`, used by the core (:class:`manip.ncp.Ncp`) and
by the asyncio driver (:class:`manip.links.Node`), with the checks of every value and
:meth:`NcpConfig.breaking_after`.

Times are in seconds, on whatever clock the caller passes the core as ``now``:

``window``               our receive window in packets (advertised in OPN and STS), 1..16384;
``retransmit_interval``  unreceipted controlled packets are sent again after this long;
``probe_interval``       SNS period while something is unacknowledged or the window is 0 (before the
                         first STS after our OPN, the probe period is ``retransmit_interval``); an idle
                         connection also probes once the peer has been silent for 2/3 of
                         ``broken_after``;
``broken_after``         no packet at all from the peer for this long: INCOMPLETE, event Broken (90 s
                         by default, the ITS NCP's interval; the 1985 guide sets no Chaos timer,
                         erratum ``ncp-timers``);
``rfc_timeout``          an RFC without reply: INCOMPLETE ("Host not responding"); a received RFC the
                         user leaves unanswered: refused with CLS "Timeout", event Closed;
``ack_delay``            how long news of received packets may wait for a packet to ride on before an
                         STS carries it;
``first_packet_no``      default number of the first packet (RFC or OPN) of each connection;
``auto_read``            True: a packet counts as read (and is acknowledged) when it is delivered;
                         False: only when the user reads it (the asyncio driver's choice, so that the
                         receive window is what makes a sender wait).
``lose_on_illegal``      True: a connection whose peer sends it an illegal packet (an illegal opcode,
                         more than 488 data bytes), answered with LOS, is given up at once: LOST, event
                         Lost (the peer takes our LOS as the end of the connection, so nothing more
                         will come).  False (the default, the server's): only the LOS is sent.
                         Erratum ``illegal-packet-gives-up``.
``defects``              how this host departs from the Chaosnet rules
                         (:class:`~manip.ncp.defects.ChaosDefects`: none by default; the reference
                         server's Chaos-level fault switches set them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final

from .defects import ChaosDefects

__all__ = ["MAX_WINDOW", "NcpConfig"]

MAX_WINDOW: Final = 0x4000
"""Largest window we advertise or accept (well inside the half of the sequence space that compares)."""


@dataclass(frozen=True, slots=True)
class NcpConfig:
    """An NCP's settings (see the module docstring); invalid values raise ValueError when made."""

    window: int = 15
    retransmit_interval: float = 0.5
    probe_interval: float = 5.0
    broken_after: float = 90.0
    rfc_timeout: float = 30.0
    ack_delay: float = 0.1
    first_packet_no: int = 1
    auto_read: bool = True
    lose_on_illegal: bool = False
    defects: ChaosDefects = field(default_factory=ChaosDefects)

    def __post_init__(self) -> None:
        if not 1 <= self.window <= MAX_WINDOW:
            raise ValueError(f"window must be in 1..16384, not {self.window!r}")
        if not 0 <= self.first_packet_no <= 0xFFFF:
            raise ValueError(f"first_packet_no must be in 0..0xFFFF, not {self.first_packet_no!r}")
        for name in ("retransmit_interval", "probe_interval", "broken_after", "rfc_timeout"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a positive number of seconds, not {value!r}")
        if not (self.ack_delay >= 0 and math.isfinite(self.ack_delay)):
            raise ValueError(f"ack_delay must be >= 0, not {self.ack_delay!r}")

    @classmethod
    def breaking_after(cls, seconds: float) -> NcpConfig:
        """The defaults, but a connection whose peer is silent for ``seconds`` is broken.  The probe
        interval shrinks with it (a third of it, at most the usual 5 s): a quiet but healthy peer must
        be asked for news, and answer, well before its connection would be given up."""
        if not (seconds > 0 and math.isfinite(seconds)):
            raise ValueError(f"broken_after must be a positive number of seconds, not {seconds!r}")
        return cls(broken_after=seconds, probe_interval=min(cls().probe_interval, seconds / 3))

    @property
    def retransmit_guard(self) -> float:
        """After an STS, packets sent less than this long ago are not sent again yet."""
        return self.retransmit_interval / 5

    @property
    def idle_probe_after(self) -> float:
        """An idle connection probes (SNS) once the peer has been silent this long."""
        return self.broken_after * 2 / 3

    @property
    def shortest_interval(self) -> float:
        """The shortest of the timers (a driver's timer need not be finer)."""
        return min(
            self.ack_delay, self.retransmit_interval, self.probe_interval, self.broken_after, self.rfc_timeout
        )
