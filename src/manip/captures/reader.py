"""Read captures back as typed records: packets, sessions (one per Chaos connection), pairs and events.

The raw channels are the source of truth: every frame is decoded again by its framing and annotated by
the same :class:`~manip.captures.view.Annotator` the recorder used, so connection numbers, pair ids and
meanings are exactly those of the JSON view (which the reader does not need, and skips without building
its messages: chunks are unpacked here rather than by ``mcap``'s record classes).  The file is
read as a stream in the order it was written, so a capture without its summary section can be read up
to where it breaks (:class:`CaptureTruncatedError` then says how far it got; ``manip-capture recover`` makes
it whole).  Damage stops the reading with :class:`~manip.captures.bounds.CaptureDamagedError`, which names
the byte offset and what was wrong: a chunk that does not decompress, whose records do not match its
CRC or its declared size, a record that runs past its chunk or the file, or one longer than the bounds
of :mod:`~manip.captures.bounds` (which no reader goes past, whatever a length field claims).

The replay and offline-verify commands of :mod:`manip.conformance` use :func:`read_sessions`:
``session.requests`` are the client's requests in order (retransmissions left out), ``session.pairs``
tie each to the server's replies, ``session.server_packets`` / ``client_packets`` are each side.
"""

from __future__ import annotations

import io
import json
import os
import stat
import struct
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import IO, Any, Final

from mcap.data_stream import ReadDataStream
from mcap.exceptions import InvalidMagic, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from manip.codecs.errors import DecodeError
from manip.codecs.packet import Direction, Packet

from .bounds import MAX_RECORD_BYTES, CaptureDamagedError, unpack_chunk
from .format import DIRECTIONS, EVENT_TOPIC, RAW_MESSAGE_ENCODING
from .recorder import FRAME_DECODERS, CaptureError, frame_decoder
from .view import Annotation, Annotator, bad_frame

_RECORD_HEAD: Final = struct.Struct("<BQ")
_MESSAGE_HEAD: Final = struct.Struct("<HIQQ")
"""A message record: channel id, sequence, log time, publish time; the data follow."""
_MESSAGE: Final = int(Opcode.MESSAGE)
_CHANNEL: Final = int(Opcode.CHANNEL)
_SCHEMA: Final = int(Opcode.SCHEMA)


class CaptureTruncatedError(CaptureError):
    """The file ends (or is damaged) before its end: ``records`` is how many were read."""

    def __init__(self, path: str, records: int, detail: str) -> None:
        super().__init__(
            f"{path}: capture truncated or damaged after {records} records ({detail}); "
            f"rebuild it with: manip-capture recover {path}"
        )
        self.records = records


@dataclass(frozen=True, slots=True)
class LinkInfo:
    """A recorded link: its id, framing and name."""

    id: int
    framing: str
    name: str


@dataclass(frozen=True, slots=True)
class CapturedPacket:
    """One recorded frame: where and when it was seen, its bytes, its packet and what it means."""

    seq: int
    time_ns: int
    link: int
    direction: Direction
    frame: bytes
    packet: Packet | None
    """None for a frame that did not decode (``annotation.kind == "bad-frame"``)."""
    annotation: Annotation

    @property
    def conn(self) -> int:
        return self.annotation.conn

    @property
    def kind(self) -> str:
        return self.annotation.kind

    @property
    def pair(self) -> int | None:
        return self.annotation.pair

    @property
    def op(self) -> str | None:
        return self.annotation.op

    @property
    def request_number(self) -> int | None:
        return self.annotation.request_number

    @property
    def retransmission(self) -> bool:
        return self.annotation.retransmission

    @property
    def opcode(self) -> int | None:
        return None if self.packet is None else self.packet.opcode

    @property
    def data(self) -> bytes:
        return b"" if self.packet is None else self.packet.data


class _CapturedBuilder:
    """A plain class with exactly :class:`CapturedPacket`'s slots: the reader fills one with ordinary
    attribute stores and makes it a CapturedPacket by assigning ``__class__`` (allowed between classes of
    the same instance layout), which costs far less than the frozen dataclass's ``__init__``."""

    __slots__ = CapturedPacket.__slots__

    def __init__(
        self,
        seq: int,
        time_ns: int,
        link: int,
        direction: Direction,
        frame: bytes,
        packet: Packet | None,
        annotation: Annotation,
    ) -> None:
        self.seq = seq
        self.time_ns = time_ns
        self.link = link
        self.direction = direction
        self.frame = frame
        self.packet = packet
        self.annotation = annotation


