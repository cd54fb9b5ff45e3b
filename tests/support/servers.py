"""Servers for tests, the one shared set (``tests/conftest.py`` makes fixtures of them).

* in-process, for one ``async`` test's own event loop: :func:`reference_server` (the reference server,
  yields its address), :func:`running_server` (the same, yields the server itself), :func:`scripted_server`
  (a links server running a test's handler);
* in a thread: :func:`in_thread` runs any of those in an event loop of its own, for blocking clients and
  for fixtures (``reference_server_url``, ``served`` with :class:`ServerOptions`);
* a process: :func:`start_process` starts ``manip-server`` (or ``manip-cougar``, or a script that is one)
  on an ephemeral port read from its output; the ``manip_server`` fixture stops and reaps what it starts.
  Only tests of the commands themselves, or of what needs a process of its own (signals, descriptor
  limits, a server that crashes), use a process.
"""

from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager, contextmanager
from dataclasses import dataclass, field
from typing import IO, Any, Literal, TypeVar

from manip.links import ChaosConnection, start_server
from manip.reference_server import Fault, FaultSet, ServerConfig, WorldCondition
from manip.reference_server.driver import ReferenceServer, serve

T = TypeVar("T")

TIME_SCALE = 50.0
"""Simulated seconds per real second: motions of a few seconds take a few tens of milliseconds."""
LINK_ADDRESSES = {"tcp": "tcp://127.0.0.1:0", "chudp": "chudp://127.0.0.1:0?addr=440"}
"""A free loopback port for each link kind a test server listens on."""

MANIP_SERVER = (sys.executable, "-m", "manip.reference_server.cli")
MANIP_COUGAR = (sys.executable, "-c", "from manip.cougar.cli import main; main()")  # no __main__ guard
START_TIMEOUT = 20.0


# ------------------------------------------------------------------------------------ in-process
@asynccontextmanager
async def running_server(
    config: ServerConfig | None = None,
    *,
    address: str = LINK_ADDRESSES["tcp"],
    contact: str = "PUMA",
    time_scale: float = TIME_SCALE,
) -> AsyncIterator[ReferenceServer]:
    """A reference server in the running event loop."""
    async with serve(address, config or ServerConfig(), contact=contact, time_scale=time_scale) as server:
        yield server


@asynccontextmanager
async def reference_server(config: ServerConfig | None = None, **options: Any) -> AsyncIterator[str]:
    """:func:`running_server` (the same options), yielding its address (with ``?contact=`` unless the
    contact is PUMA)."""
    async with running_server(config, **options) as server:
        yield server.address


Handler = Callable[[ChaosConnection], Awaitable[None]]


@asynccontextmanager
async def scripted_server(handler: Handler) -> AsyncIterator[str]:
    """A links server on a free TCP port whose every connection is ``handler``'s; yields its address."""
    server = await start_server(LINK_ADDRESSES["tcp"], None, handler)
    async with server:
        yield str(server.address)


@contextmanager
def in_thread(server: AbstractAsyncContextManager[T]) -> Iterator[T]:
    """Run ``server`` in an event loop of its own thread; yields what it yields; stops it at the end."""
    started = threading.Event()
    loop: asyncio.AbstractEventLoop | None = None
    stop: asyncio.Event | None = None
    entered: list[T] = []
    failure: BaseException | None = None

    async def main() -> None:
        nonlocal loop, stop, failure
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        try:
            async with server as bound:
                entered.append(bound)
                started.set()
                await stop.wait()
        except BaseException as exc:
            failure = exc
            started.set()

    thread = threading.Thread(target=asyncio.run, args=(main(),), name="test server", daemon=True)
    thread.start()
    assert started.wait(10), "the server did not start"
    if failure is not None:
        raise RuntimeError("the server failed to start") from failure
    assert loop is not None and stop is not None and entered
    try:
        yield entered[0]
    finally:
        loop.call_soon_threadsafe(stop.set)
        thread.join(10)
        assert not thread.is_alive(), "the server did not stop"


@dataclass(frozen=True)
class ServerOptions:
    """How the ``served`` fixture sets up its reference server (``indirect`` parametrisation)."""

    faults: tuple[Fault | WorldCondition, ...] = ()
    """Fault switches and conditions of the world, as ``--fault`` names them."""
    link: Literal["tcp", "chudp"] = "tcp"
    contact: str = "PUMA"

    def start(self) -> AbstractAsyncContextManager[ReferenceServer]:
        config = ServerConfig(faults=FaultSet.parse(f.value for f in self.faults))
        return running_server(config, address=LINK_ADDRESSES[self.link], contact=self.contact)


def free_port() -> int:
    """A loopback TCP port nothing listens on (free a moment ago)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


# ------------------------------------------------------------------------------------- processes
@dataclass
class ServerProcess:
    """A server command running as a process, listening at ``url`` (its first ``listening on`` line)."""

    proc: subprocess.Popen[str]
    url: str
    line: str
    """The whole first ``listening on`` line."""
    command: Sequence[str] = field(default=MANIP_SERVER)

    def stop(self, timeout: float = 20.0) -> tuple[str, str]:
        """SIGTERM; it must exit 0. Returns the rest of its stdout and its stderr (unless that went
        to a file)."""
        self.proc.send_signal(signal.SIGTERM)
        out, err = self.proc.communicate(timeout=timeout)
        assert self.proc.returncode == 0, err
        return out, err or ""

    def end(self) -> None:
        """Make sure it is gone and reaped: SIGTERM, then SIGKILL after 5 s."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.proc.communicate(timeout=5.0)


StartServer = Callable[..., ServerProcess]
"""The ``manip_server`` fixture: :func:`start_process`, with the stop at teardown."""


def start_process(
    *args: str,
    command: Sequence[str] = MANIP_SERVER,
    listen: str | None = LINK_ADDRESSES["tcp"],
    stderr: IO[str] | None = None,
    limit: Callable[[], None] | None = None,
) -> ServerProcess:
    """Start ``command --listen LISTEN ARGS`` and wait for its ``listening on URL`` line.

    ``stderr`` is a pipe unless a file is given (a log another tool reads); ``limit`` runs in the child
    before the command (resource limits only). If it exits or prints no such line within 20 s it is
    killed and the error holds what it wrote to stderr."""
    full = [*command, *(["--listen", listen] if listen is not None else []), *args]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        full,
        stdout=subprocess.PIPE,
        stderr=stderr if stderr is not None else subprocess.PIPE,
        text=True,
        env=env,
        preexec_fn=limit,  # noqa: PLW1509 - only sets a resource limit
    )
    assert proc.stdout is not None
    deadline = time.monotonic() + START_TIMEOUT
    line = ""
    while ": listening on " not in line:  # readline returns once the server has printed
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            _, err = proc.communicate(timeout=5.0)
            raise AssertionError(f"{' '.join(full)} did not start: {line!r} {err or ''}")
        line = proc.stdout.readline()
    url = line.partition(": listening on ")[2].split()[0]
    return ServerProcess(proc, url, line, command)
