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

On a virtual clock (:mod:`manip.links.virtual_clock`, the embedded server's simulated time) the two
threads take turns instead (*lockstep*): while the worker thinks, the loop thread waits for its next
step and nothing in the simulated world moves, not even at the same instant; while a step runs, the
worker waits.  So where an example's requests fall against the server's servo ticks depends on the
seed only, never on how fast the worker thread happened to be.

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
import queue
import random
import threading
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

from hypothesis import HealthCheck, Phase, settings

from manip.conformance.suite.context import CaseContext, Probe
from manip.links.virtual_clock import is_virtual

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
    """Seconds the whole Hypothesis run may take, on the loop's clock (None: no limit besides the case
    deadline)."""
    shrink_budget: float = DEFAULT_SHRINK_BUDGET
    _stop: threading.Event = field(default_factory=threading.Event)
    _deadline: float | None = None
    stopped_by_budget: bool = False
    steps: queue.SimpleQueue[_Step[Any]] | None = None
    """Lockstep (virtual clock): the worker hands each step to the loop thread here."""

    def __post_init__(self) -> None:
        if self.budget is not None:
            self._deadline = self.loop.time() + self.budget

    def stop(self) -> None:
        self._stop.set()

    def failure_seen(self) -> None:
        """A failing example was found: from now on only ``shrink_budget`` seconds remain."""
        limit = self.loop.time() + self.shrink_budget
        self._deadline = limit if self._deadline is None else min(self._deadline, limit)

    def check(self) -> None:
        """Raise :class:`StopRun` when the run must end (cancelled, or out of budget)."""
        if self._stop.is_set():
            raise StopRun("cancelled")
        if self._deadline is not None and self.loop.time() > self._deadline:
            self.stopped_by_budget = True
            raise StopRun("budget")

    def call(self, coro: Coroutine[Any, Any, T], timeout: float = STEP_TIMEOUT) -> T:
        """Run ``coro`` on the loop and wait for its result (from the worker thread only)."""
        try:
            self.check()
        except StopRun:
            coro.close()
            raise
        if self.steps is not None:
            step = _Step(coro)
            self.steps.put(step)
            return step.result(timeout)
        future = asyncio.run_coroutine_threadsafe(coro, self.loop)
        try:
            return future.result(timeout)
        except concurrent.futures.TimeoutError:
            future.cancel()
            raise TimeoutError(f"a step of the Hypothesis run took more than {timeout:g} s") from None
        except concurrent.futures.CancelledError:
            raise StopRun("the loop cancelled the step") from None


class _Step(Generic[T]):
    """One coroutine handed from the worker to the loop thread in lockstep, and its outcome."""

    def __init__(self, coro: Coroutine[Any, Any, T] | None) -> None:
        self.coro = coro
        """None marks the worker's end."""
        self._done = threading.Event()
        self._value: T | None = None
        self._error: BaseException | None = None

    def settle(self, value: T | None = None, error: BaseException | None = None) -> None:
        self._value, self._error = value, error
        self._done.set()

    def result(self, timeout: float) -> T:
        if not self._done.wait(timeout):
            raise TimeoutError(f"a step of the Hypothesis run took more than {timeout:g} s")
        if self._error is not None:
            raise self._error
        return self._value  # type: ignore[return-value]


async def run_in_worker(
    fn: Callable[[Bridge], T], *, budget: float | None = None, shrink_budget: float | None = None
) -> T:
    """Run ``fn(bridge)`` in a worker thread; cancelling this coroutine stops the worker's next step.

    ``shrink_budget`` defaults to the module's :data:`DEFAULT_SHRINK_BUDGET` as it is at the call (a test
    suite that only needs to know *that* a case fails may lower it)."""
    limit = DEFAULT_SHRINK_BUDGET if shrink_budget is None else shrink_budget
    loop = asyncio.get_running_loop()
    bridge = Bridge(loop, budget=budget, shrink_budget=limit)
    if is_virtual(loop):
        return await _lockstep(fn, bridge)
    try:
        return await asyncio.to_thread(fn, bridge)
    except asyncio.CancelledError:
        bridge.stop()
        raise


class _Workers:
    """Daemon threads that run one job at a time and are kept for the next.

    Hypothesis gives every thread its own generator and registers it with a full garbage collection
    (``hypothesis.internal.entropy.register_random``): with a new thread for every case, that collection
    cost a few milliseconds per case in a small process and tens of them in a large one.  A thread left
    idle for ``idle_seconds`` ends; a job that never returns keeps only its own thread."""

    def __init__(self, name: str, idle_seconds: float = 30.0) -> None:
        self._name = name
        self._idle_seconds = idle_seconds
        self._lock = threading.Lock()
        self._idle: list[queue.SimpleQueue[Callable[[], None]]] = []

    def submit(self, job: Callable[[], None]) -> None:
        """Run ``job`` on an idle thread, or on a new one if none is idle; ``job`` must not raise."""
        with self._lock:
            inbox = self._idle.pop() if self._idle else None
        if inbox is None:
            inbox = queue.SimpleQueue()
            threading.Thread(target=self._serve, args=(inbox,), name=self._name, daemon=True).start()
        inbox.put(job)

    def _serve(self, inbox: queue.SimpleQueue[Callable[[], None]]) -> None:
        while True:
            try:
                job = inbox.get(timeout=self._idle_seconds)
            except queue.Empty:
                with self._lock:
                    if inbox in self._idle:  # else a job was handed over just now: take it
                        self._idle.remove(inbox)
                        return
                continue
            job()
            with self._lock:
                self._idle.append(inbox)


_WORKERS = _Workers("manip-hypothesis")


async def _lockstep(fn: Callable[[Bridge], T], bridge: Bridge) -> T:
    """Run ``fn(bridge)`` in a thread that takes turns with this one (see the module docstring)."""
    steps: queue.SimpleQueue[_Step[Any]] = queue.SimpleQueue()
    bridge.steps = steps
    outcome: _Step[T] = _Step(None)

    def work() -> None:
        try:
            outcome.settle(fn(bridge))
        except BaseException as exc:  # handed to the loop thread
            outcome.settle(error=exc)
        steps.put(_Step(None))  # the end marker: the worker is done with this run

    _WORKERS.submit(work)
    while True:
        try:  # blocks the loop on purpose: the simulated world waits for the worker
            step = steps.get(timeout=STEP_TIMEOUT)
        except queue.Empty:
            bridge.stop()
            raise TimeoutError(
                f"the Hypothesis worker took more than {STEP_TIMEOUT:g} s between steps"
            ) from None
        if step.coro is None:
            break
        try:
            step.settle(await step.coro)
        except asyncio.CancelledError:
            bridge.stop()
            step.settle(error=StopRun("the loop cancelled the step"))
            _drain(steps)
            raise
        except BaseException as exc:
            step.settle(error=exc)
    return outcome.result(0)


def _drain(steps: queue.SimpleQueue[_Step[Any]]) -> None:
    """After a cancellation: refuse the worker's remaining steps until its end marker."""
    while (step := steps.get()).coro is not None:
        step.coro.close()
        step.settle(error=StopRun("cancelled"))


async def connect_fresh(ctx: CaseContext) -> Probe:
    """``ctx.connect()`` with the global ``random`` state reseeded for the connection index (see the
    module docstring) and restored afterwards.  The new seed is drawn from the case's own generator, so
    indices differ from example to example and still repeat with the run seed."""
    state = random.getstate()
    random.seed(ctx.random.getrandbits(64))
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
