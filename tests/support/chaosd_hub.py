"""A chaosd stand-in for tests: a Unix-domain socket whose every frame goes to each other host on it.

usim's chaosd routes; with two hosts on the socket (a server and the suite's probe, or a client and a
server) handing each frame to the other is the same thing.  :func:`chaosd_hub` runs one in a short
temporary directory (Unix socket paths are limited to about 100 bytes) and yields its socket's path.
"""

from __future__ import annotations

import asyncio
import contextlib
import tempfile
from collections.abc import AsyncIterator
from pathlib import Path


class Hub:
    """Reads frames by their 4-byte header and hands each to every other client; ``frames`` keeps them."""

    def __init__(self) -> None:
        self.clients: list[asyncio.StreamWriter] = []
        self.frames: list[bytes] = []

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.clients.append(writer)
        try:
            while True:
                header = await reader.readexactly(4)
                assert header[2:] == b"\x01\x00"
                body = await reader.readexactly(header[0] << 8 | header[1])
                self.frames.append(header + body)
                for other in self.clients:
                    if other is not writer:
                        other.write(header + body)
        except (asyncio.IncompleteReadError, ConnectionError):
            pass
        finally:
            self.clients.remove(writer)
            writer.close()


@contextlib.asynccontextmanager
async def chaosd_hub(name: str = "chaosd_server") -> AsyncIterator[tuple[Path, Hub]]:
    """A hub listening on a socket file in a fresh temporary directory: (its path, the hub)."""
    with tempfile.TemporaryDirectory(prefix="chaosd", dir="/tmp") as directory:
        path = Path(directory) / name
        hub = Hub()
        daemon = await asyncio.start_unix_server(hub.handle, str(path))
        async with daemon:
            yield path, hub
            daemon.close()