def _captured(
    seq: int,
    time_ns: int,
    link: int,
    direction: Direction,
    frame: bytes,
    packet: Packet | None,
    annotation: Annotation,
) -> CapturedPacket:
    built = _CapturedBuilder(seq, time_ns, link, direction, frame, packet, annotation)
    built.__class__ = CapturedPacket  # type: ignore[assignment]
    return built  # type: ignore[return-value]


@dataclass(frozen=True, slots=True)
class CapturedEvent:
    """One ``/manip/events`` entry (or a connection event found again from the packets)."""

    time_ns: int
    event: str
    fields: dict[str, Any]


@dataclass(slots=True)
class Pair:
    """A request (or the RFC) and the server packets that answer it, in order."""

    id: int
    request: CapturedPacket
    replies: list[CapturedPacket] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        """True once a ``final`` reply was seen."""
        return any(r.annotation.final for r in self.replies)


@dataclass(slots=True)
class Session:
    """One Chaos connection of a capture, from its RFC (if recorded) to its end."""

    conn: int
    link: int
    packets: list[CapturedPacket] = field(default_factory=list)
    events: list[CapturedEvent] = field(default_factory=list)

    @property
    def client_packets(self) -> list[CapturedPacket]:
        return [p for p in self.packets if p.direction == "c2s"]

    @property
    def server_packets(self) -> list[CapturedPacket]:
        return [p for p in self.packets if p.direction == "s2c"]

    @property
    def requests(self) -> list[CapturedPacket]:
        """The client's manip requests in order, retransmissions left out."""
        return [p for p in self.packets if p.kind == "request" and not p.retransmission]

    def exchange(self) -> list[tuple[Direction, int, bytes]]:
        """(direction, opcode, data) of every manip data packet (0200 and up), retransmissions left out:
        what a replay compares, and what stays the same when a deterministic session is recorded again
        (times, connection indices, acknowledgements and idle STS/SNS traffic do not)."""
        return [
            (p.direction, p.packet.opcode, p.packet.data)
            for p in self.packets
            if p.packet is not None and p.packet.opcode >= 0o200 and not p.retransmission
        ]

    @property
    def pairs(self) -> dict[int, Pair]:
        """Pair id -> the request (or RFC) and its replies; retransmitted copies left out."""
        pairs: dict[int, Pair] = {}
        for p in self.packets:
            pid = p.pair
            if pid is None or p.retransmission:
                continue
            if p.direction == "c2s":
                pairs.setdefault(pid, Pair(pid, p))
            elif pid in pairs:
                pairs[pid].replies.append(p)
        return pairs

    @property
    def contact(self) -> str | None:
        for e in self.events:
            if e.event == "rfc":
                return str(e.fields.get("contact"))
        return None

    @property
    def start_ns(self) -> int:
        return self.packets[0].time_ns if self.packets else 0

    @property
    def end_ns(self) -> int:
        return self.packets[-1].time_ns if self.packets else 0


@dataclass(slots=True)
class Capture:
    """A whole capture: header, metadata, links, sessions and link-level events."""

    path: str
    profile: str = ""
    library: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    links: dict[int, LinkInfo] = field(default_factory=dict)
    sessions: list[Session] = field(default_factory=list)
    events: list[CapturedEvent] = field(default_factory=list)
    """Events of the ``/manip/events`` channel that belong to no connection (links, recording)."""
    bad_frames: list[CapturedPacket] = field(default_factory=list)
    counts: Counter[str] = field(default_factory=Counter)
    """Messages per topic."""

    @property
    def packets(self) -> Iterator[CapturedPacket]:
        """Every decoded packet of every session, in recording order."""
        return iter(sorted((p for s in self.sessions for p in s.packets), key=lambda p: p.seq))

    @property
    def start_ns(self) -> int:
        times = [s.start_ns for s in self.sessions if s.packets] + [e.time_ns for e in self.events]
        return min(times, default=0)

    @property
    def end_ns(self) -> int:
        times = [s.end_ns for s in self.sessions if s.packets] + [e.time_ns for e in self.events]
        return max(times, default=0)


# ---------------------------------------------------------------------------------------- streaming


@dataclass(slots=True)
class _Raw:
    link: int
    direction: Direction
    decode: Any


