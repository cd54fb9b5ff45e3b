"""The Puma's DRV-11J port over TCP: an asyncio driver for :class:`manip.cougar.link.PumaEnd`.

:class:`Drv11jPort` is a :class:`~manip.reference_server.cougar_port.CougarPort` (by shape) for an
external Cougar such as ``manip-cougar --listen tcp://HOST:PORT``.  Its methods never block, so the
sans-I/O wrist processes can call them from the server's servo tick: words and ticks are written to the
socket at once (or buffered until it is connected), and a reader task collects Cougar's words for
:meth:`Drv11jPort.receive`.  Connection failures and a broken stream set :attr:`Drv11jPort.error`; the
wrist then answers requests with ``wrist: E WLK``.

Make one inside a running event loop (``Drv11jPort(address)``, connecting in the background) or with
``await Drv11jPort.open(address)``, which waits until Cougar has said HELLO.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Sequence
from typing import Final

from manip.cougar.link import Drv11jError, PumaEnd, parse_drv11j_address

__all__ = ["CONNECT_TIMEOUT", "Drv11jPort"]

CONNECT_TIMEOUT: Final = 5.0
_READ: Final = 1 << 16


class Drv11jPort:
    """The Puma's end of an emulated DRV-11J at ``address`` (``tcp://HOST:PORT``)."""

    def __init__(self, address: str, *, connect_timeout: float = CONNECT_TIMEOUT) -> None:
        self.address = address
        self.host, self.port = parse_drv11j_address(address)
        self.connect_timeout = connect_timeout
        self.end = PumaEnd()
        self._inbox: list[int] = []
        self._outbox: list[bytes] = [self.end.hello()]
        self._writer: asyncio.StreamWriter | None = None
        self._error: str | None = None
        self._ready = asyncio.Event()
        self._task = asyncio.get_running_loop().create_task(self._run(), name=f"drv11j {address}")

    @classmethod
    async def open(cls, address: str, *, connect_timeout: float = CONNECT_TIMEOUT) -> Drv11jPort:
        """Connect and wait for Cougar's HELLO; raises ConnectionError when that fails."""
        port = cls(address, connect_timeout=connect_timeout)
        try:
            await port.wait_ready()
        except BaseException:
            port.close()
            raise
        return port

    async def wait_ready(self) -> None:
        """Until Cougar's HELLO has arrived (ConnectionError if the link failed first)."""
        waiter = asyncio.ensure_future(self._ready.wait())
        done, _ = await asyncio.wait(
            {waiter, self._task}, timeout=self.connect_timeout, return_when="FIRST_COMPLETED"
        )
        if waiter not in done:
            waiter.cancel()
            raise ConnectionError(self._error or f"{self.address}: no HELLO within {self.connect_timeout} s")

    # ------------------------------------------------------------------------------ CougarPort
    def send(self, words: Sequence[int]) -> None:
        self._write(self.end.send(words))

    def tick(self, now: float) -> None:
        self._write(self.end.tick(now))

    def receive(self) -> list[int]:
        out, self._inbox = self._inbox, []
        return out

    @property
    def error(self) -> str | None:
        return self._error

    def close(self) -> None:
        if self._error is None:
            self._error = "link closed"
        writer = self._writer
        if writer is not None and not writer.is_closing():
            with contextlib.suppress(Exception):
                writer.write(self.end.bye("Puma closed the link"))
            writer.close()
        self._task.cancel()

    @property
    def ticks_done(self) -> int:
        """Ticks Cougar has reported run."""
        return self.end.ticks_done

    # ---------------------------------------------------------------------------- the driver
    def _write(self, data: bytes) -> None:
        if not data or self._error is not None:
            return
        if self._writer is None:
            self._outbox.append(data)
        else:
            self._writer.write(data)

    async def _run(self) -> None:
        try:
            async with asyncio.timeout(self.connect_timeout):
                reader, writer = await asyncio.open_connection(self.host, self.port)
            self._writer = writer
            writer.write(b"".join(self._outbox))
            self._outbox.clear()
            while True:
                data = await reader.read(_READ)
                if not data:
                    self._fail(self.end.closed or "Cougar closed the link")
                    return
                self._inbox.extend(self.end.receive(data))
                if self.end.peer_ready:
                    self._ready.set()
                if self.end.closed is not None:
                    self._fail(self.end.closed)
                    return
        except (OSError, TimeoutError, Drv11jError) as exc:
            self._fail(f"{self.address}: {exc or type(exc).__name__}")
        finally:
            if self._writer is not None:
                self._writer.close()

    def _fail(self, reason: str) -> None:
        if self._error is None:
            self._error = reason
