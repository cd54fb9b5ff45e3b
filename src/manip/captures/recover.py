"""Rebuild a valid MCAP file from a truncated or damaged one (the Python ``mcap`` package has no recover).

A recorder killed before ``close()`` leaves a file with no summary section and, usually, a chunk cut
short.  :func:`recover` walks the records of the data section itself (magic, then ``opcode``, 8-byte
``length``, body), keeps everything that is whole, and writes a new file whose summary the MCAP writer
rebuilds:

* complete chunks are decompressed and their CRC checked; a chunk that fails is skipped and counted
  (its messages are lost, the rest is kept);
* the chunk that was being written when the file stopped is salvaged as far as it goes: its compressed
  bytes are fed to a streaming decompressor, which returns whatever whole blocks arrived (an
  uncompressed chunk gives back every whole message; a zstd chunk smaller than one 128 KiB block gives
  nothing), and the messages whose records are complete are kept;
* header, schemas, channels, metadata and attachments are copied; messages keep their times and
  sequence numbers; channel and schema ids are renumbered in order of first appearance;
* the new file gets a ``manip.recovery`` metadata record with the :class:`RecoveryReport`.

The report says honestly what was lost: the bytes after the last whole record, the chunks skipped, the
messages salvaged from the cut chunk and the time span that chunk declared (its messages after the
last one kept are gone), and the time of the last message kept.  Like Go's ``mcap recover`` this
cannot know how many messages a cut chunk held.
"""

from __future__ import annotations

import io
import os
import struct
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Final

import lz4.frame  # type: ignore[import-untyped]
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk
from mcap.writer import CompressionType, Writer

from .format import RECOVERY_METADATA_NAME
from .recorder import CaptureError

MAGIC: Final = b"\x89MCAP0\r\n"
_RECORD_HEAD: Final = struct.Struct("<BQ")
_CHUNK_HEAD: Final = struct.Struct("<QQQI")


@dataclass(slots=True)
class RecoveryReport:
    """What :func:`recover` kept and lost."""

    source: str
    output: str
    source_bytes: int = 0
    good_bytes: int = 0
    """Bytes up to the end of the last whole record (what follows is the cut or the summary)."""
    lost_bytes: int = 0
    """Bytes after ``good_bytes`` that were not a complete summary (the cut record, garbage)."""
    complete: bool = False
    """The source already had its footer: nothing was lost."""
    chunks: int = 0
    bad_chunks: int = 0
    messages: int = 0
    """Messages written to the output (all sources)."""
    partial_chunk: bool = False
    partial_chunk_bytes: int = 0
    """Bytes of the cut chunk that were present (of ``partial_chunk_declared`` declared)."""
    partial_chunk_declared: int = 0
    partial_messages: int = 0
    """Messages salvaged from the cut chunk."""
    partial_start_ns: int | None = None
    partial_end_ns: int | None = None
    """The time span the cut chunk declared (messages in it after the last one kept are lost)."""
    orphan_messages: int = 0
    """Messages whose channel record was lost (not written)."""
    last_message_ns: int | None = None
    stopped_because: str = ""
    problems: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """A few lines for people."""
        if self.complete:
            head = (
                f"{self.source}: the file was complete ({self.messages} messages); rewritten to {self.output}"
            )
            return "\n".join([head, *self.problems])
        lines = [
            f"recovered {self.messages} messages from {self.source} into {self.output}",
            f"  kept {self.good_bytes} of {self.source_bytes} bytes; lost {self.lost_bytes} bytes "
            f"({self.stopped_because})",
            f"  whole chunks: {self.chunks} kept, {self.bad_chunks} skipped as damaged",
        ]
        if self.partial_chunk:
            span = ""
            if self.partial_start_ns is not None and self.partial_end_ns is not None:
                span = f", declared time span {_t(self.partial_start_ns)} .. {_t(self.partial_end_ns)}"
            lines.append(
                f"  cut chunk: {self.partial_chunk_bytes} of {self.partial_chunk_declared} bytes present, "
                f"{self.partial_messages} messages salvaged from it{span}"
            )
        if self.orphan_messages:
            lines.append(f"  {self.orphan_messages} messages dropped: their channel record was lost")
        if self.last_message_ns is not None:
            lines.append(
                f"  last message kept: {_t(self.last_message_ns)}; anything recorded after it is lost"
            )
        lines.extend(f"  problem: {p}" for p in self.problems)
        return "\n".join(lines)

    def as_metadata(self) -> dict[str, str]:
        return {k: str(v) for k, v in asdict(self).items() if k != "problems"} | {
            "problems": "; ".join(self.problems)
        }