class _Stream:
    """The record loop shared by :func:`iter_packets` and :func:`read_capture`."""

    def __init__(self, source: str | os.PathLike[str] | IO[bytes], capture: Capture) -> None:
        self.source = source
        self.path = "<stream>"
        self.capture = capture
        self.annotator = Annotator()
        self.raw: dict[int, _Raw] = {}
        self.events: set[int] = set()
        self.topics: dict[int, str] = {}
        self.schemas: dict[int, Schema] = {}

    def items(self) -> Iterator[CapturedPacket | CapturedEvent]:
        source = self.source
        path = (
            os.fspath(source)
            if isinstance(source, (str, os.PathLike))
            else getattr(source, "name", "<stream>")
        )
        self.path = str(path)
        try:
            stream: IO[bytes] = open(source, "rb") if isinstance(source, (str, os.PathLike)) else source  # noqa: SIM115
        except OSError as exc:
            raise CaptureError(f"cannot read the capture {path}: {exc}") from exc
        records = 0
        try:
            limit = min(MAX_RECORD_BYTES, _size_of(stream))
            for record in StreamReader(stream, emit_chunks=True, record_size_limit=limit).records:
                records += 1
                if isinstance(record, Chunk):
                    yield from self._chunk(record, _tell(stream))
                elif isinstance(record, Message):
                    item = self._message(record.channel_id, record.sequence, record.log_time, record.data)
                    if item is not None:
                        yield item
                else:
                    self._other(record)
        except InvalidMagic as exc:
            raise CaptureError(f"{path} is not an MCAP file (it does not start with the MCAP magic)") from exc
        except (McapError, EOFError, struct.error, ValueError, MemoryError) as exc:
            if records == 0:  # not even a header: nothing a recovery could start from
                raise CaptureError(f"{path} is not a capture: it ends before an MCAP header") from exc
            offset = _tell(stream)
            if offset is not None and offset >= _size_of(stream):
                raise CaptureTruncatedError(path, records, f"{type(exc).__name__}: {exc}") from exc
            what = str(exc) or type(exc).__name__
            raise CaptureDamagedError(str(path), offset, what, records=records) from exc
        finally:
            if stream is not source:
                stream.close()

    def _other(self, record: object) -> None:
        """A record outside a chunk that is not a message: what it says about the capture."""
        if isinstance(record, Channel):
            self._channel(record)
        elif isinstance(record, Schema):
            self.schemas[record.id] = record
        elif isinstance(record, Metadata):
            self.capture.metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Header):
            self.capture.profile = record.profile
            self.capture.library = record.library

    def _channel(self, channel: Channel) -> None:
        self.topics[channel.id] = channel.topic
        if channel.message_encoding == RAW_MESSAGE_ENCODING:
            meta = channel.metadata
            link = int(meta.get("link", "0"))
            direction = meta.get("direction", "")
            framing = meta.get("framing", "")
            if direction not in DIRECTIONS or framing not in FRAME_DECODERS:
                raise CaptureError(f"raw channel {channel.id} has unusable metadata {meta}")
            self.raw[channel.id] = _Raw(link, "c2s" if direction == "c2s" else "s2c", frame_decoder(framing))
            self.capture.links.setdefault(link, LinkInfo(link, framing, meta.get("name", "")))
        elif channel.topic == EVENT_TOPIC:
            self.events.add(channel.id)

    def _chunk(self, chunk: Chunk, end: int | None) -> Iterator[CapturedPacket | CapturedEvent]:
        """The records of a chunk, read here rather than by ``breakup_chunk`` so that messages nobody
        wants (the JSON view) are counted and skipped without being built.  ``end`` is the file offset
        just after the chunk (for messages about it)."""
        at = None if end is None else end - 9 - 40 - len(chunk.compression) - len(chunk.data)
        try:
            data = unpack_chunk(
                chunk.compression, chunk.data, chunk.uncompressed_size, chunk.uncompressed_crc
            )
        except ValueError as exc:
            raise CaptureDamagedError(self.path, at, f"the chunk record there is damaged: {exc}") from None
        pos, size = 0, len(data)
        head, message_head = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
        message_at = _RECORD_HEAD.size + _MESSAGE_HEAD.size
        raw_channels, events = self.raw, self.events
        seen: Counter[int] = Counter()  # messages per channel id, added to the topic counts at the end
        try:
            while pos < size:
                if pos + 9 > size:
                    raise CaptureDamagedError(self.path, at, "a chunk ends inside a record header")
                opcode, length = head(data, pos)
                start = pos
                pos += 9 + length
                if pos > size:
                    raise CaptureDamagedError(
                        self.path,
                        at,
                        f"a record in the chunk there claims {length} bytes, past the chunk's end",
                    )
                if opcode == _MESSAGE:
                    cid, sequence, log_time, _ = message_head(data, start + 9)
                    seen[cid] += 1
                    raw = raw_channels.get(cid)
                    if raw is not None:
                        yield self._frame(raw, sequence, log_time, data[start + message_at : pos])
                    elif cid in events:
                        yield self._event(log_time, data[start + message_at : pos])
                elif opcode == _CHANNEL:
                    self._channel(Channel.read(ReadDataStream(io.BytesIO(data[start + 9 : pos]))))
                elif opcode == _SCHEMA:
                    schema = Schema.read(ReadDataStream(io.BytesIO(data[start + 9 : pos])))
                    self.schemas[schema.id] = schema
        finally:
            counts, topics = self.capture.counts, self.topics
            for cid, n in seen.items():
                counts[topics.get(cid, "?")] += n

    def _message(
        self, cid: int, sequence: int, log_time: int, data: bytes
    ) -> CapturedPacket | CapturedEvent | None:
        self.capture.counts[self.topics.get(cid, "?")] += 1
        raw = self.raw.get(cid)
        if raw is not None:
            return self._frame(raw, sequence, log_time, bytes(data))
        if cid in self.events:
            return self._event(log_time, data)
        return None

    def _frame(self, raw: _Raw, sequence: int, log_time: int, frame: bytes) -> CapturedPacket:
        """A frame, decoded and annotated as the recorder did."""
        packet: Packet | None
        try:
            packet = raw.decode(frame)
        except DecodeError as exc:
            packet = None
            annotation = bad_frame(exc)
        else:
            annotation = self.annotator.annotate(raw.link, raw.direction, packet)
        return _captured(sequence, log_time, raw.link, raw.direction, frame, packet, annotation)

    @staticmethod
    def _event(log_time: int, data: bytes) -> CapturedEvent:
        try:
            body = json.loads(data)
        except RecursionError:
            raise ValueError("an event is JSON nested too deep to read") from None
        if not isinstance(body, dict):
            raise ValueError("an event is not a JSON object")
        name = str(body.pop("event", "?"))
        return CapturedEvent(log_time, name, body)


