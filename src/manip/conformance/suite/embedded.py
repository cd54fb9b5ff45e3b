"""The embedded reference server: the target of ``manip-conform run`` when no HOST is given.

Two ways to run it, one per time mode:

* **Virtual time** (the default, :func:`simulated_server`): the server runs on the runner's own event
  loop, a :class:`~manip.links.virtual_clock.VirtualClockLoop`, and listens on a Unix-domain socket in a
  private temporary directory.  Suite, NCPs, move process and Cougar share one clock that jumps over
  idle time, and every random choice comes from the run seed: the same seed gives the same verdict and
  the same bytes on the wire, and a motion of five simulated seconds costs microseconds.  A server that
  loops forever would freeze the run with it; the reference server is under test elsewhere for that.
* **Real time** (:class:`EmbeddedServer`): the server runs on its own thread and event loop on a
  loopback TCP port, so the suite judges it exactly as it judges a remote server: if the simulator
  spends seconds on one request, the runner keeps its clock (the GIL is handed over every few
  milliseconds) and a stuck server shows up as a failed deadline and a dead liveness probe.

Either way the run gets a :class:`ServerEnvironment`, whose :class:`EmbeddedWorld` arranges the
conditions of the arm's world that cases ask for (``async with ctx.arranged(CalibrationFailure()):``;
:mod:`manip.conformance.suite.world`), as another target's world does over contract 2.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import os
import random
import tempfile
import threading
from collections.abc import AsyncIterator
from types import TracebackType
from typing import Final, Literal

from manip.conformance.suite.world import Condition, ConditionUnsupported
from manip.links import NcpConfig
from manip.links.address import DEFAULT_SERVER_ADDR
from manip.links.chaosd_router import ChaosdRouter
from manip.reference_server import ServerConfig
from manip.reference_server.cougar_wrist import make_cougar_wrist
from manip.reference_server.driver import ReferenceServer, serve
from manip.reference_server.world import ReferenceWorld, WorldRefusal

__all__ = [
    "EmbeddedServer",
    "EmbeddedWorld",
    "ServerEnvironment",
    "SimulatedLink",
    "simulated_environment",
    "simulated_server",
]

SimulatedLink = Literal["unix", "chudp", "chaosd"]
"""How a simulated server is reached: manip's TCP link framing on a Unix-domain socket (the default),
CHUDP on a loopback UDP port, or usim's chaosd framing through a routing chaosd stand-in in the process
(:class:`~manip.links.chaosd_router.ChaosdRouter`) that the server dials as its daemon (each link's own
framing, for what only that link shows)."""
CHUDP_LOOPBACK: Final = "chudp://127.0.0.1:0?addr=0440"
CHAOSD_SOCKET: Final = "chaosd.sock"

START_TIMEOUT: Final = 10.0
STOP_TIMEOUT: Final = 5.0
SOCKET_NAME: Final = "puma.sock"


class ServerEnvironment:
    """The embedded server's conditions of the arm's world, switched by the cases that need them.

    :attr:`world` is the run's :class:`~manip.conformance.suite.world.World` (:class:`EmbeddedWorld`):
    cases arrange conditions through it, as they do through any target's world; :attr:`reference` is
    the reference server's own :class:`~manip.reference_server.world.ReferenceWorld` under it.  A world
    arranges conditions, never a defect of the server it judges (those are ``--server-fault``)."""

    def __init__(self, server: ReferenceServer) -> None:
        self._server = server
        self.reference = ReferenceWorld(server)
        self.world = EmbeddedWorld(self.reference)

    @property
    def address(self) -> str:
        return self._server.address


class EmbeddedWorld:
    """The embedded server's world (a :class:`~manip.conformance.suite.world.World`): the reference
    server's :class:`~manip.reference_server.world.ReferenceWorld`, in-process, at once."""

    description = "the embedded server's world"

    def __init__(self, reference: ReferenceWorld) -> None:
        self._reference = reference

    @contextlib.asynccontextmanager
    async def arranged(self, condition: Condition) -> AsyncIterator[None]:
        try:
            token = self._reference.arrange(condition.name, condition.args())
        except WorldRefusal as exc:
            raise ConditionUnsupported(condition, str(exc)) from None
        try:
            yield
        finally:
            self._reference.clear(token)


