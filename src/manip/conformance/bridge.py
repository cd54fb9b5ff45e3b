"""Running Hypothesis, which is synchronous, against the asynchronous probe of a running case.

How the two meet
================

A case runs on the runner's event loop; Hypothesis calls test functions synchronously and must not
block that loop.  So the property and stateful cases run the whole Hypothesis test in a worker thread
(:func:`run_in_worker`, ``asyncio.to_thread``) and every network step of an example is a coroutine
submitted back to the loop with ``asyncio.run_coroutine_threadsafe`` (:meth:`Bridge.call`), whose
result the worker thread waits for.  The loop stays free to run the probe's connection, the timers,
and (for the embedded server) the server itself.

Determinism: :func:`hypothesis_settings` turns off the example database and derandomisation and the
cases apply ``hypothesis.seed(ctx.seed)``, so the same run seed gives the same examples as long as the
target answers the same way.

Hypothesis seeds the global ``random`` module for every example, and a new Chaos connection draws its
index from it: every example would open its connection with the same index, which the target may
still hold for the previous one.  :func:`connect_fresh` opens connections with the global state
reseeded from the system and restores it afterwards, so the examples stay deterministic.

Budgets and cancellation: a case's deadline cancels the ``await`` of the worker; :class:`Bridge` then
refuses the next step with :class:`StopRun` (a ``BaseException``, which Hypothesis does not take for a
test failure), so the thread ends at its next step instead of talking to a closed probe.  Shrinking a
failure against a live target can take long; :class:`FailureLog` remembers the smallest failing
example seen, and once a failure is found the bridge allows only ``shrink_budget`` more seconds before
stopping, so the case reports the best counterexample found by then.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import random
import threading
import time
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from hypothesis import HealthCheck, Phase, settings

from manip.conformance.context import CaseContext, Probe

__all__ = [
    "DEFAULT_SHRINK_BUDGET",
    "Bridge",
    "FailureLog",
    "StopRun",
    "connect_fresh",
    "hypothesis_settings",
    "run_in_worker",
]

T = TypeVar("T")
F = TypeVar("F")

DEFAULT_SHRINK_BUDGET = 10.0
"""Seconds of shrinking allowed after the first failure (then the smallest failure so far is kept)."""
STEP_TIMEOUT = 60.0
"""Longest wait for one submitted coroutine (the probe has its own, shorter, reply timeouts)."""


class StopRun(BaseException):
    """The case was cancelled or its budget ran out: end the Hypothesis run at once."""


@dataclass
class FailureLog(Generic[F]):
    """The smallest failure seen so far (by ``size``), kept in case shrinking is cut short."""

    best: F | None = None
    size: int = 0
    count: int = 0

    def add(self, failure: F, size: int) -> None:
        self.count += 1
        if self.best is None or size < self.size:
            self.best, self.size = failure, size


@dataclass
class Bridge:
    """Submits coroutines from the Hypothesis worker thread to the case's event loop."""

    loop: asyncio.AbstractEventLoop
    budget: float | None = None
    """Seconds the whole Hypothesis run may take (None: no limit besides the case deadline)."""
    shrink_budget: float = DEFAULT_SHRINK_BUDGET
    _stop: threading.Event = field(default_factory=threading.Event)
    _deadline: float | None = None
    _started: float = field(default_factory=time.monotonic)
    stopped_by_budget: bool = False

    def __post_init__(self) -> None:
        if self.budget is not None:
            self._deadline = self._started + self.budget

    def stop(self) -> None:
        self._stop.set()

    def failure_seen(self) -> None:
        """A failing example was found: from now on only ``shrink_budget`` seconds remain."""
        limit = time.monotonic() + self.shrink_budget
        self._deadline = limit if self._deadline is None else min(self._deadline, limit)

    def check(self) -> None:
        """Raise :class:`StopRun` when the run must end (cancelled, or out of budget)."""
        if self._stop.is_set():
            raise StopRun("cancelled")
        if self._deadline is not None and time.monotonic() > self._deadline:
            self.stopped_by_budget = True
            raise StopRun("budget")

    def call(self, coro: Coroutine[Any, Any, T], timeout: float = STEP_TIMEOUT) -> T:
        """Run ``coro`` on the loop and wait for its result (from the worker thread only)."""
        try:
            self.check()
        except StopRun:
            coro.close()
            raise
        future = asyncio.run_coroutine_threadsafe(coro, self.loop)
        try:
            return future.result(timeout)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise TimeoutError(f"a step of the Hypothesis run took more than {timeout:g} s") from None
        except concurrent.futures.CancelledError:
            raise StopRun("the loop cancelled the step") from None


async def run_in_worker(
    fn: Callable[[Bridge], T], *, budget: float | None = None, shrink_budget: float | None = None
) -> T:
    """Run ``fn(bridge)`` in a worker thread; cancelling this coroutine stops the worker's next step.

    ``shrink_budget`` defaults to the module's :data:`DEFAULT_SHRINK_BUDGET` as it is at the call (a test
    suite that only needs to know *that* a case fails may lower it)."""
    limit = DEFAULT_SHRINK_BUDGET if shrink_budget is None else shrink_budget
    bridge = Bridge(asyncio.get_running_loop(), budget=budget, shrink_budget=limit)
    try:
        return await asyncio.to_thread(fn, bridge)
    except asyncio.CancelledError:
        bridge.stop()
        raise


async def connect_fresh(ctx: CaseContext) -> Probe:
    """``ctx.connect()`` with the global ``random`` state reseeded for the connection index (see the
    module docstring) and restored afterwards."""
    state = random.getstate()
    random.seed()
    try:
        return await ctx.connect()
    finally:
        random.setstate(state)


def hypothesis_settings(max_examples: int, **overrides: Any) -> settings:
    """Settings for a live target: no deadline per example (network jitter), no example database
    (replaying last week's failures against today's target confuses), every health check off (a live
    target is slow by nature), one bug per run, no ``@reproduce_failure`` blob (the seed reproduces)."""
    chosen: dict[str, Any] = {
        "max_examples": max(1, max_examples),
        "deadline": None,
        "database": None,
        "derandomize": False,
        "suppress_health_check": list(HealthCheck),
        "report_multiple_bugs": False,
        "print_blob": False,
        "phases": (Phase.explicit, Phase.generate, Phase.shrink),
    }
    chosen.update(overrides)
    return settings(**chosen)
