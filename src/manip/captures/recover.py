"""Rebuild a valid MCAP file from a truncated or damaged one (the Python ``mcap`` package has no recover).

A recorder killed before ``close()`` leaves a file with no summary section and, usually, a chunk cut
short.  :func:`recover` walks the records of the data section itself (magic, then ``opcode``, 8-byte
``length``, body), keeps everything that is whole, and writes a new file whose summary the MCAP writer
rebuilds:

* complete chunks are decompressed and their CRC checked.  A chunk whose records decompress but do not
  match its CRC keeps every record that still parses, and the report names it (its messages may carry
  the damage); a chunk that does not decompress is skipped and counted (its messages are lost, the
  rest is kept).  Either way the report says which chunk (its byte offset) and why;
* the chunk that was being written when the file stopped is salvaged as far as it goes: its compressed
  bytes are fed to a streaming decompressor, which returns whatever whole blocks arrived (an
  uncompressed chunk gives back every whole message; a zstd chunk smaller than one 128 KiB block gives
  nothing), and the messages whose records are complete are kept;
* header, schemas, channels, metadata and attachments are copied; messages keep their times and
  sequence numbers; channel and schema ids are renumbered in order of first appearance;
* the new file gets a ``manip.recovery`` metadata record with the :class:`RecoveryReport`.

The source is read a record at a time, never whole, and no record longer than the bounds of
:mod:`~manip.captures.bounds` is read: a reader of any input (``/dev/zero`` among them) stays small.
The output is written to a temporary file beside the target and renamed into place when it is whole.

The report says honestly what was lost: the bytes after the last whole record, the chunks skipped, the
messages salvaged from the cut chunk and the time span that chunk declared (its messages after the
last one kept are gone), and the time of the last message kept.  Like Go's ``mcap recover`` this
cannot know how many messages a cut chunk held.
"""

from __future__ import annotations

import io
import os
import stat
import struct
import time
import zlib
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from typing import IO, Any, Final

import lz4.frame  # type: ignore[import-untyped]
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema
from mcap.writer import CompressionType, Writer

from manip.outfile import OutputError, atomic_output

from .bounds import MAX_RECORD_BYTES, unpack_chunk
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
    """Chunks that do not decompress (their messages are lost)."""
    crc_chunks: int = 0
    """Chunks whose records do not match their CRC: what still parses was kept, and may be damaged."""
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

    @property
    def damaged(self) -> bool:
        """Something was lost or may be wrong: a chunk skipped or failing its CRC, a cut, orphans."""
        return bool(
            self.bad_chunks or self.crc_chunks or self.orphan_messages or self.lost_bytes or not self.complete
        )

    def summary(self) -> str:
        """A few lines for people."""
        if not self.damaged:
            head = (
                f"{self.source}: the file was complete ({self.messages} messages); rewritten to {self.output}"
            )
            return "\n".join([head, *self.problems])
        lines = [
            f"recovered {self.messages} messages from {self.source} into {self.output}",
            f"  kept {self.good_bytes} of {self.source_bytes} bytes; lost {self.lost_bytes} bytes "
            f"({self.stopped_because})",
            f"  whole chunks: {self.chunks} kept, {self.bad_chunks} skipped as damaged"
            + (f", {self.crc_chunks} kept despite a CRC mismatch" if self.crc_chunks else ""),
        ]
        if self.complete:
            lines[1] = f"  the file had its footer, but is damaged ({self.stopped_because})"
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
        if self.last_message_ns is not None and not self.complete:
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
    limit = MAX_RECORD_BYTES
    try:
        if compression == "zstd":
            data = zstandard.ZstdDecompressor().decompressobj().decompress(compressed)[:limit]
        elif compression == "lz4":
            data = lz4.frame.LZ4FrameDecompressor().decompress(compressed, max_length=limit)
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
        f = open(src, "rb")  # noqa: SIM115  # closed below
    except OSError as exc:
        raise CaptureError(f"cannot read {src}: {exc.strerror or exc}") from exc
    with f:
        if f.read(len(MAGIC)) != MAGIC:
            raise CaptureError(f"{src} is not an MCAP file (no magic at the start)")
        report = RecoveryReport(src, out, source_bytes=_size(f))
        records = _scan(f, report)
        header = next(records, None)
        if not isinstance(header, Header):
            raise CaptureError(f"{src}: the MCAP header record is missing or cut; nothing can be recovered")
        try:
            with atomic_output(out, "wb") as stream:
                _rebuild(stream, header, records, report)
        except OutputError as exc:
            raise CaptureError(str(exc)) from exc
    return report


