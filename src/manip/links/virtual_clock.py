"""An asyncio event loop on a virtual clock: deterministic simulation of a whole run in one process.

Theory of operation
===================

A conformance run against the embedded reference server has every party in one process: the suite,
both NCPs, the server's move process and the simulated Cougar.  They all read time from the event
loop (``loop.time()``, ``asyncio.sleep``, ``asyncio.timeout``), so the loop's clock *is* the world's
clock.  :class:`VirtualClockLoop` replaces the monotonic clock with a number that only moves when
nothing else can happen:

* Each turn of the loop polls the real selector without waiting.  Ready I/O is handled at once, at
  the current virtual time.
* When nothing is ready and the loop would sleep until its next timer, the clock jumps to that timer
  instead, and the loop carries on.  A five-second motion costs the servo ticks it computes, not five
  seconds.
* When nothing is ready and no timer is set, the loop waits on the real selector (only another thread
  or another process can wake it then).
* :meth:`VirtualClockLoop.frozen` stops the clock while code outside the loop works (a worker thread
  drawing Hypothesis examples, a thread-pool job): the loop then waits in real time, without jumping.

The jump is sound only when "nothing ready now" means "nothing will arrive before the next timer".
That holds for in-process peers over Unix-domain sockets (a write is in the reader's queue when
``send`` returns), which is why a simulated run uses ``unix://`` links, not TCP loopback, whose
delivery the kernel may defer.  Two runs with the same inputs and seeds then take the same path and
put the same bytes on the wire.  Nothing here is needed for real time: :func:`run` with
``virtual=False`` is :func:`asyncio.run`.
"""

from __future__ import annotations

import asyncio
import contextlib
import selectors
from collections.abc import Callable, Coroutine, Iterator, Mapping
from typing import Any, TypeVar

__all__ = ["VirtualClockLoop", "is_virtual", "loop_clock_ns", "run"]

T = TypeVar("T")

START: float = 1000.0
"""Where the virtual clock starts (any positive value: some code treats 0 as 'never')."""


class _JumpingSelector(selectors.BaseSelector):
    """The real selector, asked without waiting; an idle wait becomes a jump of the virtual clock."""

    def __init__(self, loop: VirtualClockLoop) -> None:
        self._inner = selectors.DefaultSelector()
        self._loop = loop

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self._inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self._inner.modify(fileobj, events, data)

    def get_map(self) -> Mapping[Any, selectors.SelectorKey]:
        return self._inner.get_map()

    def close(self) -> None:
        self._inner.close()

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = self._inner.select(0)
        if ready or timeout == 0:
            return ready
        loop = self._loop
        if timeout is None or loop.frozen_count:
            # Nothing to jump to, or the clock is held: only the outside world can move us on.
            return self._inner.select(None if timeout is None else min(timeout, 0.05))
        loop.advance(timeout)
        return []


class VirtualClockLoop(asyncio.SelectorEventLoop):
    """A selector event loop whose ``time()`` is virtual (see the module docstring)."""

    virtual = True

    def __init__(self, start: float = START) -> None:
        self._now = start
        self.frozen_count = 0
        self.jumps = 0
        """How many times the clock jumped (for benchmarks and tests)."""
        super().__init__(selector=_JumpingSelector(self))

    def time(self) -> float:
        return self._now

    def advance(self, seconds: float) -> None:
        """Move the clock forward (the selector does this when the loop is idle).

        The clock lands on whole nanoseconds (the float of the first one at or after the instant asked
        for, so whatever waits for that instant finds it has come): a capture's times are whole
        nanoseconds, so a replay of it reaches exactly the instants of the run, and what happens at one
        instant (a request and a servo tick) happens alike in both."""
        if seconds > 0:
            instant = self._now + seconds
            ns = round(instant * 1e9)
            if ns / 1e9 < instant:
                ns += 1
            self._now = ns / 1e9
            self.jumps += 1

    @contextlib.contextmanager
    def frozen(self) -> Iterator[None]:
        """Hold the clock for the block (nestable; safe to enter on the loop's thread only)."""
        self.frozen_count += 1
        try:
            yield
        finally:
            self.frozen_count -= 1

    def run_in_executor(  # type: ignore[override]  # same call, typed loosely
        self, executor: Any, func: Callable[..., T], *args: Any
    ) -> asyncio.Future[T]:
        """A thread-pool job holds the clock until it is done: virtual time must not run on while a
        real thread works (``asyncio.to_thread`` comes here too)."""
        self.frozen_count += 1
        future = super().run_in_executor(executor, func, *args)
        future.add_done_callback(self._thaw)
        return future

    def _thaw(self, _future: asyncio.Future[Any]) -> None:
        self.frozen_count -= 1


def is_virtual(loop: asyncio.AbstractEventLoop | None = None) -> bool:
    """True when ``loop`` (default: the running loop) runs on a virtual clock."""
    loop = loop or asyncio.get_running_loop()
    return bool(getattr(loop, "virtual", False))


def loop_clock_ns() -> int:
    """The running loop's clock in nanoseconds: log times of a simulated run's recording."""
    return round(asyncio.get_running_loop().time() * 1e9)


def run(main: Coroutine[Any, Any, T], *, virtual: bool = False) -> T:
    """:func:`asyncio.run`, on a :class:`VirtualClockLoop` when ``virtual``."""
    if not virtual:
        return asyncio.run(main)
    with asyncio.Runner(loop_factory=VirtualClockLoop) as runner:
        return runner.run(main)
