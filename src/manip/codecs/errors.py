"""Errors raised by the codecs.

Every decode failure says *what* is wrong, *where* (a field path and a byte offset into the input) and
*which clause* of the spec it violates, so a user can act on it without reading the codec.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(eq=False)
class CodecError(ValueError):
    """Base class: a value could not be encoded or decoded."""

    message: str
    path: str = ""
    offset: int | None = None
    clause: str | None = None

    def __post_init__(self) -> None:
        super().__init__(self.message)

    def __str__(self) -> str:
        where = []
        if self.path:
            where.append(self.path)
        if self.offset is not None:
            where.append(f"byte {self.offset}")
        text = f"{self.message}"
        if where:
            text = f"{' at '.join(where)}: {text}"
        if self.clause:
            text += f" [{self.clause}]"
        return text

    def at(self, path: str, offset: int | None = None) -> CodecError:
        """Return this error re-anchored under an outer field path / byte offset."""
        inner = self.path
        joined = f"{path}.{inner}" if path and inner else (path or inner)
        off = self.offset
        if offset is not None:
            off = offset + (off or 0)
        return type(self)(self.message, joined, off, self.clause)


class DecodeError(CodecError):
    """Bytes (or words) that do not decode to a valid message."""


class EncodeError(CodecError):
    """A value that cannot be represented on the wire."""
