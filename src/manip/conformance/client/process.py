"""The harness under test as a child process: start it, read its hello, feed it cases, read results.

Nothing the harness does can hang or crash the suite: every wait on it has a time limit (its hello, each
line, writing a case to its stdin, its exit, its pipes closing after a kill: :class:`Limits`), a line
that breaks the contract ends the case with a :class:`HarnessProblem` naming it, and a harness that
died, hung, flooded or wrote garbage is killed and started again for the next case.  Lines are bounded
in length (stdout and stderr alike).  The harness runs in a process group of its own, so a kill also
ends the children it started (a shell's ``sleep``), which would otherwise hold its pipes open.  The last
lines of its stderr are kept for the report.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.conformance.client.contract import (
    ContractError,
    HarnessHello,
    Instruction,
    Result,
    parse_hello,
    parse_result,
)

__all__ = [
    "HELLO_TIMEOUT",
    "LINE_LIMIT",
    "CaseTranscript",
    "HarnessError",
    "HarnessProblem",
    "HarnessProcess",
    "Limits",
]

HELLO_TIMEOUT: Final = 20.0
"""Seconds a harness has to write its hello after it starts (an interpreter may be slow to load)."""
EXIT_GRACE: Final = 5.0
"""Seconds a harness has to exit once its stdin is closed (docs/client-harness.md section 1)."""
KILL_WAIT: Final = 5.0
"""Seconds to wait, after a kill, for the process to end and its pipes to close; past it the suite lets
go of the process (a grandchild that left the harness's process group may still hold a pipe)."""
WRITE_TIMEOUT: Final = 5.0
"""Seconds writing one case to the harness's stdin may take (a harness that never reads fills the pipe)."""
STDERR_LINES: Final = 20
LINE_LIMIT: Final = 1 << 20
"""The longest stdout line, in bytes (a longer one is a harness error); stderr lines are cut to
:data:`STDERR_WIDTH` characters."""
STDERR_WIDTH: Final = 400


@dataclass(frozen=True)
class Limits:
    """Every time limit on the harness, in seconds (the defaults are the contract's)."""

    hello: float = HELLO_TIMEOUT
    exit_grace: float = EXIT_GRACE
    kill_wait: float = KILL_WAIT
    write: float = WRITE_TIMEOUT


class HarnessError(Exception):
    """The harness cannot be used at all (it does not start, or its hello is wrong)."""


@dataclass(frozen=True)
class HarnessProblem:
    """Why a case's results are incomplete: what the harness did wrong."""

    what: str
    """``crashed``, ``hung``, ``garbage``, ``no-hello`` (a restart that said no hello)."""
    detail: str


@dataclass
class CaseTranscript:
    """What the harness wrote for one case."""

    results: list[Result] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    """When each result line was read (the event loop's clock)."""
    problem: HarnessProblem | None = None
    stderr: list[str] = field(default_factory=list)


class HarnessProcess:
    """``argv`` run as a harness; :meth:`start` reads the hello, :meth:`run_case` one case."""

    def __init__(
        self, argv: Sequence[str], env: dict[str, str] | None = None, limits: Limits | None = None
    ) -> None:
        if not argv:
            raise HarnessError("no harness command given (manip-conform client -- CMD [ARGS...])")
        self.argv = list(argv)
        self.env = env
        self.limits = limits or Limits()
        self.hello: HarnessHello | None = None
        self.starts = 0
        self.unusable: str | None = None
        """Why a restart failed (no hello, bad hello): the run stops using the harness."""
        self._proc: asyncio.subprocess.Process | None = None
        self._stderr: deque[str] = deque(maxlen=STDERR_LINES)
        self._stderr_task: asyncio.Task[None] | None = None

    async def start(self) -> HarnessHello:
        """Start the harness and read its hello (:class:`HarnessError` if either fails)."""
        await self.stop()
        self.starts += 1
        env = dict(os.environ if self.env is None else self.env)
        env.setdefault("PYTHONUNBUFFERED", "1")
        try:
            self._proc = await asyncio.create_subprocess_exec(
                *self.argv,
                stdin=asyncio.subprocess.PIPE,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.PIPE,
                env=env,
                limit=LINE_LIMIT,
                start_new_session=True,  # its own process group: a kill reaches its children too
            )
        except OSError as exc:
            raise HarnessError(f"cannot start {self.argv[0]!r}: {exc}") from exc
        self._stderr_task = asyncio.get_running_loop().create_task(self._read_stderr(self._proc))
        hello_timeout = self.limits.hello
        try:
            line = await self._readline(hello_timeout)
        except TimeoutError:
            await self.kill()
            raise HarnessError(f"no hello line within {hello_timeout:g} s{self._stderr_hint()}") from None
        except ContractError as exc:
            await self.kill()
            raise HarnessError(f"bad hello line: {exc}") from None
        if line is None:
            await self.stop()
            raise HarnessError(f"the harness exited before its hello{self._stderr_hint()}")
        try:
            hello = parse_hello(line)
        except ContractError as exc:
            await self.kill()
            raise HarnessError(f"bad hello line {line[:200]!r}: {exc}") from None
        self.hello = hello
        return hello

    def _stderr_hint(self) -> str:
        tail = list(self._stderr)[-5:]
        return "; its stderr ends:\n  " + "\n  ".join(tail) if tail else ""

    async def _read_stderr(self, proc: asyncio.subprocess.Process) -> None:
        """Keep the last lines of stderr, each cut to :data:`STDERR_WIDTH`; read to its end whatever
        comes (a stderr left unread would block the harness, and keep its pipe from closing)."""
        assert proc.stderr is not None
        partial = b""
        with contextlib.suppress(Exception):
            while chunk := await proc.stderr.read(1 << 16):
                *lines, partial = (partial + chunk).split(b"\n")
                partial = partial[-STDERR_WIDTH:]
                for line in lines[-STDERR_LINES:]:
                    self._stderr.append(_shown(line))
        if partial:
            self._stderr.append(_shown(partial))

    async def _readline(self, timeout: float) -> str | None:
        """One stdout line (None at end of file); TimeoutError after ``timeout`` seconds."""
        assert self._proc is not None and self._proc.stdout is not None
        async with asyncio.timeout(timeout):
            try:
                raw = await self._proc.stdout.readline()
            except ValueError:  # a line past the limit
                raise ContractError(f"a line longer than {LINE_LIMIT} bytes") from None
        if not raw:
            return None
        return raw.decode(errors="replace").rstrip("\r\n")

    async def run_case(self, instruction: Instruction, deadline: float) -> CaseTranscript:
        """Send the case and read its results until ``done`` (or a problem) within ``deadline`` s."""
        run = CaseTranscript()
        if self._proc is None or self._proc.returncode is not None:
            try:
                await self.start()
            except HarnessError as exc:
                self.unusable = str(exc)
                run.problem = HarnessProblem("no-hello", f"started again for this case: {exc}")
                run.stderr = list(self._stderr)
                return run
        self._stderr.clear()
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write(instruction.line())
            async with asyncio.timeout(self.limits.write):
                await self._proc.stdin.drain()
        except (ConnectionError, OSError) as exc:
            run.problem = HarnessProblem("crashed", f"could not write the case to its stdin: {exc}")
            await self._finish_bad(run)
            return run
        except TimeoutError:
            run.problem = HarnessProblem(
                "hung", f"it read nothing of the case from its stdin within {self.limits.write:g} s"
            )
            await self._finish_bad(run)
            return run
        loop = asyncio.get_running_loop()
        end = loop.time() + deadline
        while True:
            try:
                line = await self._readline(max(0.0, end - loop.time()))
            except TimeoutError:
                run.problem = HarnessProblem(
                    "hung", f"no 'done' within the case's deadline of {deadline:g} s"
                )
                break
            except ContractError as exc:
                run.problem = HarnessProblem("garbage", str(exc))
                break
            if line is None:
                code = await self._exit_status(self._proc)
                run.problem = HarnessProblem("crashed", f"the harness exited (status {code}) before 'done'")
                break
            if not line.strip():
                continue
            try:
                result = parse_result(line, instruction.case)
            except ContractError as exc:
                run.problem = HarnessProblem("garbage", f"line {line[:200]!r}: {exc}")
                break
            run.results.append(result)
            run.times.append(loop.time())
            if result.type == "done":
                run.stderr = list(self._stderr)
                return run
        await self._finish_bad(run)
        return run

    async def _finish_bad(self, run: CaseTranscript) -> None:
        await self.kill()
        run.stderr = list(self._stderr)

    async def _exit_status(self, proc: asyncio.subprocess.Process) -> int | None:
        """Its exit status once its stdout ended (None if it does not come within a second)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):
                return await proc.wait()
        return proc.returncode

    async def stop(self) -> None:
        """Close its stdin, wait a little for it to exit, then kill it (every wait bounded)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.returncode is None:
            with contextlib.suppress(Exception):
                assert proc.stdin is not None
                proc.stdin.close()
            drain = asyncio.get_running_loop().create_task(_drain(proc))
            try:
                async with asyncio.timeout(self.limits.exit_grace):
                    await proc.wait()
            except TimeoutError:
                _kill_group(proc)
            await self._let_go(proc, drain)
        else:
            await self._let_go(proc, None)

    async def _let_go(self, proc: asyncio.subprocess.Process, drain: asyncio.Task[None] | None) -> None:
        """Wait (bounded) for the process to end and its pipes to close, then drop it."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.limits.kill_wait):
                await proc.wait()
                if self._stderr_task is not None:
                    await self._stderr_task
        _kill_group(proc)  # whatever of its group is left (a child that outlived it)
        for task in (drain, self._stderr_task):
            if task is not None and not task.done():
                task.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
        self._stderr_task = None
        transport = getattr(proc, "_transport", None)  # asyncio keeps no public handle on it
        if transport is not None:
            transport.close()

    async def kill(self) -> None:
        """Stop at once (a hung, flooding or garbled harness: no grace), its children with it."""
        proc = self._proc
        if proc is None:
            return
        self._proc = None
        drain = asyncio.get_running_loop().create_task(_drain(proc))
        _kill_group(proc)
        await self._let_go(proc, drain)


def _kill_group(proc: asyncio.subprocess.Process) -> None:
    """SIGKILL the harness's process group (it leads its own session: :meth:`HarnessProcess.start`)."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, signal.SIGKILL)


async def _drain(proc: asyncio.subprocess.Process) -> None:
    """Read and drop what is left on its stdout, so the pipe is seen to close (a flooded pipe whose
    reader paused would never show its end, and asyncio's ``wait`` waits for that)."""
    if proc.stdout is None:
        return
    with contextlib.suppress(Exception):
        while await proc.stdout.read(1 << 16):
            pass


def _shown(line: bytes) -> str:
    return line[:STDERR_WIDTH].decode(errors="replace").rstrip()
