"""Add messages to an ``mcap`` :class:`~mcap.writer.Writer`'s open chunk without its per-message overhead.

Why: ``Writer.add_message`` builds a ``Message`` record object, then writes it field by field through a
record builder (about 25 Python calls a message), and a recorder writes two messages a frame (the raw
frame and its JSON view).  That was the largest single cost of recording.

How: :func:`message_adder` gives a :class:`MessageAppender`'s ``add`` and ``add_pair``, which do the
bookkeeping ``add_message`` does (file statistics, the chunk's time range, its message index, closing a
chunk once it exceeds the chunk size) on the writer's own state and write each message record with one
``struct.pack``; message indexes are written with one ``struct.pack`` each too.  The file is byte for
byte the one ``add_message`` writes (a property test holds it to that).  The writer's state is internal
to ``mcap`` (checked against 1.6): when it is not what the appender expects, :func:`message_adder` gives
``add_message`` instead, so a different ``mcap`` costs speed, never a wrong file.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from io import BytesIO
from itertools import chain
from typing import Any, Final

from mcap._chunk_builder import ChunkBuilder
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import MessageIndex, Statistics
from mcap.writer import Writer

_MESSAGE: Final = struct.Struct("<BQHIQQ")
"""A message record's opcode and length, then channel id, sequence, log time and publish time."""
_MESSAGE_FIXED: Final = _MESSAGE.size - 9
"""Bytes of a message record after its length field, besides the data."""
_OPCODE: Final = int(Opcode.MESSAGE)
_INDEX_HEAD: Final = struct.Struct("<BQHI")
"""A message index record's opcode and length, then channel id and the byte length of its entries."""


class _MessageIndex(MessageIndex):
    """A chunk's message index for one channel, written with one ``struct.pack`` of all its entries
    rather than two calls per entry (the same bytes)."""

    def write(self, stream: RecordBuilder) -> None:
        records = self.records
        entries = struct.pack(f"<{2 * len(records)}Q", *chain.from_iterable(records))
        head = _INDEX_HEAD.pack(int(Opcode.MESSAGE_INDEX), 6 + len(entries), self.channel_id, len(entries))
        stream.write(head)
        stream.write(entries)


AddMessage = Callable[[int, int, bytes, int], None]
"""``add(channel, t, data, sequence)``: one message with log and publish time ``t``."""
AddPair = Callable[[int, bytes, int, bytes, int, int], None]
"""``add_pair(channel, data, channel2, data2, t, sequence)``: two messages with the same times and sequence
(a frame and its view), in that order."""


def message_adder(writer: Writer) -> tuple[AddMessage, AddPair, bool]:
    """Functions adding one and two messages to ``writer`` (chunked), and whether they are the fast ones."""
    internals = _internals(writer)
    if internals is None:

        def add_message(channel: int, t: int, data: bytes, sequence: int) -> None:
            writer.add_message(channel, t, data, t, sequence)

        def add_pair(channel: int, data: bytes, channel2: int, data2: bytes, t: int, sequence: int) -> None:
            writer.add_message(channel, t, data, t, sequence)
            writer.add_message(channel2, t, data2, t, sequence)

        return add_message, add_pair, False
    appender = MessageAppender(*internals)
    return appender.add, appender.add_pair, True


