"""The target of a campaign, and what the fuzzer can see of it besides its answers.

* :class:`RemoteServer`: a server someone else runs (``manip-conform fuzz HOST``).  Its answers are
  all there is, unless ``--server-log FILE`` names its log: every traceback written there during the
  campaign is then a violation.  A crash ends the campaign unless the server comes back (``--restart-wait``).
* :class:`LaunchedServer`: a server the fuzzer starts itself and restarts after a crash, reading its
  standard error (and output) for tracebacks: the embedded reference server (no HOST: ``manip-server``
  on a free loopback port, with ``--server-fault`` switches), or an implementer's own (``--launch
  CMD`` with HOST).  The reference server also reports its count of bad frames (SIGUSR1, the
  ``--stats`` line), so a drop it did not count is a violation too.

A traceback is a ``Traceback (most recent call last):`` line through the exception line that ends it
(:class:`TracebackScanner`).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import shlex
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Final

from manip.links.address import LinkAddress, parse_address

__all__ = [
    "FuzzedServer",
    "LaunchedServer",
    "RemoteServer",
    "TracebackScanner",
    "UnreachableError",
    "reference_server_argv",
]

START_TIMEOUT: Final = 30.0
STOP_TIMEOUT: Final = 5.0
STATS_TIMEOUT: Final = 2.0
KEPT_TRACEBACKS: Final = 50
TRACEBACK_HEAD: Final = "Traceback (most recent call last):"
_LISTENING: Final = re.compile(r"^manip-server: listening on (\S+)")
_BAD_FRAMES: Final = re.compile(r"bad frames (\d+)")


class UnreachableError(Exception):
    """The target could not be started or reached; the message says why."""


class TracebackScanner:
    """Finds tracebacks in log lines fed one by one; ``found`` holds each one's text (the line before
    it, which names what failed, included), ``total`` counts them all."""

    def __init__(self) -> None:
        self.found: list[str] = []
        self.total = 0
        self._block: list[str] | None = None
        self._previous = ""

    def feed(self, line: str) -> None:
        line = line.rstrip("\n")
        if line.startswith(TRACEBACK_HEAD):
            self._block = [self._previous, line] if self._previous else [line]
        elif self._block is not None:
            self._block.append(line)
            if line and not line[0].isspace():  # the exception line ends it
                self.total += 1
                if len(self.found) < KEPT_TRACEBACKS:
                    self.found.append("\n".join(self._block))
                self._block = None
        self._previous = line

    def take(self) -> list[str]:
        out, self.found = self.found, []
        return out


class FuzzedServer:
    """What the campaign asks of a target (module docstring)."""

    address: LinkAddress
    embedded = False
    can_restart = False
    label = ""

    async def start(self) -> None:
        """Start (or find) the target; :class:`UnreachableError` if it cannot be had."""

    async def stop(self) -> None:
        """Stop what :meth:`start` started."""

    def gone(self) -> str | None:
        """Why the target is known to be gone (its process exited), else None."""
        return None

    def tracebacks(self) -> list[str]:
        """The tracebacks the target logged since the last call."""
        return []

    @property
    def tracebacks_seen(self) -> int | None:
        """Tracebacks seen in all (None: the fuzzer cannot see the target's log)."""
        return None

    async def bad_frames(self) -> int | None:
        """The target's count of bad frames so far (None: it reports none)."""
        return None

    async def restart(self) -> None:
        raise UnreachableError("the fuzzer did not start this target, so it cannot restart it")


class RemoteServer(FuzzedServer):
    """A server at ``address``, its log optionally at ``log``."""

    def __init__(self, address: LinkAddress, log: Path | None = None) -> None:
        self.address = address
        self.label = str(address)
        self._log = log
        self._offset = 0
        self._scanner = TracebackScanner()
        self._tail = ""

    async def start(self) -> None:
        if self._log is not None:
            try:
                self._offset = self._log.stat().st_size
            except OSError as exc:
                raise UnreachableError(f"--server-log {self._log}: {exc.strerror or exc}") from exc

    def tracebacks(self) -> list[str]:
        if self._log is None:
            return []
        try:
            with self._log.open("rb") as f:
                f.seek(self._offset)
                chunk = f.read()
        except OSError:
            return []
        self._offset += len(chunk)
        text = self._tail + chunk.decode("utf-8", "replace")
        lines = text.split("\n")
        self._tail = lines.pop()  # an unfinished line waits for the rest
        for line in lines:
            self._scanner.feed(line)
        return self._scanner.take()

    @property
    def tracebacks_seen(self) -> int | None:
        return self._scanner.total if self._log is not None else None


def reference_server_argv(
    link: str = "tcp", *, faults: Sequence[str] = (), wrist: bool = False, seed: int | None = None
) -> list[str]:
    """The command that runs the reference server as the embedded target: loopback, a free port, only
    warnings logged (a campaign would log a line per request), the simulated wrist when asked."""
    listen = "tcp://127.0.0.1:0" if link == "tcp" else "chudp://127.0.0.1:0?addr=0440"
    argv = [sys.executable, "-m", "manip.reference_server.cli", "--listen", listen, "--log-level", "WARNING"]
    # A fast clock has motions end (and their completions reported) within a batch; the wrist link
    # runs in real time, so with it the clock is only four times as fast (its simulation costs CPU).
    argv += ["--cougar", "sim", "--time-scale", "4"] if wrist else ["--time-scale", "50"]
    if seed is not None:
        argv += ["--seed", str(seed)]
    for fault in faults:
        argv += ["--fault", fault]
    return argv


class LaunchedServer(FuzzedServer):
    """A server the fuzzer runs: ``argv``; ``address`` where it listens, or None for the reference
    server, which prints it (``manip-server: listening on URL``)."""

    can_restart = True

    def __init__(self, argv: Sequence[str], address: LinkAddress | None = None, *, label: str = "") -> None:
        self.argv = list(argv)
        self.embedded = address is None
        self._fixed = address
        self.label = label or shlex.join(self.argv)
        self._proc: asyncio.subprocess.Process | None = None
        self._scanner = TracebackScanner()
        self._readers: list[asyncio.Task[None]] = []
        self._stats: asyncio.Queue[str] = asyncio.Queue()
        self._listening: asyncio.Future[str] | None = None
        self.starts = 0

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        self._listening = loop.create_future()
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        try:
            self._proc = await asyncio.create_subprocess_exec(
                *self.argv,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.PIPE,
                env=env,
                start_new_session=True,
            )
        except OSError as exc:
            raise UnreachableError(f"cannot start {self.argv[0]}: {exc.strerror or exc}") from exc
        self.starts += 1
        assert self._proc.stdout is not None and self._proc.stderr is not None
        self._readers = [
            loop.create_task(self._read(self._proc.stdout, stdout=True)),
            loop.create_task(self._read(self._proc.stderr, stdout=False)),
        ]
        if self._fixed is not None:
            self.address = self._fixed
            return
        try:
            async with asyncio.timeout(START_TIMEOUT):
                url = await self._listening
        except (TimeoutError, EOFError) as exc:
            await self.stop()
            raise UnreachableError(
                f"the server did not say where it listens within {START_TIMEOUT:g} s"
            ) from exc
        self.address = parse_address(url)

    async def _read(self, stream: asyncio.StreamReader, *, stdout: bool) -> None:
        while True:
            raw = await stream.readline()
            if not raw:
                if self._listening is not None and not self._listening.done():
                    self._listening.set_exception(EOFError())
                return
            line = raw.decode("utf-8", "replace")
            if stdout:
                match = _LISTENING.match(line)
                if match and self._listening is not None and not self._listening.done():
                    self._listening.set_result(match.group(1))
                    continue
                if line.startswith("manip-server: stats:"):
                    self._stats.put_nowait(line)
                    continue
            self._scanner.feed(line)

    def gone(self) -> str | None:
        proc = self._proc
        if proc is None or proc.returncode is None:
            return None
        code = proc.returncode
        return f"the server process exited ({'signal ' + str(-code) if code < 0 else 'status ' + str(code)})"

    def tracebacks(self) -> list[str]:
        return self._scanner.take()

    @property
    def tracebacks_seen(self) -> int:
        return self._scanner.total

    async def bad_frames(self) -> int | None:
        proc = self._proc
        if not self.embedded or proc is None or proc.returncode is not None:
            return None
        while not self._stats.empty():
            self._stats.get_nowait()
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signal.SIGUSR1)
        try:
            async with asyncio.timeout(STATS_TIMEOUT):
                line = await self._stats.get()
        except TimeoutError:
            return None
        match = _BAD_FRAMES.search(line)
        return int(match.group(1)) if match else None

    async def stop(self) -> None:
        await self._end(signal.SIGTERM)

    async def kill(self) -> None:
        """Stop at once (a hung server does not answer SIGTERM in time)."""
        await self._end(signal.SIGKILL)

    async def _end(self, how: signal.Signals) -> None:
        proc = self._proc
        if proc is None:
            return
        if proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, how)  # its whole group: a --launch command may have started it
            try:
                async with asyncio.timeout(STOP_TIMEOUT):
                    await proc.wait()
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                await proc.wait()
        for task in self._readers:
            with contextlib.suppress(asyncio.CancelledError, TimeoutError):
                await asyncio.wait_for(task, STOP_TIMEOUT)
        self._proc = None

    async def restart(self) -> None:
        await self.kill()
        await self.start()
