"""Two NCPs joined by two lossy channels, on a simulated clock.

A small discrete-event driver for tests and the conformance suite: it moves packets from each NCP into
the channel towards the other, delivers what arrives, fires timers, and jumps the clock straight to the
next thing that will happen (a channel delivery or an NCP deadline), so minutes of protocol time take
milliseconds.  Events are recorded per node in :attr:`Simulation.log` and, if a handler is given,
passed to it as they appear; the handler may call the NCPs (at ``sim.now``).
"""

from __future__ import annotations

from collections.abc import Callable

from .events import Event
from .lossy import LossyChannel
from .node import Ncp

Handler = Callable[["Simulation", Ncp, Event], None]

_STUCK_LIMIT = 100_000


class Simulation:
    """Drive ``a`` and ``b`` over channels ``a -> b`` and ``b -> a`` built with ``channel_options``.

    The two channels get the seeds ``2 * seed`` and ``2 * seed + 1``."""

    def __init__(
        self,
        a: Ncp,
        b: Ncp,
        *,
        seed: int = 0,
        start: float = 0.0,
        handler: Handler | None = None,
        keep_log: bool = True,
        drop: float = 0.2,
        duplicate: float = 0.05,
        reorder: float = 0.05,
        delay: tuple[float, float] = (0.001, 0.02),
        corrupt: float = 0.0,
    ) -> None:
        def channel(s: int) -> LossyChannel:
            return LossyChannel(
                s, drop=drop, duplicate=duplicate, reorder=reorder, delay=delay, corrupt=corrupt
            )

        self.a = a
        self.b = b
        self.a_to_b = channel(2 * seed)
        self.b_to_a = channel(2 * seed + 1)
        self.now = start
        self.handler = handler
        self.keep_log = keep_log
        self.log: dict[int, list[Event]] = {a.address: [], b.address: []}
        self._routes = ((a, self.a_to_b, b), (b, self.b_to_a, a))

    def flush(self) -> None:
        """Put every packet the NCPs produced on the channels and hand out every event they produced."""
        busy = True
        while busy:
            busy = False
            for src, channel, _dst in self._routes:
                for packet in src.packets_to_send():
                    channel.send(self.now, packet)
                    busy = True
                while (event := src.next_event()) is not None:
                    busy = True
                    if self.keep_log:
                        self.log[src.address].append(event)
                    if self.handler is not None:
                        self.handler(self, src, event)

    def next_time(self) -> float | None:
        """When something next happens: a delivery or an NCP deadline."""
        times = [
            t
            for t in (
                self.a.next_deadline(),
                self.b.next_deadline(),
                self.a_to_b.next_delivery_time(),
                self.b_to_a.next_delivery_time(),
            )
            if t is not None
        ]
        return min(times) if times else None

    def step(self, until: float) -> bool:
        """Advance to the next happening if it is due by ``until``; False if there is none that early."""
        self.flush()
        t = self.next_time()
        if t is None or t > until:
            return False
        self.now = max(self.now, t)
        for _src, channel, dst in self._routes:
            for packet in channel.deliver(self.now):
                dst.receive(self.now, packet)
        self.a.timer(self.now)
        self.b.timer(self.now)
        self.flush()
        return True

    def run(self, until: float, stop: Callable[[], bool] | None = None) -> bool:
        """Run until the clock reaches ``until`` or ``stop()`` becomes true (checked after each step).

        Returns True if ``stop`` ended the run.  The clock ends at ``until`` unless ``stop`` ended it."""
        self.flush()
        if stop is not None and stop():
            return True
        stuck = 0
        while True:
            before = self.now
            if not self.step(until):
                break
            if stop is not None and stop():
                return True
            stuck = stuck + 1 if self.now == before else 0
            if stuck > _STUCK_LIMIT:
                raise RuntimeError(f"simulation makes no progress at t={self.now}")
        self.now = max(self.now, until)
        return False

    def run_for(self, seconds: float, stop: Callable[[], bool] | None = None) -> bool:
        """``run`` for ``seconds`` from now."""
        return self.run(self.now + seconds, stop)
