"""The harness under test as a child process: start it, read its hello, feed it cases, read results.

Nothing the harness does can hang or crash the suite: every read has a deadline, a line that breaks the
contract ends the case with a :class:`HarnessProblem` naming it, and a harness that died, hung or wrote
garbage is killed and started again for the next case.  The last lines of its stderr are kept for the
report.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Final

from manip.conformance.client.contract import (
    ContractError,
    Hello,
    Instruction,
    Result,
    parse_hello,
    parse_result,
)

__all__ = ["HELLO_TIMEOUT", "CaseRun", "HarnessError", "HarnessProblem", "HarnessProcess"]

HELLO_TIMEOUT: Final = 20.0
"""Seconds a harness has to write its hello after it starts (an interpreter may be slow to load)."""
EXIT_GRACE: Final = 5.0
STDERR_LINES: Final = 20
LINE_LIMIT: Final = 1 << 20


class HarnessError(Exception):
    """The harness cannot be used at all (it does not start, or its hello is wrong)."""


@dataclass(frozen=True)
class HarnessProblem:
    """Why a case's results are incomplete: what the harness did wrong."""

    what: str
    """``crashed``, ``hung``, ``garbage``, ``no-done``."""
    detail: str


@dataclass
class CaseRun:
    """What the harness wrote for one case."""

    results: list[Result] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    """When each result line was read (the event loop's clock)."""
    problem: HarnessProblem | None = None
    stderr: list[str] = field(default_factory=list)


class HarnessProcess:
    """``argv`` run as a harness; :meth:`start` reads the hello, :meth:`run_case` one case."""

    def __init__(self, argv: Sequence[str], env: dict[str, str] | None = None) -> None:
        if not argv:
            raise HarnessError("no harness command given (manip-conform client -- CMD [ARGS...])")
        self.argv = list(argv)
        self.env = env
        self.hello: Hello | None = None
        self.starts = 0
        self._proc: asyncio.subprocess.Process | None = None
        self._stderr: deque[str] = deque(maxlen=STDERR_LINES)
        self._stderr_task: asyncio.Task[None] | None = None

    async def start(self) -> Hello:
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
            )
        except OSError as exc:
            raise HarnessError(f"cannot start {self.argv[0]!r}: {exc}") from exc
        self._stderr_task = asyncio.get_running_loop().create_task(self._read_stderr(self._proc))
        try:
            line = await self._readline(HELLO_TIMEOUT)
        except TimeoutError:
            await self.stop()
            raise HarnessError(f"no hello line within {HELLO_TIMEOUT:g} s{self._stderr_hint()}") from None
        if line is None:
            await self.stop()
            raise HarnessError(f"the harness exited before its hello{self._stderr_hint()}")
        try:
            hello = parse_hello(line)
        except ContractError as exc:
            await self.stop()
            raise HarnessError(f"bad hello line {line[:200]!r}: {exc}") from None
        self.hello = hello
        return hello

    def _stderr_hint(self) -> str:
        tail = list(self._stderr)[-5:]
        return "; its stderr ends:\n  " + "\n  ".join(tail) if tail else ""

    async def _read_stderr(self, proc: asyncio.subprocess.Process) -> None:
        assert proc.stderr is not None
        with contextlib.suppress(Exception):
            while line := await proc.stderr.readline():
                self._stderr.append(line.decode(errors="replace").rstrip())

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

    async def run_case(self, instruction: Instruction, deadline: float) -> CaseRun:
        """Send the case and read its results until ``done`` (or a problem) within ``deadline`` s."""
        if self._proc is None or self._proc.returncode is not None:
            await self.start()
        run = CaseRun()
        self._stderr.clear()
        assert self._proc is not None and self._proc.stdin is not None
        try:
            self._proc.stdin.write(instruction.line())
            await self._proc.stdin.drain()
        except (ConnectionError, OSError) as exc:
            run.problem = HarnessProblem("crashed", f"could not write the case to its stdin: {exc}")
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
                await asyncio.sleep(0)  # let the exit status arrive
                code = self._proc.returncode
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

    async def _finish_bad(self, run: CaseRun) -> None:
        await self.kill()
        run.stderr = list(self._stderr)

    async def stop(self) -> None:
        """Close its stdin, wait a little for it to exit, then kill it."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if proc.returncode is None:
            with contextlib.suppress(Exception):
                assert proc.stdin is not None
                proc.stdin.close()
            try:
                async with asyncio.timeout(EXIT_GRACE):
                    await proc.wait()
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    proc.kill()
                await proc.wait()
        if self._stderr_task is not None:
            with contextlib.suppress(Exception):
                async with asyncio.timeout(1.0):
                    await self._stderr_task
            self._stderr_task = None

    async def kill(self) -> None:
        """Stop at once (a hung or garbled harness: no grace)."""
        proc = self._proc
        if proc is not None and proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                proc.kill()
        await self.stop()
