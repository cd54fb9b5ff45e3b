"""The bounds every reader of a capture file keeps, and the checked unpacking of one chunk.

A capture is outside input: a damaged or hostile file must end in a :class:`CaptureDamagedError` naming
the file, the byte offset and what was wrong, never in a traceback or a runaway allocation.  So:

* no record is read whose length goes past the end of the file, or past :data:`MAX_RECORD_BYTES`;
* no chunk is decompressed to more than :data:`MAX_RECORD_BYTES` (its declared size is checked first,
  and the decompressor is held to it);
* a chunk whose CRC (when it has one) does not match its records is damaged, as is one that does not
  decompress or whose records run past its end.

:data:`MAX_RECORD_BYTES` is 32 MiB: 128 times the chunks manip writes (256 KiB), 8 times the largest the
mcap tools write by default, and small enough that a reader stays well under 200 MB however its input
lies.  ``MANIP_CAPTURE_MAX_RECORD_MB`` in the environment sets another bound (in MiB), for files from a
writer that makes larger chunks.
"""

from __future__ import annotations

import math
import os
import zlib
from typing import Final

import lz4.frame  # type: ignore[import-untyped]
import zstandard

from .recorder import CaptureError


def _max_record_bytes() -> int:
    text = os.environ.get("MANIP_CAPTURE_MAX_RECORD_MB", "").strip()
    try:
        megabytes = float(text) if text else 32.0
    except ValueError:
        megabytes = 32.0
    if not math.isfinite(megabytes) or megabytes <= 0:
        megabytes = 32.0
    return max(1, int(megabytes * (1 << 20)))


MAX_RECORD_BYTES: Final = _max_record_bytes()
"""The largest record (and decompressed chunk) a reader accepts; see the module docstring."""


class CaptureDamagedError(CaptureError):
    """The capture is damaged at ``offset``: ``what`` says how.  Reading stops there."""

    def __init__(self, path: str, offset: int | None, what: str, *, records: int | None = None) -> None:
        where = f" at byte {offset}" if offset is not None else ""
        after = f" (after {records} whole records)" if records is not None else ""
        super().__init__(
            f"{path}: damaged{where}{after}: {what}; manip-capture recover {path} keeps what can be read"
        )
        self.path = path
        self.offset = offset
        self.what = what


def unpack_chunk(compression: str, compressed: bytes, declared: int, crc: int) -> bytes:
    """The records of a chunk, decompressed and checked against its declared size and CRC.

    Raises ``ValueError`` saying what is wrong (the caller adds the file and offset)."""
    if declared > MAX_RECORD_BYTES:
        raise ValueError(
            f"chunk declares {declared} uncompressed bytes, more than the {MAX_RECORD_BYTES} allowed "
            "(MANIP_CAPTURE_MAX_RECORD_MB)"
        )
    if compression == "zstd":
        try:  # a stream reader held to the declared size: a frame's own content size is not trusted
            data = zstandard.ZstdDecompressor().stream_reader(compressed).read(declared + 1)
        except zstandard.ZstdError as exc:
            raise ValueError(f"zstd chunk does not decompress: {exc}") from None
    elif compression == "lz4":
        data = _lz4(compressed, declared)
    elif compression == "":
        data = compressed
    else:
        raise ValueError(f"chunk compression {compression!r} is not supported")
    if len(data) != declared:
        raise ValueError(f"chunk holds {len(data)} bytes of records, its header says {declared}")
    if crc and zlib.crc32(data) != crc:
        raise ValueError(
            f"chunk CRC mismatch: records give {zlib.crc32(data):08x}, the header says {crc:08x}"
        )
    return data if type(data) is bytes else bytes(data)


def _lz4(compressed: bytes, declared: int) -> bytes:
    decompressor = lz4.frame.LZ4FrameDecompressor()
    try:
        data: bytes = decompressor.decompress(compressed, max_length=declared + 1)
    except RuntimeError as exc:
        raise ValueError(f"lz4 chunk does not decompress: {exc}") from None
    if len(data) > declared:
        raise ValueError(f"lz4 chunk decompresses to more than the {declared} bytes its header says")
    return data
