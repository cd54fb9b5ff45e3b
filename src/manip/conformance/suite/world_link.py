"""The suite's side of contract 2 (``docs/world-harness.md``): a world reached over JSON Lines.

:func:`open_world` reads ``--world``: ``tcp://HOST:PORT`` connects to a world that listens (the reference
server's: ``manip-server --world tcp://127.0.0.1:0``); ``prompt`` asks an operator at a terminal
(:mod:`manip.conformance.suite.world_prompt`); anything else is a command line the suite starts, whose
stdin and stdout carry the messages (its stderr is the world's log, left on the terminal).

Every read is bounded: a line is at most :data:`MAX_LINE` bytes, ``hello`` must come within
:data:`HELLO_TIMEOUT` seconds and each answer within the time the message allows.  A world that
breaks the contract (garbage, a wrong id, silence, an early exit) raises
:class:`~manip.conformance.suite.world.WorldError` with what it did; after one such error the world is
not asked again in the run.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import shlex
from collections.abc import AsyncIterator
from typing import Any, Final

from manip.conformance.suite.world import Condition, ConditionUnsupported, WorldError
from manip.conformance.suite.world_prompt import PromptWorld
from manip.links.address import AddressError, parse_address

__all__ = ["CONTRACT", "HELLO_TIMEOUT", "MAX_LINE", "ContractWorld", "open_world"]

CONTRACT: Final = 2
MAX_LINE: Final = 65536
"""Bytes of one JSON line, its newline included, the suite reads at most."""
HELLO_TIMEOUT: Final = 10.0
"""Seconds a world has to say hello."""
DEFAULT_ANSWER_TIMEOUT: Final = 30.0
"""Seconds a machine world has to answer an arrange or a clear (``--world-timeout``)."""
EXIT_GRACE: Final = 5.0
"""Seconds a world command has to exit once its stdin is closed, before it is killed."""


class ContractWorld:
    """A world of contract 2 over a reader and a writer; see the module docstring."""

    def __init__(
        self,
        where: str,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        *,
        answer_timeout: float = DEFAULT_ANSWER_TIMEOUT,
    ) -> None:
        self.where = where
        self._reader = reader
        self._writer = writer
        self._timeout = answer_timeout
        self._next_id = 1
        self._lock = asyncio.Lock()
        self._broken: str | None = None
        self.name = ""
        self.version = ""
        self.conditions: frozenset[str] = frozenset()

    @property
    def description(self) -> str:
        return f"the world {self.where} ({self.name} {self.version})".replace(" ()", "")

    async def hello(self) -> None:
        """Read and check the world's ``hello``."""
        message = await self._read(HELLO_TIMEOUT, "hello")
        if message.get("type") != "hello":
            raise self._break(f"its first message is not hello: {_shown(message)}")
        if message.get("contract") != CONTRACT:
            raise self._break(
                f"it speaks contract {message.get('contract')!r}, this suite contract {CONTRACT}"
            )
        conditions = message.get("conditions")
        if not isinstance(conditions, list) or not all(isinstance(c, str) for c in conditions):
            raise self._break(f"its hello has no conditions array: {_shown(message)}")
        self.name = str(message.get("name", ""))
        self.version = str(message.get("version", ""))
        self.conditions = frozenset(conditions)

    @contextlib.asynccontextmanager
    async def arranged(self, condition: Condition) -> AsyncIterator[None]:
        if condition.name not in self.conditions:
            raise ConditionUnsupported(condition, f"{self.description} does not list it in its hello")
        answer, ident = await self._ask(
            {"type": "arrange", "condition": condition.name, "args": condition.args()}, "arranged"
        )
        if answer.get("type") == "unsupported":
            raise ConditionUnsupported(condition, str(answer.get("reason", "no reason given")))
        clear = {"type": "clear", "arrangement": ident}
        try:
            yield
        except BaseException:
            # The case's own end comes first; a world that cannot clear is reported by the next case.
            with contextlib.suppress(WorldError):
                await self._ask(clear, "cleared")
            raise
        await self._ask(clear, "cleared")

    async def _ask(self, message: dict[str, Any], wanted: str) -> tuple[dict[str, Any], int]:
        """Send ``message`` with a fresh id; its answer (``wanted``, or ``unsupported`` for an arrange)."""
        async with self._lock:
            if self._broken is not None:
                raise WorldError(f"{self.where} failed earlier in the run: {self._broken}")
            ident = self._next_id
            self._next_id += 1
            message = {**message, "id": ident, "timeout": self._timeout}
            try:
                self._writer.write((json.dumps(message) + "\n").encode())
                await self._writer.drain()
            except (OSError, RuntimeError) as exc:
                raise self._break(f"it cannot be written to: {exc}") from None
            answer = await self._read(self._timeout, f"answer to {message['type']} #{ident}")
            kinds = {wanted, "failed"} | ({"unsupported"} if wanted == "arranged" else set())
            if answer.get("id") != ident or answer.get("type") not in kinds:
                raise self._break(f"it answered {message['type']} #{ident} with {_shown(answer)}")
            if answer.get("type") == "failed":
                problem = f"it could not {message['type']}: {answer.get('reason', '')}"
                if message["type"] == "clear":  # the condition may still hold: ask it nothing more
                    raise self._break(problem)
                raise WorldError(f"{self.where}: {problem}")
            return answer, ident

    async def _read(self, timeout: float, what: str) -> dict[str, Any]:
        try:
            async with asyncio.timeout(timeout):
                raw = await self._reader.readuntil(b"\n")
        except TimeoutError:
            raise self._break(f"no {what} within {timeout:g} s") from None
        except asyncio.IncompleteReadError as exc:
            tail = f" after {exc.partial[:80]!r}" if exc.partial else ""
            raise self._break(f"it ended before {what}{tail}") from None
        except asyncio.LimitOverrunError:
            raise self._break(f"{what} is a line longer than {MAX_LINE} bytes") from None
        except OSError as exc:
            raise self._break(f"reading {what}: {exc}") from None
        try:
            message = json.loads(raw)
        except ValueError:
            raise self._break(f"{what} is not JSON: {raw[:80]!r}") from None
        if not isinstance(message, dict):
            raise self._break(f"{what} is not a JSON object: {raw[:80]!r}")
        return message

    def _break(self, problem: str) -> WorldError:
        self._broken = problem
        return WorldError(f"{self.where}: {problem}")

    async def aclose(self) -> None:
        with contextlib.suppress(OSError, RuntimeError):
            self._writer.close()
            await asyncio.wait_for(self._writer.wait_closed(), EXIT_GRACE)


