"""``--world prompt``: an operator at a terminal is the world.

For each condition a case needs, the suite says what to arrange, where, and how it will be cleared, then
waits for the operator to type Enter (arranged) or ``n`` and Enter (cannot: the case is not judged), with
a time limit (``--world-timeout``); when the case is done it asks for the condition to be cleared and
waits again.  The operator's waiting time is kept off the case's deadline.

It needs a terminal: :func:`check_terminal` refuses a run whose standard input or error is not one, so
a CI job never hangs on a question nobody sees.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from collections.abc import AsyncIterator
from typing import Final, TextIO

from manip.conformance.suite.world import Condition, ConditionUnsupported, WorldError

__all__ = ["PROMPT_TIMEOUT", "PromptWorld", "check_terminal"]

PROMPT_TIMEOUT: Final = 300.0
"""Seconds the operator has to answer, by default."""
MAX_ANSWER: Final = 1024
"""Bytes of an answer read at most."""


def check_terminal() -> str | None:
    """Why ``--world prompt`` cannot run here (None when it can)."""
    if not sys.stdin.isatty() or not sys.stderr.isatty():
        return (
            "--world prompt asks an operator at a terminal, and standard input or standard error is not a "
            "terminal: run it from a terminal, or give a world command or URL (docs/world-harness.md)"
        )
    return None


class PromptWorld:
    """A world whose conditions an operator arranges by hand; see the module docstring."""

    description = "the operator"

    def __init__(
        self, *, answer_timeout: float = PROMPT_TIMEOUT, out: TextIO | None = None, fd: int | None = None
    ) -> None:
        self._timeout = answer_timeout
        self._out = out or sys.stderr
        self._fd = sys.stdin.fileno() if fd is None else fd
        self._lock = asyncio.Lock()

    @contextlib.asynccontextmanager
    async def arranged(self, condition: Condition) -> AsyncIterator[None]:
        async with self._lock:
            answer = await self._ask(
                f"ARRANGE {condition.describe()}.\n"
                f"  (it will be cleared afterwards: {condition.how_to_clear()})\n"
                f"  Press Enter once it holds, or type n and Enter if you cannot "
                f"({self._timeout:g} s): "
            )
            if answer.strip().lower() in ("n", "no"):
                raise ConditionUnsupported(condition, "the operator could not arrange it")
        try:
            yield
        finally:
            async with self._lock:
                await self._ask(
                    f"CLEAR: {condition.how_to_clear()}.\n  Press Enter once done ({self._timeout:g} s): "
                )

    async def _ask(self, question: str) -> str:
        self._out.write("\n" + question)
        self._out.flush()
        loop = asyncio.get_running_loop()
        got: asyncio.Future[bytes] = loop.create_future()

        def readable() -> None:
            try:
                data = os.read(self._fd, MAX_ANSWER)
            except OSError as exc:
                if not got.done():
                    got.set_exception(WorldError(f"the terminal cannot be read: {exc}"))
                return
            if not got.done():
                got.set_result(data)

        loop.add_reader(self._fd, readable)
        try:
            async with asyncio.timeout(self._timeout):
                data = await got
        except TimeoutError:
            raise WorldError(f"the operator did not answer within {self._timeout:g} s") from None
        finally:
            loop.remove_reader(self._fd)
        if not data:
            raise WorldError("the terminal's input ended (end of file) before the operator answered")
        return data.decode("utf-8", "replace")
