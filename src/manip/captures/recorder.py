"""Write captures: :class:`Recorder` turns frames and packets of any number of links into an MCAP file.

The file layout is :mod:`manip.captures.format`'s.  Every frame goes to the raw channel of its link and
direction (the source of truth) and, unless ``decoded_view=False``, to the decoded JSON view, with the
same ``log_time`` and ``sequence``.  Connection events found by the :class:`~manip.captures.view.Annotator`
and link events given by the caller go to ``/manip/events``.

Durability: chunks are closed and written (``Writer.flush``) at least every ``flush_interval`` seconds
while anything is pending: on the next write once the interval has passed, and from a timer on the
running event loop when the recorder was made inside one (so an idle session is written too).  A
recorder killed without :meth:`Recorder.close` loses at most the last interval; ``manip-capture
recover`` rebuilds the file's index (:mod:`manip.captures.recover`).

Speed (``bench/capture.py``): each frame is decoded once (the framing's body decoder called directly,
:class:`OneFrameDecoder`), annotated once (fast numeric layouts, :mod:`manip.codecs.fastpath`), its view
written straight to JSON text (:func:`~manip.captures.view.view_bytes`), and both messages added by
:mod:`manip.captures.appender` (the bytes ``Writer.add_message`` would write, at a fraction of the cost).
With the view, frames wait in a batch of up to :data:`BATCH` and go through those steps a step at a
time: the same work runs about a third faster than frame by frame, as each step's code stays hot.  The
batch is written before anything else is (an event, a flush, the end), so the file is the same one,
message for message; a batch is held no longer than the chunk it goes into, which is only on disk
after the next flush anyway.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import os
import shlex
import sys
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import IO, Any, Final, cast

import mcap
from mcap.writer import CompressionType, Writer

from manip import __version__
from manip.codecs.chaos import decode_raw, encode_raw
from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.framing import (
    ChaosdFrameDecoder,
    StreamDecoder,
    TcpFrameDecoder,
    decode_chaosd,
    decode_chudp,
    decode_tcp,
    encode_chaosd,
    encode_chudp,
    encode_tcp,
)
from manip.codecs.packet import Direction, Packet
from manip.spec import SPEC

from .appender import message_adder
from .arm_view import (
    FRAME_TRANSFORM_SCHEMA,
    HAND_TOPIC,
    JOINTS_SCHEMA,
    POSE_OPS,
    arm_messages,
    frame_transform_schema,
    joints_schema,
)
from .format import (
    DIRECTIONS,
    EVENT_SCHEMA_NAME,
    EVENT_TOPIC,
    METADATA_NAME,
    PROFILE,
    RAW_MESSAGE_ENCODING,
    RAW_SCHEMA_ENCODING,
    RAW_SCHEMA_PREFIX,
    RAW_TOPIC,
    VIEW_SCHEMA_NAME,
    VIEW_TOPIC,
    event_schema,
    raw_schema,
    view_schema,
)
from .view import Annotation, Annotator, bad_frame, view_bytes

log = logging.getLogger("manip.captures")

LIBRARY: Final = f"manip {__version__} (mcap {getattr(mcap, '__version__', '?')})"
DEFAULT_CHUNK_SIZE: Final = 256 * 1024
"""Uncompressed bytes per chunk before it is closed anyway (a chunk is also closed every flush)."""
DEFAULT_FLUSH_INTERVAL: Final = 1.0
COMPRESSIONS: Final = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}


class OneFrameDecoder:
    """Decodes single frames of a stream framing.  A frame that is exactly one whole frame (the recorder
    and reader only ever see those) goes straight to the framing decoder's own length check and body
    decoder: feeding a stream decoder costs more than the decoding.  Anything else is fed to a fresh
    stream decoder, which says precisely what is wrong; error offsets are within the frame either way."""

    __slots__ = ("_body", "_factory", "_length", "_prefix")

    def __init__(self, factory: Callable[[], StreamDecoder]) -> None:
        self._factory = factory
        decoder = factory()
        self._prefix = decoder.prefix
        # The decoder's hooks for its subclasses, called directly: they hold the framing's checks.
        self._length = decoder._body_length
        self._body = decoder._decode

    def __call__(self, frame: bytes) -> Packet:
        prefix = self._prefix
        size = len(frame)
        if size > prefix:
            try:
                whole = self._length(frame, 0, 0) == size - prefix
            except DecodeError:
                whole = False
            if whole:
                return self._body(frame, prefix, size, prefix)
        decoder = self._factory()
        items = decoder.feed(frame)
        if len(items) == 1 and not decoder.pending and isinstance(items[0], Packet):
            return items[0]
        if len(items) == 1 and isinstance(items[0], DecodeError):
            raise items[0]
        raise DecodeError(f"expected one whole frame, got {len(items)} and {size} bytes", path="frame")


def frame_decoder(framing: str) -> Callable[[bytes], Packet]:
    """A single-frame decoder for ``framing`` (stream framings keep state: one per reader or link)."""
    if framing == "tcp":
        return OneFrameDecoder(TcpFrameDecoder)
    if framing == "chaosd":
        return OneFrameDecoder(ChaosdFrameDecoder)
    return FRAME_DECODERS[framing]


FRAME_DECODERS: Final[Mapping[str, Callable[[bytes], Packet]]] = {
    "tcp": decode_tcp,
    "chudp": decode_chudp,
    "chaosd": decode_chaosd,
    "raw": decode_raw,
}
"""One frame's bytes to its packet, per framing (checksums verified where the link verifies them)."""
FrameEncoder = Callable[..., bytes]
_FRAME_ENCODERS: Final[Mapping[str, FrameEncoder]] = {
    "tcp": encode_tcp,
    "chudp": encode_chudp,
    "chaosd": encode_chaosd,
}
_JSON: Final = json.JSONEncoder(separators=(",", ":"))
_OPCODE_BYTE: Final = {"tcp": 2, "chudp": 4, "chaosd": 5, "raw": 1}
"""Where each framing puts the Chaos opcode byte of a frame."""
BATCH: Final = 256
"""Frames waiting to be decoded, annotated and written together (see the module docstring)."""
_DATA: Final = Annotation(0, "data")
"""What a data packet is annotated with when no view is written (nothing reads it)."""