def _rebuild(stream: IO[bytes], header: Header, records: Iterator[Any], report: RecoveryReport) -> None:
    writer = Writer(stream, compression=CompressionType.ZSTD)
    writer.start(profile=header.profile, library=header.library)
    rebuilder = _Rebuilder(writer, report)
    for record in records:
        if isinstance(record, _Whole):
            _whole_chunk(record, rebuilder, report)
        elif isinstance(record, _Partial):
            for r in record.records:
                before = report.messages
                rebuilder.record(r)
                report.partial_messages += report.messages - before
        else:
            rebuilder.record(record)
    writer.add_metadata(RECOVERY_METADATA_NAME, report.as_metadata())
    writer.finish()  # type: ignore[no-untyped-call]


def _whole_chunk(whole: _Whole, rebuilder: _Rebuilder, report: RecoveryReport) -> None:
    """A complete chunk: its records if it decompresses (kept under a CRC mismatch, and said so)."""
    chunk = whole.chunk
    where = f"chunk at byte {whole.offset} ({_t(chunk.message_start_time)})"
    try:
        data = unpack_chunk(chunk.compression, chunk.data, chunk.uncompressed_size, 0)
    except ValueError as exc:  # does not decompress, or not to its size: the chunk is lost
        report.bad_chunks += 1
        report.problems.append(f"{where} skipped: {exc}")
        return
    records = _parse_records(data)
    before = report.messages
    for r in records:
        rebuilder.record(r)
    kept = report.messages - before
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        report.crc_chunks += 1
        report.problems.append(
            f"{where}: CRC mismatch (the header says {chunk.uncompressed_crc:08x}, the records give "
            f"{zlib.crc32(data):08x}); its {kept} readable messages were kept, and may carry the damage"
        )
    else:
        report.chunks += 1


@dataclass(slots=True)
class _Partial:
    records: list[Any]


@dataclass(slots=True)
class _Whole:
    chunk: Chunk
    offset: int


def _size(f: IO[bytes]) -> int:
    try:
        info = os.fstat(f.fileno())
    except OSError:
        return 0
    return info.st_size if stat.S_ISREG(info.st_mode) else 0


def _scan(f: IO[bytes], report: RecoveryReport) -> Iterator[Any]:
    """The whole records of the data section, a record at a time, plus the salvage of a cut chunk at the
    end; ``report`` says where and why the scan stopped once the iterator is exhausted."""
    pos = len(MAGIC)
    while True:
        head = f.read(_RECORD_HEAD.size)
        if len(head) < _RECORD_HEAD.size:
            report.stopped_because = "the file ends inside a record header" if head else "end of file"
            report.lost_bytes = len(head)
            break
        opcode, length = _RECORD_HEAD.unpack(head)
        if length > MAX_RECORD_BYTES:
            report.stopped_because = (
                f"record at byte {pos} (opcode {opcode:#04x}) claims {length} bytes, more than the "
                f"{MAX_RECORD_BYTES} allowed (MANIP_CAPTURE_MAX_RECORD_MB)"
            )
            report.lost_bytes = max(0, report.source_bytes - pos)
            break
        body = f.read(length)
        if len(body) < length:
            report.stopped_because = f"record at byte {pos} (opcode {opcode:#04x}) cut short"
            report.lost_bytes = _RECORD_HEAD.size + len(body)
            if opcode == Opcode.CHUNK:
                yield _Partial(_salvage_chunk(body, length, report))
            break
        if opcode in (Opcode.DATA_END, Opcode.FOOTER):
            report.complete = True
            report.stopped_because = "end of the data section"
            pos += _RECORD_HEAD.size + length
            break
        try:
            record = _read_record(opcode, body, pos)
        except (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError) as exc:
            report.stopped_because = f"record at byte {pos} (opcode {opcode:#04x}) is garbled: {exc}"
            report.lost_bytes = max(0, report.source_bytes - pos)
            break
        if record is not None:
            yield record
        pos += _RECORD_HEAD.size + length
        report.good_bytes = pos
    report.good_bytes = pos
    if report.complete:
        report.lost_bytes = 0


def _read_record(opcode: int, body: bytes, pos: int) -> Any:
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.CHUNK:
        return _Whole(Chunk.read(stream), pos)
    reader = _READERS.get(opcode)
    if reader is None:
        return None
    return Message.read(stream, len(body)) if opcode == Opcode.MESSAGE else reader(stream)


_READERS: Final[dict[int, Any]] = {
    Opcode.HEADER: Header.read,
    Opcode.MESSAGE: Message.read,
    Opcode.CHANNEL: Channel.read,
    Opcode.SCHEMA: Schema.read,
    Opcode.METADATA: Metadata.read,
    Opcode.ATTACHMENT: Attachment.read,
}


def _default_output(src: str) -> str:
    stem = src[:-5] if src.endswith(".mcap") else src
    return f"{stem}.recovered.mcap"