@contextlib.asynccontextmanager
async def simulated_server(
    config: ServerConfig | None = None,
    *,
    seed: int,
    wrist: bool = False,
    broken_after: float | None = None,
) -> AsyncIterator[str]:
    """``async with simulated_server(config, seed=...) as address:`` (:func:`simulated_environment`)."""
    async with simulated_environment(config, seed=seed, wrist=wrist, broken_after=broken_after) as env:
        yield env.address


@contextlib.asynccontextmanager
async def simulated_environment(
    config: ServerConfig | None = None,
    *,
    seed: int,
    wrist: bool = False,
    broken_after: float | None = None,
    link: SimulatedLink = "unix",
) -> AsyncIterator[ServerEnvironment]:
    """``async with simulated_environment(config, seed=...) as env:`` a reference server on this loop,
    at ``env.address``, reached over ``link`` (:data:`SimulatedLink`).

    The global ``random`` generator is part of the simulated world (connection indices are drawn from
    it): it is seeded from ``seed`` here, so both ends' indices repeat with the run.  Over CHUDP the
    virtual clock's jump is as sound as a loopback datagram is delivered before its ``sendto`` returns,
    which Linux does (the receiving queue is filled in the sender's system call); over chaosd, as the
    router's reads and writes on Unix sockets are (its hop costs a turn of the loop, not time)."""
    random.seed(seed)
    options = None if broken_after is None else NcpConfig.breaking_after(broken_after)
    wrist_factory = functools.partial(make_cougar_wrist, "sim", seed=seed) if wrist else None
    with tempfile.TemporaryDirectory(prefix="manip-sim-") as directory:
        path = os.path.join(directory, SOCKET_NAME if link != "chaosd" else CHAOSD_SOCKET)
        async with contextlib.AsyncExitStack() as stack:
            if link == "chaosd":
                router = await stack.enter_async_context(ChaosdRouter(path))
            server = await stack.enter_async_context(
                serve(
                    {"unix": f"unix://{path}", "chudp": CHUDP_LOOPBACK, "chaosd": f"chaosd://{path}"}[link],
                    config or ServerConfig(),
                    seed=seed,
                    wrist_factory=wrist_factory,
                    options=options,
                )
            )
            if link == "chaosd":
                await router.name_silent(DEFAULT_SERVER_ADDR)
            yield ServerEnvironment(server)


class EmbeddedServer:
    """``with EmbeddedServer(config) as address:`` runs a reference server on a loopback port, on its own
    thread, in real time."""

    def __init__(
        self,
        config: ServerConfig | None = None,
        address: str = "tcp://127.0.0.1:0",
        *,
        time_scale: float = 1.0,
        seed: int | None = None,
        wrist: bool = False,
        broken_after: float | None = None,
        cougar: str = "sim",
    ) -> None:
        """``wrist``: give the robot a Cougar wrist, so the wrist opcodes are served (and checked) rather
        than refused with C UIM: ``cougar`` says which (``sim``, the simulated one in-process, or the
        ``tcp://`` address of one on the emulated DRV-11J, such as the suite's judging Cougar).
        ``broken_after``: the server's broken-connection timer (default 90 s, the ITS Chaos NCP's;
        erratum ``ncp-timers``)."""
        self._ncp = None if broken_after is None else NcpConfig.breaking_after(broken_after)
        self._config = config or ServerConfig()
        self._wrist = functools.partial(make_cougar_wrist, cougar, seed=seed) if wrist else None
        self._time_scale = time_scale
        self._seed = seed
        self._bind = address
        self._ready = threading.Event()
        self._address: str | None = None
        self.environment: ServerEnvironment | None = None
        """Set once the server runs (:class:`ServerEnvironment`)."""
        self._error: BaseException | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._main, name="manip-embedded-server", daemon=True)

    def _main(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # reported to the starting thread
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        async with serve(
            self._bind,
            self._config,
            time_scale=self._time_scale,
            seed=self._seed,
            wrist_factory=self._wrist,
            options=self._ncp,
        ) as server:
            self._address = server.address
            self.environment = ServerEnvironment(server)
            self._ready.set()
            await self._stop.wait()

    def __enter__(self) -> str:
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT) or self._address is None:
            raise RuntimeError(f"the embedded server did not start: {self._error!r}")
        return self._address

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if self._loop is not None and self._stop is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(STOP_TIMEOUT)
