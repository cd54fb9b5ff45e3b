"""The Puma <-> Cougar word protocol (the 1985 guide, Table 1), driven by ``manip/spec/data/cougar.toml``.

Messages are a code word then a fixed number of 16-bit data words (floats take two words, the
sign/exponent word first; EXMN's reply carries its own count).  :class:`WordStream` is COMINT's input
buffer as a sans-I/O object: feed it words in any chunks and it returns complete messages in order; a
partial message waits for more words; an unknown code makes it dump the buffer and report out-of-sync,
as COMINT does (B.7).  The same class reads either direction.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from manip.codecs.errors import CodecError, DecodeError, EncodeError
from manip.codecs.pdp11float import f_to_words, words_to_f
from manip.spec import SPEC, CougarMessage

CougarDirection = Literal["command", "response"]
"""Which way Cougar words travel: commands from the Puma, responses from Cougar."""
CougarValue = float | int | tuple[float, ...] | tuple[int, ...]

_TABLES: Mapping[CougarDirection, Mapping[int, CougarMessage]] = {
    "command": SPEC.cougar_commands,
    "response": SPEC.cougar_responses,
}
_CLAUSE: Mapping[CougarDirection, str] = {
    "command": "cougar.command.layout",
    "response": "cougar.response.layout",
}


@dataclass(frozen=True)
class CougarMsg:
    """One decoded command or response with its field values and the words it was made of."""

    spec: CougarMessage
    values: Mapping[str, CougarValue]
    words: tuple[int, ...] = field(repr=False)

    @property
    def code(self) -> int:
        return self.spec.code

    @property
    def name(self) -> str:
        return self.spec.name


@dataclass(frozen=True)
class OutOfSync:
    """An unknown code word: the buffer (this word and everything after it so far) was dumped."""

    code: int
    discarded: tuple[int, ...]


@dataclass(frozen=True)
class Malformed:
    """A complete message whose data do not decode (e.g. a reserved-operand float); it was consumed."""

    words: tuple[int, ...]
    error: DecodeError


StreamItem = CougarMsg | OutOfSync | Malformed


def lookup(direction: CougarDirection, key: int | str) -> CougarMessage:
    table = _TABLES[direction]
    if isinstance(key, int):
        if key in table:
            return table[key]
    else:
        for msg in table.values():
            if msg.name == key:
                return msg
    raise KeyError(f"no Cougar {direction} {key!r} in Table 1")


def message_length(direction: CougarDirection, words: Sequence[int]) -> int | None:
    """Total words (code included) of the message starting at ``words[0]``; None if not yet knowable.

    Raises KeyError for an unknown code.
    """
    msg = _TABLES[direction][words[0]]
    fixed = msg.data_words
    if fixed is not None:
        return 1 + fixed
    # The one variable layout: a count word then that many words.
    if len(words) < 2:
        return None
    return 2 + words[1]


def encode(direction: CougarDirection, key: int | str, **values: Any) -> list[int]:
    """The words of a command or response, code word first."""
    msg = lookup(direction, key)
    words = [msg.code]
    known = {f.name for f in msg.data}
    if set(values) - known:
        raise EncodeError(f"{msg.name}: unknown field(s) {sorted(set(values) - known)}", path=msg.name)
    for f in msg.data:
        path = f"{msg.name}.{f.name}"
        if f.name not in values:
            raise EncodeError(f"missing field {f.name!r}", path=path)
        v = values[f.name]
        items = list(v) if isinstance(v, (list, tuple)) else [v]
        if f.count is None:
            words.append(len(items))
        elif len(items) != f.count:
            raise EncodeError(
                f"needs {f.count} values, got {len(items)}", path=path, clause=_CLAUSE[direction]
            )
        for i, item in enumerate(items):
            where = f"{path}[{i}]" if f.count != 1 else path
            if f.element == "float":
                try:
                    words.extend(f_to_words(item))
                except CodecError as exc:
                    raise exc.at(where) from exc
            else:
                lo, hi = (-0x8000, 0x7FFF) if f.element == "int16" else (0, 0xFFFF)
                if isinstance(item, bool) or not isinstance(item, int) or not lo <= item <= hi:
                    raise EncodeError(f"{item!r} is not an integer in {lo}..{hi}", path=where)
                words.append(item & 0xFFFF)
    return words


def _decode_body(msg: CougarMessage, words: Sequence[int], direction: CougarDirection) -> CougarMsg:
    values: dict[str, CougarValue] = {}
    pos = 1
    for f in msg.data:
        if f.count is None:
            n = words[pos]
            values[f.name] = tuple(words[pos + 1 : pos + 1 + n])
            pos += 1 + n
            continue
        items: list[Any] = []
        for i in range(f.count):
            if f.element == "float":
                try:
                    items.append(words_to_f(words[pos], words[pos + 1]))
                except CodecError as exc:
                    index = f"[{i}]" if f.count != 1 else ""
                    raise exc.at(f"{msg.name}.{f.name}{index}", 2 * pos) from exc
                pos += 2
            else:
                w = words[pos]
                items.append(w - 0x10000 if f.element == "int16" and w & 0x8000 else w)
                pos += 1
        values[f.name] = items[0] if f.count == 1 else tuple(items)
    if pos != len(words):
        raise DecodeError(
            f"{msg.name} is {pos} words, {len(words)} given", msg.name, 2 * pos, _CLAUSE[direction]
        )
    return CougarMsg(msg, values, tuple(words))


def decode(direction: CougarDirection, words: Sequence[int]) -> CougarMsg:
    """Decode exactly one message.  Offsets in errors are byte offsets (2 per word)."""
    if not words:
        raise DecodeError("no code word", "code", 0, "cougar.word-link")
    table = _TABLES[direction]
    if words[0] not in table:
        raise DecodeError(f"unknown {direction} code {words[0]}", "code", 0, "cougar.comint.unknown-code")
    need = message_length(direction, words)
    if need is None or len(words) < need:
        raise DecodeError(
            f"{table[words[0]].name} is incomplete: {len(words)} of {need if need else '?'} words",
            table[words[0]].name,
            2 * len(words),
            "cougar.comint.partial-waits",
        )
    return _decode_body(table[words[0]], words, direction)


class WordStream:
    """COMINT's input buffer: words in, complete messages (or out-of-sync reports) out, in order."""

    def __init__(self, direction: CougarDirection) -> None:
        self.direction: CougarDirection = direction
        self._buffer: list[int] = []
        self.out_of_sync_count = 0

    @property
    def pending(self) -> tuple[int, ...]:
        """Words waiting for the rest of their message."""
        return tuple(self._buffer)

    def feed(self, words: Iterable[int]) -> list[StreamItem]:
        for w in words:
            if not 0 <= w <= 0xFFFF:
                raise ValueError(f"{w!r} is not a 16-bit word")
            self._buffer.append(w)
        out: list[StreamItem] = []
        table = _TABLES[self.direction]
        while self._buffer:
            code = self._buffer[0]
            if code not in table:
                # B.7: assume sync with the other side is lost; dump everything buffered.
                out.append(OutOfSync(code, tuple(self._buffer)))
                self._buffer.clear()
                self.out_of_sync_count += 1
                break
            need = message_length(self.direction, self._buffer)
            if need is None or len(self._buffer) < need:
                break
            words, self._buffer = self._buffer[:need], self._buffer[need:]
            try:
                out.append(_decode_body(table[code], words, self.direction))
            except DecodeError as exc:
                out.append(Malformed(tuple(words), exc))
        return out