def _shown(message: object) -> str:
    text = json.dumps(message)
    return text if len(text) <= 120 else text[:117] + "..."


@contextlib.asynccontextmanager
async def open_world(
    spec: str, *, answer_timeout: float = DEFAULT_ANSWER_TIMEOUT
) -> AsyncIterator[ContractWorld | PromptWorld]:
    """``async with open_world(spec) as world:`` the world ``--world spec`` names, its hello read.
    WorldError when it cannot be reached or breaks the contract at once."""
    if spec == "prompt":
        yield PromptWorld(answer_timeout=answer_timeout)
        return
    if spec.startswith("tcp://"):
        async with _tcp_world(spec, answer_timeout) as world:
            yield world
        return
    async with _command_world(spec, answer_timeout) as world:
        yield world


@contextlib.asynccontextmanager
async def _tcp_world(url: str, answer_timeout: float) -> AsyncIterator[ContractWorld]:
    try:
        address = parse_address(url)
    except AddressError as exc:
        raise WorldError(f"--world {url}: {exc}") from None
    try:
        async with asyncio.timeout(HELLO_TIMEOUT):
            reader, writer = await asyncio.open_connection(address.host, address.port, limit=MAX_LINE)
    except (OSError, TimeoutError) as exc:
        raise WorldError(f"the world at {url} cannot be reached: {exc or 'timed out'}") from None
    world = ContractWorld(url, reader, writer, answer_timeout=answer_timeout)
    try:
        await world.hello()
        yield world
    finally:
        await world.aclose()


@contextlib.asynccontextmanager
async def _command_world(command: str, answer_timeout: float) -> AsyncIterator[ContractWorld]:
    try:
        argv = shlex.split(command)
    except ValueError as exc:
        raise WorldError(f"--world {command!r} is not a command line: {exc}") from None
    if not argv:
        raise WorldError("--world names no command")
    try:
        process = await asyncio.create_subprocess_exec(
            *argv, stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE, limit=MAX_LINE
        )
    except OSError as exc:
        raise WorldError(f"the world command {argv[0]!r} cannot be started: {exc}") from None
    assert process.stdout is not None and process.stdin is not None
    world = ContractWorld(f"command {argv[0]}", process.stdout, process.stdin, answer_timeout=answer_timeout)
    try:
        await world.hello()
        yield world
    finally:
        await world.aclose()
        try:
            await asyncio.wait_for(process.wait(), EXIT_GRACE)
        except TimeoutError:
            process.kill()
            await process.wait()
        # What it wrote and nobody read (a dead process writes no more): the pipe then closes.
        with contextlib.suppress(OSError, ValueError, TimeoutError, asyncio.LimitOverrunError):
            while await asyncio.wait_for(process.stdout.read(MAX_LINE), EXIT_GRACE):
                pass
