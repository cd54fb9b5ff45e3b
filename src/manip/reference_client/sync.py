"""A blocking facade: ``with connect(...) as arm: arm.here()``.

Choice: one private event loop per connection, running in a daemon thread, with each call submitted
to it by ``asyncio.run_coroutine_threadsafe`` and waited for.  Not ``asyncio.run`` per call: the
background process must keep running between calls, to collect asynchronous responses (segment
completions that ``wait_for_segment`` needs later) and, over Chaosnet, to let the NCP acknowledge,
retransmit and probe; a loop that exists only during a call would stall the connection in between.

Consequences:

* calls may come from any thread except the loop's own; listeners (``add_async_listener`` ...) run in
  the loop's thread, so they must not call back into the facade (that would deadlock; it raises
  RuntimeError instead);
* nothing blocks for ever: every request has its timeout (``ClientOptions.timeout``), and a lost
  connection fails every waiting call;
* :meth:`SyncManipulator.close` (or leaving the ``with``) disconnects and stops the thread.
"""

from __future__ import annotations

import asyncio
import inspect
import threading
from collections.abc import Callable, Coroutine
from types import TracebackType
from typing import Any, Concatenate, ParamSpec, TypeVar

from manip.reference_client.background import AsyncListener, ErrorListener
from manip.reference_client.connect import TransportSource, open_manipulator, with_contact
from manip.reference_client.manipulator import Manipulator
from manip.reference_client.options import ClientOptions
from manip.reference_client.request import Request

T = TypeVar("T")
P = ParamSpec("P")


class _LoopThread:
    """An event loop running for ever in a daemon thread, until :meth:`stop`."""

    def __init__(self, name: str) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._main, name=name, daemon=True)
        self._thread.start()

    def _main(self) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_forever()
        finally:
            tasks = asyncio.all_tasks(self.loop)
            for task in tasks:
                task.cancel()
            self.loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
            self.loop.run_until_complete(self.loop.shutdown_asyncgens())
            self.loop.close()

    def run(self, coro: Coroutine[Any, Any, T]) -> T:
        if threading.current_thread() is self._thread:
            coro.close()
            raise RuntimeError("a blocking manipulator call from its own event loop thread (a listener?)")
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result()

    def stop(self) -> None:
        if self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.loop.stop)
            if threading.current_thread() is not self._thread:
                self._thread.join()


def _named(call: Callable[..., Any], method: Callable[..., Any]) -> None:
    """Give the facade's ``call`` the name and docstring of the manipulator's ``method``."""
    call.__name__ = method.__name__
    call.__qualname__ = f"SyncManipulator.{method.__name__}"
    call.__doc__ = method.__doc__
    # help() and IDEs show the manipulator's parameters, not *args/**kwargs.
    setattr(call, "__signature__", inspect.signature(method))  # noqa: B010


def _blocking(
    method: Callable[Concatenate[Manipulator, P], Coroutine[Any, Any, T]],
) -> Callable[Concatenate[SyncManipulator, P], T]:
    """The facade's method for the coroutine method ``method``: it runs ``arm.<method>(...)`` in the
    loop thread and waits for its result.  The signature (hence mypy's view of it) is the manipulator's;
    the method is looked up on the arm at call time, as a hand-written ``self.arm.name(...)`` would."""
    name = method.__name__

    def call(self: SyncManipulator, /, *args: P.args, **kwargs: P.kwargs) -> T:
        bound: Callable[P, Coroutine[Any, Any, T]] = getattr(self.arm, name)
        return self._run(bound(*args, **kwargs))

    _named(call, method)
    return call


def _delegated(
    method: Callable[Concatenate[Manipulator, P], T],
) -> Callable[Concatenate[SyncManipulator, P], T]:
    """The facade's method for the plain (not coroutine) method ``method``: called directly, in the
    caller's thread."""
    name = method.__name__

    def call(self: SyncManipulator, /, *args: P.args, **kwargs: P.kwargs) -> T:
        bound: Callable[P, T] = getattr(self.arm, name)
        return bound(*args, **kwargs)

    _named(call, method)
    return call


