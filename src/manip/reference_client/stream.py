"""Asynchronous responses (guard hits, completed segments) as an async iterator."""

from __future__ import annotations

import asyncio
from types import TracebackType

from manip.codecs.messages import AsyncResponse
from manip.reference_client.background import BackgroundProcess
from manip.reference_client.errors import ManipError


class AsyncResponseStream:
    """Every asynchronous response from the moment the stream is made, in order.

    Iteration ends when the stream is closed or the user closes the connection; if the connection is
    lost (or a fatal error ends it) the next ``__anext__`` raises that error once the responses that
    came before it are consumed.  Nothing is dropped: the stream buffers without limit, so close a
    stream you stop reading.
    """

    def __init__(self, process: BackgroundProcess) -> None:
        self._process = process
        self._queue: asyncio.Queue[AsyncResponse | None] = asyncio.Queue()
        self._error: ManipError | None = None
        self._finished = False
        self._remove_async = process.add_async_listener(self._queue.put_nowait)
        self._remove_close = process.add_close_listener(self._ended)

    def _ended(self, error: ManipError) -> None:
        if not self._process.closed_by_user:
            self._error = error
        self._queue.put_nowait(None)

    def close(self) -> None:
        """Stop listening; a pending ``__anext__`` ends the iteration."""
        self._remove_async()
        self._remove_close()
        self._queue.put_nowait(None)

    def __aiter__(self) -> AsyncResponseStream:
        return self

    async def __anext__(self) -> AsyncResponse:
        if self._finished:
            raise StopAsyncIteration
        item = await self._queue.get()
        if item is not None:
            return item
        self._finished = True
        self.close()
        if self._error is not None:
            raise self._error
        raise StopAsyncIteration

    async def __aenter__(self) -> AsyncResponseStream:
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