def _size_of(stream: IO[bytes]) -> int:
    """The size of a regular file (no record can be longer); a bound of records otherwise."""
    try:
        info = os.fstat(stream.fileno())
    except (OSError, AttributeError, io.UnsupportedOperation):
        return MAX_RECORD_BYTES
    return info.st_size if stat.S_ISREG(info.st_mode) else MAX_RECORD_BYTES


def _tell(stream: IO[bytes]) -> int | None:
    try:
        return stream.tell()
    except (OSError, AttributeError, ValueError):
        return None


def iter_packets(
    source: str | os.PathLike[str] | IO[bytes], *, capture: Capture | None = None
) -> Iterator[CapturedPacket]:
    """Every recorded frame in recording order, decoded and annotated (streaming, constant memory).

    ``capture``, if given, is filled in as the file is read (header, metadata, links: a packet's link
    is known by the time the packet is yielded); its sessions stay empty."""
    for item in _Stream(source, Capture(str(source)) if capture is None else capture).items():
        if isinstance(item, CapturedPacket):
            yield item


def read_capture(source: str | os.PathLike[str] | IO[bytes]) -> Capture:
    """The whole capture, grouped by session.  Raises :class:`CaptureTruncatedError` on a damaged file."""
    capture = Capture(str(source))
    sessions: dict[int, Session] = {}
    for item in _Stream(source, capture).items():
        if isinstance(item, CapturedEvent):
            if "conn" not in item.fields:
                capture.events.append(item)
            continue
        if item.packet is None:
            capture.bad_frames.append(item)
            continue
        session = sessions.get(item.conn)
        if session is None:
            session = sessions[item.conn] = Session(item.conn, item.link)
        session.packets.append(item)
        for event in item.annotation.events:
            body = {k: v for k, v in event.items() if k != "event"}
            session.events.append(CapturedEvent(item.time_ns, str(event["event"]), body))
    capture.sessions = [sessions[k] for k in sorted(sessions)]
    return capture


def read_sessions(source: str | os.PathLike[str] | IO[bytes]) -> list[Session]:
    """The sessions (Chaos connections) of a capture, in the order they started."""
    return read_capture(source).sessions


def read_session(source: str | os.PathLike[str] | IO[bytes], index: int = 0) -> Session:
    """One session of a capture (the first by default); CaptureError if there is no such session."""
    sessions = read_sessions(source)
    if not -len(sessions) <= index < len(sessions):
        raise CaptureError(f"{source}: no session {index} (the capture has {len(sessions)})")
    return sessions[index]