class SyncManipulator:
    """The blocking twin of :class:`~manip.reference_client.manipulator.Manipulator`: each request
    method has the manipulator's signature and docstring, and blocks until its result."""

    def __init__(self, runner: _LoopThread, arm: Manipulator) -> None:
        self._runner = runner
        self.arm = arm
        """The asynchronous manipulator (use it only from the loop thread)."""

    def _run(self, coro: Coroutine[Any, Any, T]) -> T:
        return self._runner.run(coro)

    # ------------------------------------------------------------------ lifecycle

    def close(self) -> None:
        try:
            if not self.arm.closed:
                self._run(self.arm.aclose())
        finally:
            self._runner.stop()

    def __enter__(self) -> SyncManipulator:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        return self.arm.closed

    # ------------------------------------------------------------------ requests

    make_request = _delegated(Manipulator.make_request)
    request = _blocking(Manipulator.request)

    def perform(self, request: Request[T]) -> T:
        """Send a request made with :meth:`make_request` and wait for its result."""

        async def send() -> T:
            result: T = await self.arm.send_request(request)
            return result

        return self._run(send())

    # ------------------------------------------------------------------ listeners and segments

    @property
    def notify_trivial_errors(self) -> bool:
        return self.arm.notify_trivial_errors

    @notify_trivial_errors.setter
    def notify_trivial_errors(self, on: bool) -> None:
        async def switch() -> None:
            self.arm.notify_trivial_errors = on

        self._run(switch())

    def add_async_listener(self, listener: AsyncListener) -> Callable[[], None]:
        """``listener`` runs in the loop thread."""
        return self.arm.add_async_listener(listener)

    def add_error_listener(self, listener: ErrorListener) -> Callable[[], None]:
        """``listener`` runs in the loop thread."""
        return self.arm.add_error_listener(listener)

    add_close_listener = _delegated(Manipulator.add_close_listener)
    request_notifications = _blocking(Manipulator.request_notifications)
    wait_for_segment = _blocking(Manipulator.wait_for_segment)
    prepare_segment_wait = _blocking(Manipulator.prepare_segment_wait)
    free_joint = _blocking(Manipulator.free_joint)
    release_joint = _blocking(Manipulator.release_joint)

    # ------------------------------------------------------------------ E.1 operations

    describe = _blocking(Manipulator.describe)
    here = _blocking(Manipulator.here)
    joint_angles = _blocking(Manipulator.joint_angles)
    calibrate = _blocking(Manipulator.calibrate)
    move = _blocking(Manipulator.move)
    straight_move = _blocking(Manipulator.straight_move)
    kill_power = _blocking(Manipulator.kill_power)
    set_configuration = _blocking(Manipulator.set_configuration)
    hand = _blocking(Manipulator.hand)
    open_hand = _blocking(Manipulator.open_hand)
    close_hand = _blocking(Manipulator.close_hand)
    incremental_move = _blocking(Manipulator.incremental_move)
    incremental_straight_move = _blocking(Manipulator.incremental_straight_move)
    ready = _blocking(Manipulator.ready)
    set_joint_angles = _blocking(Manipulator.set_joint_angles)
    set_speed = _blocking(Manipulator.set_speed)
    enable_power = _blocking(Manipulator.enable_power)
    solve_forwards = _blocking(Manipulator.solve_forwards)
    solve_backwards = _blocking(Manipulator.solve_backwards)

    # ------------------------------------------------------------------ Puma extensions

    read_forces = _blocking(Manipulator.read_forces)
    read_raw_gauges = _blocking(Manipulator.read_raw_gauges)
    set_gauge_offsets = _blocking(Manipulator.set_gauge_offsets)
    calibrate_wrist = _blocking(Manipulator.calibrate_wrist)
    set_spring = _blocking(Manipulator.set_spring)
    set_damping = _blocking(Manipulator.set_damping)
    set_joint_damping = _blocking(Manipulator.set_joint_damping)
    set_frame_vector = _blocking(Manipulator.set_frame_vector)
    set_weight = _blocking(Manipulator.set_weight)
    set_guard = _blocking(Manipulator.set_guard)
    clear_guard = _blocking(Manipulator.clear_guard)
    compliant_move = _blocking(Manipulator.compliant_move)
    examine_wrist = _blocking(Manipulator.examine_wrist)
    deposit_wrist = _blocking(Manipulator.deposit_wrist)
    wrist_version = _blocking(Manipulator.wrist_version)
    reset_abort = _blocking(Manipulator.reset_abort)
    set_commanded_force = _blocking(Manipulator.set_commanded_force)


def connect(
    source: TransportSource, options: ClientOptions | None = None, *, contact: str | None = None
) -> SyncManipulator:
    """Connect and return a blocking manipulator; use it in ``with`` to disconnect at the end.

    ``source`` is a URL (``tcp://127.0.0.1:42085``, see :mod:`~manip.reference_client.connect`), a
    transport factory (called in the connection's own event loop thread, so the transport's asyncio
    objects belong to that loop) or a transport made for that loop.
    """
    options = with_contact(options, contact)
    runner = _LoopThread(f"manip client ({options.name})")
    try:
        arm = runner.run(open_manipulator(source, options))
    except BaseException:
        runner.stop()
        raise
    return SyncManipulator(runner, arm)
