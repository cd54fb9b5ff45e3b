"""One rule for a target still busy with the connection before: every opener of the suite retries alike.

A robot serves one client at a time: a manip server refuses a second RFC with CLS "Busy", a Cougar a
second link with its own busy BYE.  A case, a replay session or a fuzz batch opens its connection right
after the previous one closed, which the target may not have finished tearing down.  So every opener
(the case runner, the raw Chaos peer, replay, the fuzzer, the Cougar probe) retries a refusal that says
busy every :data:`BUSY_DELAY` seconds for :data:`BUSY_PATIENCE` seconds, and no longer: a target that
is busy for longer has another client, which is the user's to know.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from typing import Final, TypeVar

from manip.links import ConnectionRefused

__all__ = ["BUSY_DELAY", "BUSY_PATIENCE", "BUSY_RETRIES", "open_retrying_busy", "says_busy"]

T = TypeVar("T")

BUSY_DELAY: Final = 0.05
"""Seconds between two attempts."""
BUSY_PATIENCE: Final = 5.0
"""Seconds a target may stay busy before the refusal is final."""
BUSY_RETRIES: Final = round(BUSY_PATIENCE / BUSY_DELAY)
"""Attempts after the first, for openers that count them."""


def says_busy(reason: str | None) -> bool:
    """Whether a refusal's reason says the target is busy (with whatever case the target writes it)."""
    return reason is not None and "busy" in reason.lower()


async def open_retrying_busy(open_: Callable[[], Awaitable[T]], *, retry: bool = True) -> T:
    """``open_()``, again after a :class:`~manip.links.ConnectionRefused` that says busy (unless
    ``retry`` is false); any other refusal, or a busy one past the patience, is raised."""
    for attempt in range(BUSY_RETRIES + 1 if retry else 1):
        try:
            return await open_()
        except ConnectionRefused as exc:
            if not retry or attempt == BUSY_RETRIES or not says_busy(exc.reason):
                raise
            await asyncio.sleep(BUSY_DELAY)
    raise AssertionError("unreachable")