class CaptureError(Exception):
    """A capture cannot be written or read; the message says what to do."""


class _GuardedFile:
    """The recorder's file: the first write error (a full disk) is kept and what follows is dropped, so
    a failing disk never raises in the middle of a session (in a link's callback); the recorder logs
    it once and keeps it as :attr:`Recorder.write_error`.  Offsets count what was handed over, as the
    writer expects."""

    def __init__(self, raw: IO[bytes]) -> None:
        self.raw = raw
        self.error: OSError | None = None
        self.position = 0

    def write(self, data: bytes) -> int:
        if self.error is None:
            try:
                self.raw.write(data)
            except OSError as exc:
                self.error = exc
        self.position += len(data)
        return len(data)

    def tell(self) -> int:
        return self.position

    def flush(self) -> None:
        if self.error is None:
            try:
                self.raw.flush()
            except OSError as exc:
                self.error = exc

    def close(self) -> None:
        try:
            self.raw.close()
        except OSError as exc:
            if self.error is None:
                self.error = exc


@dataclass(slots=True)
class _Link:
    id: int
    framing: str
    name: str
    channels: dict[Direction, int]
    decode: Callable[[bytes], Packet]
    closed: bool = False


class Recorder:
    """An MCAP capture being written.  Use as a context manager, or call :meth:`close`.

    ``output`` is a path or a binary stream (left open).  ``seed`` and ``command_line`` go into the
    ``manip.capture`` metadata with the tool version and spec revision (``how`` says what recorded:
    ``proxy``, ``server``, ``client``...); ``metadata`` adds more string pairs; ``clock_ns`` gives the log
    times (see :attr:`clock_ns`)."""

    def __init__(
        self,
        output: str | os.PathLike[str] | IO[bytes],
        *,
        how: str = "library",
        seed: int | None = None,
        command_line: Sequence[str] | None = None,
        metadata: Mapping[str, str] | None = None,
        decoded_view: bool = True,
        arm_view: bool = True,
        compression: str = "zstd",
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        flush_interval: float = DEFAULT_FLUSH_INTERVAL,
        clock_ns: Callable[[], int] = time.time_ns,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise CaptureError(f"unknown compression {compression!r}; use one of {sorted(COMPRESSIONS)}")
        if not flush_interval > 0:
            raise CaptureError(f"flush_interval must be positive, not {flush_interval}")
        self._stream: IO[bytes]
        self._file: _GuardedFile | None
        if isinstance(output, (str, os.PathLike)):
            self.path: str | None = os.fspath(output)
            try:
                self._file = _GuardedFile(open(self.path, "wb"))  # noqa: SIM115  # closed by close()
            except OSError as exc:
                raise CaptureError(f"cannot write the capture {self.path}: {exc}") from exc
            self._stream = cast(IO[bytes], self._file)
            self._owns_stream = True
        else:
            self.path = None
            self._file = None
            self._stream = output
            self._owns_stream = False
        self.decoded_view = decoded_view
        self.arm_view = arm_view and decoded_view
        """Write ``/arm/hand`` and ``/arm/joints`` (:mod:`~manip.captures.arm_view`); they come from the
        decoded view's annotations, so only with it."""
        self._arm_channels: dict[str, int] = {}
        self._arm_seq = 0
        self.flush_interval = flush_interval
        self.clock_ns = clock_ns
        """Log times of what is recorded without a time of its own (Unix nanoseconds by default; a
        simulated run gives its virtual clock, so one seed records the same file)."""
        self._counts: Counter[str] = Counter()
        self.flushes = 0
        self._writer = Writer(self._stream, chunk_size=chunk_size, compression=COMPRESSIONS[compression])
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._add, self._add_pair, _ = message_adder(self._writer)
        self._writer.add_metadata(
            METADATA_NAME,
            {
                "tool": "manip",
                "tool_version": __version__,
                "spec_revision": SPEC.revision,
                "protocol_version": str(SPEC.protocol_version),
                "seed": "" if seed is None else str(seed),
                "command_line": shlex.join(sys.argv if command_line is None else command_line),
                "recorded_by": how,
                "decoded_view": "yes" if decoded_view else "no",
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                **(metadata or {}),
            },
        )
        self._raw_schemas: dict[str, int] = {}
        self._view_channels: dict[Direction, int] = {}
        if decoded_view:
            schema = self._writer.register_schema(
                VIEW_SCHEMA_NAME, "jsonschema", json.dumps(view_schema()).encode()
            )
            for d in DIRECTIONS:
                self._view_channels[d] = self._writer.register_channel(VIEW_TOPIC[d], "json", schema)
        events = self._writer.register_schema(
            EVENT_SCHEMA_NAME, "jsonschema", json.dumps(event_schema()).encode()
        )
        self._event_channel = self._writer.register_channel(EVENT_TOPIC, "json", events)
        self._links: dict[int, _Link] = {}
        self._batch: list[tuple[_Link, Direction, bytes, Packet | None, int]] = []
        self._annotator = Annotator()
        self._seq = 0
        self._event_seq = 0
        self._pending = False
        self._warned = False
        self._due = time.monotonic() + flush_interval
        self._closed = False
        self._timer: asyncio.TimerHandle | None = None
        try:
            self._loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            self._loop = None
        self.event("recording-started")
        self._arm_timer()

    def __repr__(self) -> str:  # no draining here: looking at a recorder must not write to its file
        waiting = f", {len(self._batch)} frames waiting" if self._batch else ""
        return f"<Recorder {self.path or self._stream!r} {sum(self._counts.values())} messages{waiting}>"

    @property
    def counts(self) -> Counter[str]:
        """Messages written per topic (frames still in the batch are written first)."""
        if self._batch:
            self._drain()
        return self._counts

    # ------------------------------------------------------------------------------ links

    def open_link(self, framing: str, *, name: str = "", t_ns: int | None = None) -> int:
        """Start recording a link whose frames are in ``framing``; returns its link id (from 1)."""
        if framing not in FRAME_DECODERS:
            raise CaptureError(f"unknown framing {framing!r}; use one of {sorted(FRAME_DECODERS)}")
        link_id = len(self._links) + 1
        self._links[link_id] = _Link(
            link_id, framing, name or f"{framing}-{link_id}", {}, frame_decoder(framing)
        )
        self.event("link-open", t_ns, link=link_id, framing=framing, name=name)
        return link_id

    def close_link(self, link: int, reason: str, t_ns: int | None = None) -> None:
        """Record that ``link`` closed, and why (once)."""
        info = self._links[link]
        if not info.closed:
            info.closed = True
            self.event("link-closed", t_ns, link=link, reason=reason)

    def framing_lost(self, link: int, direction: Direction, reason: str, t_ns: int | None = None) -> None:
        """A stream's frame boundaries are lost: nothing more of that direction can be recorded."""
        self.event("framing-lost", t_ns, link=link, direction=direction, reason=reason)

    # ------------------------------------------------------------------------------ frames

    def frame(self, link: int, direction: Direction, frame: bytes, t_ns: int | None = None) -> None:
        """Record one frame exactly as it crossed ``link``."""
        info = self._links[link]
        t = self.clock_ns() if t_ns is None else t_ns
        if self.decoded_view:
            self._enqueue(info, direction, frame, None, t)
            return
        at = _OPCODE_BYTE.get(info.framing)
        if at is not None and len(frame) > at and frame[at] >= 0o200:
            # Raw only: a data frame needs no decoding (the reader decodes and checks it).
            self._write(info, direction, frame, None, _DATA, t)
            return
        packet: Packet | None
        try:
            packet = info.decode(frame)
        except DecodeError as exc:
            packet = None
            annotation = bad_frame(exc)
        else:
            # Without the view only the connection events are needed: they come from control packets.
            annotation = self._annotate(link, direction, packet)
        self._write(info, direction, frame, packet, annotation, t)

    def _enqueue(
        self, info: _Link, direction: Direction, frame: bytes, packet: Packet | None, t: int
    ) -> None:
        if self._closed:
            raise CaptureError("the recorder is closed")
        batch = self._batch
        batch.append((info, direction, frame, packet, t))
        if len(batch) >= BATCH:
            self._drain()
        if time.monotonic() >= self._due:
            self.flush()

    def _drain(self) -> None:
        """Decode, annotate, view and write the batch, one step at a time over all of it."""
        batch = self._batch
        if not batch:
            return
        self._batch = []
        packets: list[Packet | None] = []
        bad: dict[int, Annotation] = {}
        for k, (info, _, frame, packet, _) in enumerate(batch):
            if packet is None:
                try:
                    packet = info.decode(frame)
                except DecodeError as exc:
                    bad[k] = bad_frame(exc)
            packets.append(packet)
        annotate = self._annotator.annotate
        annotations = [
            bad[k] if packet is None else annotate(item[0].id, item[1], packet)
            for k, (item, packet) in enumerate(zip(batch, packets, strict=True))
        ]
        first = self._seq + 1
        views = [
            view_bytes(
                annotation,
                info.id,
                direction,
                seq,
                packet,
                len(frame) if packet is None else len(packet.data),
            )
            for seq, (info, direction, frame, _, _), packet, annotation in zip(
                itertools.count(first), batch, packets, annotations
            )
        ]
        add_pair, view_channels = self._add_pair, self._view_channels
        for seq, (info, direction, frame, _, t), view, annotation in zip(
            itertools.count(first), batch, views, annotations
        ):
            channel = info.channels.get(direction)
            if channel is None:
                channel = info.channels[direction] = self._raw_channel(info, direction)
            add_pair(channel, frame, view_channels[direction], view, t, seq)
            for event in annotation.events:
                self._event(event, t)
            if annotation.op in POSE_OPS and self.arm_view:
                self._arm(annotation, info.id, t)
        self._seq += len(batch)
        c2s = sum(1 for item in batch if item[1] == "c2s")
        counts = self._counts
        for direction, n in (("c2s", c2s), ("s2c", len(batch) - c2s)):
            if n:
                counts[RAW_TOPIC[direction]] += n
                counts[VIEW_TOPIC[direction]] += n
        self._pending = True

    def _annotate(self, link: int, direction: Direction, packet: Packet) -> Annotation:
        # Without the view only the connection events are needed: they come from control packets.
        if self.decoded_view or packet.opcode < 0o200:
            return self._annotator.annotate(link, direction, packet)
        return _DATA

    def packet(
        self,
        link: int,
        direction: Direction,
        packet: Packet,
        *,
        hw_dest: int | None = None,
        hw_src: int | None = None,
        t_ns: int | None = None,
    ) -> None:
        """Record a packet a link sent or received, as the frame its link carries (trailer ``hw_dest``,
        ``hw_src``; for a received packet, the trailer it came with)."""
        info = self._links[link]
        encode = _FRAME_ENCODERS.get(info.framing)
        try:
            frame = encode_raw(packet) if encode is None else encode(packet, hw_dest=hw_dest, hw_src=hw_src)
        except EncodeError as exc:
            log.warning("%s: cannot record %r: %s", info.name, packet, exc)
            self._counts["unrecordable"] += 1
            return
        t = self.clock_ns() if t_ns is None else t_ns
        if self.decoded_view:
            self._enqueue(info, direction, frame, packet, t)
            return
        self._write(info, direction, frame, packet, self._annotate(link, direction, packet), t)

    def _write(
        self,
        info: _Link,
        direction: Direction,
        frame: bytes,
        packet: Packet | None,
        annotation: Annotation,
        t: int,
    ) -> None:
        """Write one frame without the view (with the view, frames go through the batch)."""
        if self._closed:
            raise CaptureError("the recorder is closed")
        self._seq += 1
        channel = info.channels.get(direction)
        if channel is None:
            channel = info.channels[direction] = self._raw_channel(info, direction)
        self._counts[RAW_TOPIC[direction]] += 1
        self._add(channel, t, frame, self._seq)
        for event in annotation.events:
            self._event(event, t)
        self._written()

    def _raw_channel(self, info: _Link, direction: Direction) -> int:
        schema = self._raw_schemas.get(info.framing)
        if schema is None:
            schema = self._raw_schemas[info.framing] = self._writer.register_schema(
                RAW_SCHEMA_PREFIX + info.framing, RAW_SCHEMA_ENCODING, raw_schema(info.framing)
            )
        metadata = {"link": str(info.id), "framing": info.framing, "name": info.name, "direction": direction}
        return int(
            self._writer.register_channel(RAW_TOPIC[direction], RAW_MESSAGE_ENCODING, schema, metadata)
        )

    def _arm(self, annotation: Annotation, link: int, t: int) -> None:
        """The ``/arm/*`` messages of a pose-bearing reply (channels registered on first use)."""
        for topic, data in arm_messages(annotation, link, t):
            channel = self._arm_channels.get(topic)
            if channel is None:
                name, schema = (
                    (FRAME_TRANSFORM_SCHEMA, frame_transform_schema())
                    if topic == HAND_TOPIC
                    else (JOINTS_SCHEMA, joints_schema())
                )
                schema_id = self._writer.register_schema(name, "jsonschema", json.dumps(schema).encode())
                channel = self._arm_channels[topic] = self._writer.register_channel(topic, "json", schema_id)
            self._arm_seq += 1
            self._add(channel, t, data, self._arm_seq)
            self._counts[topic] += 1

    # ------------------------------------------------------------------------------ events

    def event(self, event: str, t_ns: int | None = None, /, **fields: Any) -> None:
        """Record an event on ``/manip/events`` (fields as the ``manip.Event`` schema allows)."""
        self._drain()  # frames before the event are written before it
        self._event({"event": event, **{k: v for k, v in fields.items() if v not in (None, "")}}, t_ns)
        self._written()

    def _event(self, body: dict[str, Any], t_ns: int | None) -> None:
        if self._closed:
            raise CaptureError("the recorder is closed")
        t = self.clock_ns() if t_ns is None else t_ns
        self._event_seq += 1
        self._add(self._event_channel, t, _JSON.encode(body).encode(), self._event_seq)
        self._counts[EVENT_TOPIC] += 1

    # ------------------------------------------------------------------------------ durability

    def _written(self) -> None:
        self._pending = True
        if time.monotonic() >= self._due:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and write it out now."""
        if self._closed:
            return
        self._drain()
        self._due = time.monotonic() + self.flush_interval
        if self._pending:
            self._pending = False
            self.flushes += 1
            self._writer.flush()  # type: ignore[no-untyped-call]
            self._warn_once()

    def _arm_timer(self) -> None:
        """Wake up when the next flush is due (the due time moves whenever a write flushes)."""
        if self._loop is not None and not self._loop.is_closed():
            delay = max(0.0, self._due - time.monotonic())
            self._timer = self._loop.call_later(delay, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        if self._closed:
            return
        if time.monotonic() >= self._due:
            try:
                self.flush()
            except Exception as exc:  # a full disk must not take the session down with it
                log.error("capture flush failed: %s", exc)
                self._due = time.monotonic() + self.flush_interval
        self._arm_timer()
        self._warn_once()

    @property
    def write_error(self) -> CaptureError | None:
        """Why the file could not be written (a full disk...), once a write failed: what is recorded
        after it is dropped, the recorder logs it once, and a command checks it after :meth:`close`
        (which does not raise it: closing must not fail a session whose recording failed)."""
        error = None if self._file is None else self._file.error
        if error is None:
            return None
        return CaptureError(f"cannot write the capture {self.path}: {error.strerror or error}")

    def _warn_once(self) -> None:
        error = self.write_error
        if error is not None and not self._warned:
            self._warned = True
            log.error("%s; the rest of the session is not recorded", error)

    def close(self) -> None:
        """Write the summary (indexes, statistics) and close the file; later calls do nothing."""
        if self._closed:
            return
        self.event("recording-stopped")
        self._closed = True
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        try:
            self._writer.finish()  # type: ignore[no-untyped-call]
        finally:
            if self._owns_stream:
                self._stream.close()
        self._warn_once()  # the file then has no summary: readers call it truncated, never complete

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def connections(self) -> int:
        """Chaos connections seen so far (frames still in the batch are written first)."""
        if self._batch:
            self._drain()
        return self._annotator.connections

    def __enter__(self) -> Recorder:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
