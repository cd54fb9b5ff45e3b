"""The chaosd daemon stand-in for tests: :class:`~manip.links.chaosd_router.ChaosdRouter` in a short
temporary directory (Unix socket paths are limited to about 100 bytes)."""

from __future__ import annotations

import contextlib
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path

from manip.links.chaosd_router import ChaosdRouter

KEEP = 1000
"""Frames the router keeps for a test to read."""


@contextlib.asynccontextmanager
async def chaosd_router(name: str = "chaosd_server") -> AsyncIterator[tuple[Path, ChaosdRouter]]:
    """A router listening on a socket file in a fresh temporary directory: (its path, the router)."""
    with tempfile.TemporaryDirectory(prefix="chaosd", dir="/tmp") as directory:
        path = Path(directory) / name
        async with ChaosdRouter(str(path), keep=KEEP) as router:
            yield path, router
