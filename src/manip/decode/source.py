"""Where ``manip-decode`` reads from: a file, standard input or the argument itself, as a stream of bytes.

Nothing is read whole.  The first block says whether the input is hex text or binary (unless told);
hex text is turned into bytes a block at a time (spaces, colons, commas and ``0x`` prefixes allowed
anywhere), so a file of any size goes through in constant memory.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from typing import IO, Final

BLOCK: Final = 1 << 16
MAX_TEXT: Final = 4 << 20
"""The most a Cougar word stream may hold (read whole): 4 MiB of text, about 800,000 words."""
_HEX_TEXT: Final = re.compile(rb"^[\s0-9a-fA-Fx:,]*$")
_SEPARATORS: Final = re.compile(rb"0[xX]|[\s:,]")
_HEX_ARGUMENT: Final = re.compile(r"^[\s0-9a-fA-Fx:,]+$")
_HEX_CHARACTERS: Final = frozenset("0123456789abcdefABCDEFxX:, \t\n\r\v\f")


class SourceError(Exception):
    """The input cannot be read as asked; ``usage`` is True when the command line is at fault."""

    def __init__(self, message: str, *, usage: bool = False) -> None:
        super().__init__(message)
        self.usage = usage


@dataclass(frozen=True, slots=True)
class Source:
    """An opened input: its name for messages and its byte stream."""

    name: str
    stream: IO[bytes]
    owned: bool

    def close(self) -> None:
        if self.owned:
            self.stream.close()


def open_source(source: str | None) -> Source:
    """``-`` or None: standard input; an existing path: that file; else the argument must be hex."""
    if source is None or source == "-":
        return Source("standard input", sys.stdin.buffer, False)
    if os.path.isdir(source):
        raise SourceError(f"{source} is a directory, not a file", usage=True)
    if os.path.exists(source):
        try:
            return Source(source, open(source, "rb"), True)  # closed by Source.close
        except OSError as exc:
            raise SourceError(f"cannot read {source}: {exc.strerror}") from exc
    if _HEX_ARGUMENT.match(source):
        import io  # noqa: PLC0415

        return Source("the argument", io.BytesIO(source.encode("ascii")), True)
    raise SourceError(f"no such file: {source} (and it is not a hex string either)", usage=True)


TERMINAL_PROMPT: Final = (
    "manip-decode: reading standard input, a terminal: type or paste hex (or give HEX, FILE or --mcap "
    "FILE; --help says more), then Ctrl-D"
)
"""What is said on standard error before reading a terminal, which would otherwise wait in silence."""


def terminal_prompt(source: str | None) -> str | None:
    """:data:`TERMINAL_PROMPT` when ``source`` is standard input and that is a terminal, else None."""
    if source not in (None, "-"):
        return None
    try:
        return TERMINAL_PROMPT if sys.stdin.isatty() else None
    except (AttributeError, ValueError):  # no standard input at all, or a closed one
        return None


def require_file(path: str) -> str:
    """``path`` if it is a readable file; SourceError (usage) saying what is wrong otherwise."""
    if not os.path.exists(path):
        raise SourceError(f"no such file: {path}", usage=True)
    if os.path.isdir(path):
        raise SourceError(f"{path} is a directory, not a file", usage=True)
    return path


class _HexDecoder:
    """Hex text to bytes, fed in blocks; a digit pair or a ``0x`` split across blocks is carried over."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.held = b""
        self.fed = 0
        """Bytes of text fed so far (for the offset of a bad character)."""

    def feed(self, text: bytes, final: bool = False) -> bytes:
        start = self.fed - len(self.held)
        self.fed += len(text)
        text = self.held + text
        self.held = b""
        if not final and text[-1:] == b"0":  # perhaps the start of a 0x
            text, self.held = text[:-1], text[-1:]
        cleaned = _SEPARATORS.sub(b"", text)
        if not final and len(cleaned) % 2:
            # The odd digit waits for its partner (never a separator: those are gone already).
            cleaned, self.held = cleaned[:-1], cleaned[-1:] + self.held
        try:
            out = bytes.fromhex(cleaned.decode("ascii"))
        except (ValueError, UnicodeDecodeError):
            at = next((i for i, c in enumerate(text) if chr(c) not in _HEX_CHARACTERS), None)
            shown = repr(chr(text[at])) if at is not None else "?"
            where = f" at byte {start + at}" if at is not None else ""
            raise SourceError(
                f"{self.name} is not hex text: character {shown}{where} is not a hex digit"
            ) from None
        if final and len(cleaned) % 2:
            raise SourceError(f"{self.name}: odd number of hex digits (the last one has no partner)")
        return out


def _is_terminal(stream: IO[bytes]) -> bool:
    try:
        return stream.isatty() and hasattr(stream, "read1")
    except (AttributeError, ValueError):
        return False


def byte_blocks(src: Source, binary: bool | None) -> Iterator[bytes]:
    """The input's bytes, a block at a time (hex text decoded); ``binary`` None guesses from the start.
    A terminal is read a line at a time, so that one Ctrl-D after the last line ends the input."""
    read = src.stream.read1 if _is_terminal(src.stream) else src.stream.read  # type: ignore[attr-defined]
    first = read(BLOCK)
    if binary is None:
        binary = not _HEX_TEXT.match(first)
    if binary:
        block = first
        while block:
            yield block
            block = read(BLOCK)
        return
    hexes = _HexDecoder(src.name)
    block = first
    while block:
        out = hexes.feed(block)
        if out:
            yield out
        block = read(BLOCK)
    out = hexes.feed(b"", final=True)
    if out:
        yield out


def read_text(source: str | None) -> str:
    """The whole input as text (Cougar word streams are short: at most :data:`MAX_TEXT` bytes are
    read, so an endless input such as ``/dev/zero`` is refused rather than read without end)."""
    if source is not None and source != "-" and not os.path.exists(source):
        return source
    src = open_source(source)
    try:
        text = src.stream.read(MAX_TEXT + 1)
    finally:
        src.close()
    if len(text) > MAX_TEXT:
        raise SourceError(
            f"{src.name} holds more than {MAX_TEXT >> 20} MiB: too long for a Cougar word stream"
        )
    return text.decode("ascii", "replace")