class MessageAppender:
    """Writes messages into a chunked ``mcap`` Writer's state as ``add_message`` would."""

    __slots__ = ("_chunk", "_chunk_size", "_finalize", "_stats")

    def __init__(
        self, chunk: ChunkBuilder, stats: Statistics, chunk_size: int, finalize: Callable[[], Any]
    ) -> None:
        self._chunk = chunk
        self._stats = stats
        self._chunk_size = chunk_size
        self._finalize = finalize

    def add(self, channel: int, t: int, data: bytes, sequence: int) -> None:
        """One message on ``channel`` with log and publish time ``t``."""
        stats = self._stats
        if stats.message_count == 0 or t < stats.message_start_time:
            stats.message_start_time = t
        stats.message_end_time = max(stats.message_end_time, t)
        stats.channel_message_counts[channel] += 1
        stats.message_count += 1
        chunk = self._chunk
        if chunk.num_messages == 0 or t < chunk.message_start_time:
            chunk.message_start_time = t
        chunk.message_end_time = max(chunk.message_end_time, t)
        buffer: BytesIO = chunk.record_writer._buffer
        offset = buffer.tell()
        index = chunk.message_indices.get(channel)
        if index is None:
            index = chunk.message_indices[channel] = _MessageIndex(channel_id=channel, records=[])
        index.records.append((t, offset))
        chunk.num_messages += 1
        buffer.write(_MESSAGE.pack(_OPCODE, _MESSAGE_FIXED + len(data), channel, sequence, t, t))
        buffer.write(data)
        if offset + _MESSAGE.size + len(data) > self._chunk_size:
            self._finalize()

    def add_pair(self, channel: int, data: bytes, channel2: int, data2: bytes, t: int, sequence: int) -> None:
        """:meth:`add` of both messages, sharing the bookkeeping."""
        chunk = self._chunk
        buffer: BytesIO = chunk.record_writer._buffer
        offset = buffer.tell()
        end = offset + _MESSAGE.size + len(data)
        if end > self._chunk_size:  # the first message closes the chunk: the second starts a new one
            self.add(channel, t, data, sequence)
            self.add(channel2, t, data2, sequence)
            return
        stats = self._stats
        if stats.message_count == 0 or t < stats.message_start_time:
            stats.message_start_time = t
        stats.message_end_time = max(stats.message_end_time, t)
        counts = stats.channel_message_counts
        counts[channel] += 1
        counts[channel2] += 1
        stats.message_count += 2
        if chunk.num_messages == 0 or t < chunk.message_start_time:
            chunk.message_start_time = t
        chunk.message_end_time = max(chunk.message_end_time, t)
        chunk.num_messages += 2
        indexes = chunk.message_indices
        index = indexes.get(channel)
        if index is None:
            index = indexes[channel] = _MessageIndex(channel_id=channel, records=[])
        index.records.append((t, offset))
        index = indexes.get(channel2)
        if index is None:
            index = indexes[channel2] = _MessageIndex(channel_id=channel2, records=[])
        index.records.append((t, end))
        pack = _MESSAGE.pack
        buffer.write(
            b"".join(
                (
                    pack(_OPCODE, _MESSAGE_FIXED + len(data), channel, sequence, t, t),
                    data,
                    pack(_OPCODE, _MESSAGE_FIXED + len(data2), channel2, sequence, t, t),
                    data2,
                )
            )
        )
        if end + _MESSAGE.size + len(data2) > self._chunk_size:
            self._finalize()


def _internals(writer: Writer) -> tuple[ChunkBuilder, Statistics, int, Callable[[], Any]] | None:
    """The writer's chunk builder, statistics, chunk size and chunk-closing method, if as expected."""
    chunk = getattr(writer, "_Writer__chunk_builder", None)
    stats = getattr(writer, "_Writer__statistics", None)
    size = getattr(writer, "_Writer__chunk_size", None)
    finalize = getattr(writer, "_Writer__finalize_chunk", None)
    if not (
        isinstance(chunk, ChunkBuilder)
        and isinstance(stats, Statistics)
        and isinstance(size, int)
        and callable(finalize)
        and isinstance(getattr(chunk.record_writer, "_buffer", None), BytesIO)
        and isinstance(getattr(chunk, "message_indices", None), dict)
        and isinstance(getattr(chunk, "num_messages", None), int)
        and isinstance(getattr(chunk, "message_start_time", None), int)
        and isinstance(getattr(chunk, "message_end_time", None), int)
    ):
        return None
    return chunk, stats, size, finalize