def _t(ns: int) -> str:
    """A log time for people: UTC date and time to the microsecond (never a raw epoch)."""
    seconds, rest = divmod(ns, 1_000_000_000)
    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(seconds)) + f".{rest // 1000:06d}Z"


class _Rebuilder:
    """Writes what is salvaged to the new file, renumbering schemas and channels."""

    def __init__(self, writer: Writer, report: RecoveryReport) -> None:
        self.writer = writer
        self.report = report
        self.schemas: dict[int, int] = {0: 0}
        self.channels: dict[int, int] = {}

    def record(self, record: Any) -> None:
        if isinstance(record, Message):
            channel = self.channels.get(record.channel_id)
            if channel is None:
                self.report.orphan_messages += 1
                return
            self.writer.add_message(
                channel, record.log_time, record.data, record.publish_time, record.sequence
            )
            self.report.messages += 1
            last = self.report.last_message_ns
            self.report.last_message_ns = record.log_time if last is None else max(last, record.log_time)
        elif isinstance(record, Channel):
            if record.id not in self.channels:
                schema = self.schemas.get(record.schema_id)
                if schema is None:
                    self.report.problems.append(f"channel {record.topic} lost its schema {record.schema_id}")
                    schema = 0
                self.channels[record.id] = self.writer.register_channel(
                    record.topic, record.message_encoding, schema, dict(record.metadata)
                )
        elif isinstance(record, Schema):
            if record.id not in self.schemas:
                self.schemas[record.id] = self.writer.register_schema(
                    record.name, record.encoding, record.data
                )
        elif isinstance(record, Metadata):
            self.writer.add_metadata(record.name, dict(record.metadata))
        elif isinstance(record, Attachment):
            self.writer.add_attachment(
                record.create_time, record.log_time, record.name, record.media_type, record.data
            )


def _parse_records(data: bytes) -> list[Any]:
    """The whole records of a chunk's (possibly cut) uncompressed content."""
    records: list[Any] = []
    pos = 0
    while pos + _RECORD_HEAD.size <= len(data):
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        end = pos + _RECORD_HEAD.size + length
        if end > len(data):
            break
        stream = ReadDataStream(io.BytesIO(data[pos + _RECORD_HEAD.size : end]))
        try:
            if opcode == Opcode.MESSAGE:
                records.append(Message.read(stream, length))
            elif opcode == Opcode.CHANNEL:
                records.append(Channel.read(stream))
            elif opcode == Opcode.SCHEMA:
                records.append(Schema.read(stream))
        except (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError):
            break
        pos = end
    return records


def _salvage_chunk(body: bytes, declared: int, report: RecoveryReport) -> list[Any]:
    """Messages (and their schema and channel records) of a chunk cut short."""
    report.partial_chunk = True
    report.partial_chunk_bytes = len(body)
    report.partial_chunk_declared = declared
    if len(body) < _CHUNK_HEAD.size + 4:
        return []
    start, end, _size, _crc = _CHUNK_HEAD.unpack_from(body)
    report.partial_start_ns, report.partial_end_ns = start, end
    pos = _CHUNK_HEAD.size
    (name_len,) = struct.unpack_from("<I", body, pos)
    pos += 4
    compression = body[pos : pos + name_len].decode("ascii", "replace")
    pos += name_len + 8  # the records' byte-array length
    compressed = body[pos:]
    try:
        if compression == "zstd":
            data = zstandard.ZstdDecompressor().decompressobj().decompress(compressed)
        elif compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(compressed)
        elif compression == "":
            data = compressed
        else:
            report.problems.append(f"cut chunk uses unknown compression {compression!r}")
            return []
    except (zstandard.ZstdError, RuntimeError) as exc:
        report.problems.append(f"cut chunk does not decompress: {exc}")
        return []
    return _parse_records(data)


