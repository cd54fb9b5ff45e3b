"""Text in Chaos data: the Lisp Machine character set <-> Python ``str``.

A Lisp Machine writes text with its own character codes: the printing characters 040-176 are ASCII, but the
formatting characters sit 0200 above their ASCII counterparts (0210 backspace, 0211 tab, 0212 line feed,
0214 page, 0215 newline/Return), and the codes 000-037 are *graphics*, not control characters.  See
erratum ``lispm-characters`` and clauses ``describe.text-charset`` / ``text.lispm-charset``.

Decoding (every byte string decodes; nothing is lost):

* 0215 and 0212 -> ``"\\n"``, 0211 -> ``"\\t"``, 0214 -> ``"\\f"``, 0210 -> ``"\\b"``;
* 000-177 -> the ASCII character with that code, **except** 010, 011, 012, 014 and 015: those five would
  collide with the decoded formatting characters above (and on a Lisp Machine they are graphics, not
  formatting), so they go to the private range like the other special codes;
* every other code (the private set: 010, 011, 012, 014, 015 and 0200-0377 apart from 0210, 0211, 0212,
  0214, 0215) -> the private-use character U+E000 + code, e.g. 0201 (Break) -> U+E081.

Encoding is the inverse: ``"\\n"``, ``"\\r\\n"`` and a lone ``"\\r"`` -> 0215 (universal newlines), ``"\\t"``
-> 0211, ``"\\f"`` -> 0214, ``"\\b"`` -> 0210, other characters below U+0080 -> themselves, U+E000 + c for
a code c of the private set -> c.  Anything else raises :class:`EncodeError` (``text.lispm-charset``).

Round trips: ``decode_lispm(encode_lispm(s)) == s`` for every encodable ``s`` without ``"\\r"`` (carriage
returns are normalised to ``"\\n"``), and ``encode_lispm(decode_lispm(b)) == b`` for every ``b`` in which
0212 does not occur (0212, Line, reads as a newline and is written back as 0215).

``decode_lispm(b, ascii_controls=True)`` is a lenient reading for peers that wrote ASCII text: 010, 011,
012 and 014 decode as backspace, tab, newline and page, and CR LF or a lone CR as a newline.
"""

from __future__ import annotations

from manip.codecs.errors import EncodeError

PRIVATE_BASE = 0xE000
"""Private-use code point of code 0: code ``c`` of the private set decodes to ``chr(PRIVATE_BASE + c)``."""

LISPM_NEWLINE = 0o215
LISPM_LINE = 0o212
LISPM_TAB = 0o211
LISPM_PAGE = 0o214
LISPM_BACKSPACE = 0o210

_FORMATTING: dict[int, str] = {
    LISPM_BACKSPACE: "\b",
    LISPM_TAB: "\t",
    LISPM_LINE: "\n",
    LISPM_PAGE: "\f",
    LISPM_NEWLINE: "\n",
}

_ASCII_LOOKALIKES = frozenset({0o10, 0o11, 0o12, 0o14, 0o15})
"""Low codes whose ASCII meaning would collide with a decoded formatting character."""

PRIVATE_CODES: frozenset[int] = frozenset(
    c for c in range(256) if c in _ASCII_LOOKALIKES or (c >= 0o200 and c not in _FORMATTING)
)
"""Codes that decode to a private-use character (U+E000 + code)."""

_DECODE: tuple[str, ...] = tuple(
    _FORMATTING[c] if c in _FORMATTING else chr(PRIVATE_BASE + c) if c in PRIVATE_CODES else chr(c)
    for c in range(256)
)

_DECODE_ASCII: tuple[str, ...] = tuple(
    {0o10: "\b", 0o11: "\t", 0o12: "\n", 0o14: "\f", 0o15: "\r"}.get(c, _DECODE[c]) for c in range(256)
)

_ENCODE: dict[str, int] = {
    "\n": LISPM_NEWLINE,
    "\r": LISPM_NEWLINE,
    "\t": LISPM_TAB,
    "\f": LISPM_PAGE,
    "\b": LISPM_BACKSPACE,
}
for _c in range(0o200):
    if _c not in _ASCII_LOOKALIKES:
        _ENCODE.setdefault(chr(_c), _c)
for _c in PRIVATE_CODES:
    _ENCODE[chr(PRIVATE_BASE + _c)] = _c
del _c


def decode_lispm(b: bytes, *, ascii_controls: bool = False) -> str:
    """Decode Lisp Machine text (see the module docstring for the exact mapping)."""
    if not ascii_controls:
        return "".join(_DECODE[c] for c in b)
    text = "".join(_DECODE_ASCII[c] for c in b)
    return text.replace("\r\n", "\n").replace("\r", "\n")


def encode_lispm(s: str) -> bytes:
    """Encode text for the wire; raises :class:`EncodeError` for characters the set cannot carry."""
    out = bytearray()
    i = 0
    n = len(s)
    while i < n:
        ch = s[i]
        code = _ENCODE.get(ch)
        if code is None:
            raise EncodeError(
                f"character {ch!r} (U+{ord(ch):04X}) is not in the Lisp Machine character set",
                path="text",
                offset=i,
                clause="text.lispm-charset",
            )
        out.append(code)
        i += 2 if ch == "\r" and i + 1 < n and s[i + 1] == "\n" else 1
    return bytes(out)


def is_lispm_encodable(s: str) -> bool:
    """True when :func:`encode_lispm` accepts ``s``."""
    return all(ch in _ENCODE for ch in s)
