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
import threading
from collections.abc import Callable, Coroutine, Mapping, Sequence
from types import TracebackType
from typing import Any, SupportsFloat, SupportsInt, TypeVar

from manip.arm.transform import Transform
from manip.codecs.lisp import LispValue
from manip.reference_client.arguments import FloatArray
from manip.reference_client.background import AsyncListener, CloseListener, ErrorListener
from manip.reference_client.connect import TransportSource, open_manipulator, with_contact
from manip.reference_client.issuer import DEFAULT, Default, Timeout
from manip.reference_client.manipulator import Manipulator, RequestData
from manip.reference_client.options import ClientOptions
from manip.reference_client.request import DataExtractor, Request, RequestCode, ResponseType

T = TypeVar("T")


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


class SyncManipulator:
    """The blocking twin of :class:`~manip.reference_client.manipulator.Manipulator`."""

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

    def make_request(
        self,
        code: str | int | RequestCode,
        data: RequestData | None = None,
        *,
        fields: Mapping[str, Any] | None = None,
        response_type: ResponseType | None = None,
        extractor: str | DataExtractor[Any] | Default | None = DEFAULT,
        timeout: Timeout = DEFAULT,
    ) -> Request[Any]:
        return self.arm.make_request(
            code, data, fields=fields, response_type=response_type, extractor=extractor, timeout=timeout
        )

    def request(
        self,
        code: str | int | RequestCode,
        data: RequestData | None = None,
        *,
        fields: Mapping[str, Any] | None = None,
        response_type: ResponseType | None = None,
        extractor: str | DataExtractor[Any] | Default | None = DEFAULT,
        timeout: Timeout = DEFAULT,
    ) -> Any:
        return self._run(
            self.arm.request(
                code, data, fields=fields, response_type=response_type, extractor=extractor, timeout=timeout
            )
        )

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

    def add_close_listener(self, listener: CloseListener) -> Callable[[], None]:
        return self.arm.add_close_listener(listener)

    def request_notifications(self, mask: int, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.request_notifications(mask, timeout=timeout))

    def wait_for_segment(self, segment: SupportsInt, *, timeout: float | None = None) -> None:
        self._run(self.arm.wait_for_segment(segment, timeout=timeout))

    def free_joint(self, joint: int, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.free_joint(joint, timeout=timeout))

    def release_joint(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.release_joint(timeout=timeout))

    # ------------------------------------------------------------------ E.1 operations

    def describe(self, *, timeout: Timeout = DEFAULT) -> dict[str, LispValue]:
        return self._run(self.arm.describe(timeout=timeout))

    def here(self, *, timeout: Timeout = DEFAULT) -> Transform:
        return self._run(self.arm.here(timeout=timeout))

    def joint_angles(self, *, timeout: Timeout = DEFAULT) -> tuple[float, ...]:
        return self._run(self.arm.joint_angles(timeout=timeout))

    def calibrate(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.calibrate(timeout=timeout))

    def move(self, target: Transform, *, timeout: Timeout = DEFAULT) -> int:
        return self._run(self.arm.move(target, timeout=timeout))

    def straight_move(self, target: Transform, *, timeout: Timeout = DEFAULT) -> int:
        return self._run(self.arm.straight_move(target, timeout=timeout))

    def kill_power(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.kill_power(timeout=timeout))

    def set_configuration(self, lefty: bool, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_configuration(lefty, timeout=timeout))

    def hand(self, amount: int, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.hand(amount, timeout=timeout))

    def open_hand(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.open_hand(timeout=timeout))

    def close_hand(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.close_hand(timeout=timeout))

    def incremental_move(
        self,
        dx: float = 0.0,
        dy: float = 0.0,
        dz: float = 0.0,
        do: float = 0.0,
        da: float = 0.0,
        dt: float = 0.0,
        *,
        timeout: Timeout = DEFAULT,
    ) -> int:
        return self._run(self.arm.incremental_move(dx, dy, dz, do, da, dt, timeout=timeout))

    def incremental_straight_move(
        self,
        dx: float = 0.0,
        dy: float = 0.0,
        dz: float = 0.0,
        do: float = 0.0,
        da: float = 0.0,
        dt: float = 0.0,
        *,
        timeout: Timeout = DEFAULT,
    ) -> int:
        return self._run(self.arm.incremental_straight_move(dx, dy, dz, do, da, dt, timeout=timeout))

    def ready(self, *, timeout: Timeout = DEFAULT) -> int:
        return self._run(self.arm.ready(timeout=timeout))

    def set_joint_angles(self, joints: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> int:
        return self._run(self.arm.set_joint_angles(joints, timeout=timeout))

    def set_speed(self, factor: float, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_speed(factor, timeout=timeout))

    def enable_power(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.enable_power(timeout=timeout))

    def solve_forwards(
        self, target: Transform, current: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT
    ) -> tuple[float, ...]:
        return self._run(self.arm.solve_forwards(target, current, timeout=timeout))

    def solve_backwards(self, joints: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> Transform:
        return self._run(self.arm.solve_backwards(joints, timeout=timeout))

    # ------------------------------------------------------------------ Puma extensions

    def read_forces(self, *, timeout: Timeout = DEFAULT) -> tuple[float, ...]:
        return self._run(self.arm.read_forces(timeout=timeout))

    def read_raw_gauges(self, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        return self._run(self.arm.read_raw_gauges(timeout=timeout))

    def set_gauge_offsets(self, offsets: Sequence[SupportsInt], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_gauge_offsets(offsets, timeout=timeout))

    def calibrate_wrist(self, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        return self._run(self.arm.calibrate_wrist(timeout=timeout))

    def set_spring(self, k: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_spring(k, timeout=timeout))

    def set_damping(self, b: FloatArray, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_damping(b, timeout=timeout))

    def set_joint_damping(self, bji: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_joint_damping(bji, timeout=timeout))

    def set_frame_vector(self, offset: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_frame_vector(offset, timeout=timeout))

    def set_weight(self, weight: float, cg: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_weight(weight, cg, timeout=timeout))

    def set_guard(
        self,
        index: int,
        dvec: Sequence[SupportsFloat],
        tol: float,
        *,
        stop: bool = True,
        timeout: Timeout = DEFAULT,
    ) -> None:
        self._run(self.arm.set_guard(index, dvec, tol, stop=stop, timeout=timeout))

    def clear_guard(self, index: int, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.clear_guard(index, timeout=timeout))

    def compliant_move(
        self, joints: Sequence[SupportsFloat], scheme: int = 0, *, timeout: Timeout = DEFAULT
    ) -> int:
        return self._run(self.arm.compliant_move(joints, scheme, timeout=timeout))

    def examine_wrist(self, address: int, count: int, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        return self._run(self.arm.examine_wrist(address, count, timeout=timeout))

    def deposit_wrist(self, address: int, value: int, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.deposit_wrist(address, value, timeout=timeout))

    def wrist_version(self, *, timeout: Timeout = DEFAULT) -> int:
        return self._run(self.arm.wrist_version(timeout=timeout))

    def reset_abort(self, *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.reset_abort(timeout=timeout))

    def set_commanded_force(self, force: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        self._run(self.arm.set_commanded_force(force, timeout=timeout))


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