def recover(source: str | os.PathLike[str], output: str | os.PathLike[str] | None = None) -> RecoveryReport:
    """Rebuild ``source`` into ``output`` (default: ``<source stem>.recovered.mcap``); see the module."""
    src = os.fspath(source)
    out = os.fspath(output) if output is not None else _default_output(src)
    if os.path.abspath(src) == os.path.abspath(out):
        raise CaptureError("recover writes a new file: give an output path other than the source")
    try:
        with open(src, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise CaptureError(f"cannot read {src}: {exc}") from exc
    if not data.startswith(MAGIC):
        raise CaptureError(f"{src} is not an MCAP file (no magic at the start)")
    report = RecoveryReport(src, out, source_bytes=len(data))
    records = _scan(data, report)
    header = next((r for r in records if isinstance(r, Header)), None)
    if header is None:
        raise CaptureError(f"{src}: the MCAP header record is missing or cut; nothing can be recovered")
    with open(out, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile=header.profile, library=header.library)
        rebuilder = _Rebuilder(writer, report)
        for record in records:
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as exc:  # CRC, decompression: the chunk is damaged; keep the rest
                    report.bad_chunks += 1
                    report.problems.append(f"chunk at {_t(record.message_start_time)} skipped: {exc}")
                    continue
                report.chunks += 1
                for r in inner:
                    rebuilder.record(r)
            elif isinstance(record, _Partial):
                for r in record.records:
                    before = report.messages
                    rebuilder.record(r)
                    report.partial_messages += report.messages - before
            else:
                rebuilder.record(record)
        writer.add_metadata(RECOVERY_METADATA_NAME, report.as_metadata())
        writer.finish()  # type: ignore[no-untyped-call]
    return report


@dataclass(slots=True)
class _Partial:
    records: list[Any]


def _scan(data: bytes, report: RecoveryReport) -> list[Any]:
    """The whole records of the data section, plus the salvage of a cut chunk at the end."""
    records: list[Any] = []
    pos = len(MAGIC)
    size = len(data)
    while True:
        if pos + _RECORD_HEAD.size > size:
            report.stopped_because = "the file ends inside a record header" if pos < size else "end of file"
            break
        opcode, length = _RECORD_HEAD.unpack_from(data, pos)
        body_start = pos + _RECORD_HEAD.size
        end = body_start + length
        if end > size:
            report.stopped_because = f"record at byte {pos} (opcode {opcode:#04x}) cut short"
            if opcode == Opcode.CHUNK:
                records.append(_Partial(_salvage_chunk(data[body_start:], length, report)))
            break
        if opcode in (Opcode.DATA_END, Opcode.FOOTER):
            report.complete = True
            report.stopped_because = "end of the data section"
            pos = end
            break
        stream = ReadDataStream(io.BytesIO(data[body_start:end]))
        try:
            if opcode == Opcode.HEADER:
                records.append(Header.read(stream))
            elif opcode == Opcode.CHUNK:
                records.append(Chunk.read(stream))
            elif opcode == Opcode.MESSAGE:
                records.append(Message.read(stream, length))
            elif opcode == Opcode.CHANNEL:
                records.append(Channel.read(stream))
            elif opcode == Opcode.SCHEMA:
                records.append(Schema.read(stream))
            elif opcode == Opcode.METADATA:
                records.append(Metadata.read(stream))
            elif opcode == Opcode.ATTACHMENT:
                records.append(Attachment.read(stream))
        except (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError) as exc:
            report.stopped_because = f"record at byte {pos} (opcode {opcode:#04x}) is garbled: {exc}"
            break
        pos = end
    report.good_bytes = pos
    report.lost_bytes = 0 if report.complete else size - pos
    return records


def _default_output(src: str) -> str:
    stem = src[:-5] if src.endswith(".mcap") else src
    return f"{stem}.recovered.mcap"
