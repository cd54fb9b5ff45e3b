"""Reader and printer for the small Lisp subset of the describe-self reply (E.1 Opcode 200).

Values (:data:`LispValue`):

* ``int``; ``float``; ``str``;
* :class:`Keyword` (``:brand-name``) and :class:`Symbol` (``t``, ``quote``): names are case-insensitive and
  stored in lower case;
* proper lists as Python ``list`` (``NIL`` and ``()`` read as ``[]``);
* :class:`Cons` for dotted pairs and dotted lists: ``(a . b)`` is ``Cons(a, b)`` and ``(a b . c)`` is
  ``Cons(a, Cons(b, c))``.  A ``Cons`` never has a list as its cdr (that value is a proper list); use
  :func:`cons` to build one from any cdr.

Reading (traditional Lisp Machine syntax, clause ``describe.alist-readable``, erratum ``octal-numbers``):

* bare integers are in ``base`` (8 by default, the protocol's convention); a trailing dot means decimal
  (``6.``, ``-12.``); ``#o``, ``#x``, ``#b`` and ``#NNr`` give an explicit radix;
* floats are decimal: ``1.5``, ``.5``, ``1.5e3``, ``1e3`` (exponent marker ``e`` only);
* a token of digits that are not all valid in ``base`` (``19`` in base 8) is an error, not a symbol, of
  clause ``describe.numbers-octal``: a number written in decimal without its trailing point;
* strings are delimited by ``"``; the escape character is ``/`` (Zetalisp).  ``\\`` is an ordinary character
  unless the caller selects Common Lisp syntax with ``escape="\\\\"``;
* ``'x`` reads as ``(quote x)``; ``;`` starts a comment to the end of the line;
* whitespace is space, tab, newline, return, page and vertical tab, plus the private-use characters that
  :func:`manip.codecs.lispm_text.decode_lispm` gives for raw ASCII tab, line feed, page and return (so a
  reply written by an ASCII peer still reads);
* not supported (a :class:`DecodeError`): escaped or ``|quoted|`` symbols, package prefixes, other ``#``
  syntax, backquote and comma; in a description (:func:`read_alist`), lists nested deeper than
  :data:`MAX_DEPTH` (64; erratum ``lisp-nesting-depth``).

Printing follows ``prin1`` with ``base`` 8 and ``*nopoint`` nil: octal integers without a marker; in base 10
a trailing dot unless ``nopoint``; symbols and keywords in upper case unless ``upper=False``; floats in the
shortest decimal form that reads back exactly.  For every value ``v`` of the subset and base 8 or 10,
``read_lisp(print_lisp(v, base=b), base=b) == v``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypeAlias

from manip.codecs.errors import DecodeError, EncodeError

READ_CLAUSE = "describe.alist-readable"
MAX_DEPTH = 64
"""A description's lists (and quotes) nested deeper than this are refused by :func:`read_alist`
(erratum ``lisp-nesting-depth``): a description is an association list a few levels deep, and whatever
walks a value recursively (the client's text and JSON output, ``json``) stays far from Python's
recursion limit.  :func:`read_lisp` itself reads any depth unless given ``max_depth``."""
SHAPE_CLAUSE = "describe.alist-shape"
OCTAL_CLAUSE = "describe.numbers-octal"
"""The clause of a token of digits not valid in the reader's base: a decimal number without its point."""


@dataclass(frozen=True, slots=True)
class Keyword:
    """A keyword such as ``:BRAND-NAME``; ``name`` is stored without the colon, in lower case."""

    name: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.name.lower())


@dataclass(frozen=True, slots=True)
class Symbol:
    """An ordinary symbol; ``name`` is stored in lower case."""

    name: str

    def __post_init__(self) -> None:
        object.__setattr__(self, "name", self.name.lower())


@dataclass(frozen=True, slots=True)
class Cons:
    """A dotted pair.  ``cdr`` is never a list: ``(a . (b))`` is the proper list ``[a, b]``."""

    car: LispValue
    cdr: LispValue

    def __post_init__(self) -> None:
        if isinstance(self.cdr, list):
            raise ValueError("a Cons whose cdr is a list is a proper list; build it with cons()")


LispValue: TypeAlias = int | float | str | Keyword | Symbol | Cons | list["LispValue"]


def cons(car: LispValue, cdr: LispValue) -> LispValue:
    """``(car . cdr)`` in canonical form: a list when ``cdr`` is a list, else a :class:`Cons`."""
    if isinstance(cdr, list):
        return [car, *cdr]
    return Cons(car, cdr)


# ---------------------------------------------------------------------------------------------- reader

_WHITESPACE = frozenset(" \t\n\r\f\v\ue009\ue00a\ue00c\ue00d")
_TERMINATORS = frozenset("()\";'`,") | _WHITESPACE
_DECIMAL_INT = re.compile(r"[+-]?[0-9]+\.")
_SIGNED_DIGITS = re.compile(r"([+-]?)([0-9a-zA-Z]+)")
_FLOAT = re.compile(r"[+-]?(?:[0-9]*\.[0-9]+(?:[eE][+-]?[0-9]+)?|[0-9]+(?:\.[0-9]*)?[eE][+-]?[0-9]+)")
_SHARP_RADIX = re.compile(r"#(?:([oOxXbB])|([0-9]+)[rR])(.*)")
_SHARP_LETTERS = {"o": 8, "x": 16, "b": 2}
_DIGITS = "0123456789abcdefghijklmnopqrstuvwxyz"


class _Missing:
    pass


_MISSING = _Missing()


@dataclass
class _Frame:
    start: int
    quote: bool = False
    items: list[LispValue] | None = None
    dot: int | None = None
    tail: LispValue | _Missing = _MISSING


def _error(message: str, offset: int) -> DecodeError:
    return DecodeError(message, offset=offset, clause=READ_CLAUSE)


def _check_base(base: int) -> None:
    if not 2 <= base <= 36:
        raise ValueError(f"base must be 2..36, not {base}")


def _parse_digits(sign: str, digits: str, radix: int) -> int | None:
    """The integer, or None when a digit is not valid in ``radix``."""
    value = 0
    for ch in digits.lower():
        d = _DIGITS.find(ch)
        if d < 0 or d >= radix:
            return None
        value = value * radix + d
    return -value if sign == "-" else value


def _classify(token: str, base: int, start: int, escape: str) -> LispValue:
    """The value of one token (number, keyword, symbol or NIL)."""
    if escape in token or "|" in token:
        raise _error(f"escaped characters in symbol {token!r} are not supported", start)
    if token.startswith("#"):
        m = _SHARP_RADIX.fullmatch(token)
        radix = 0
        if m:
            radix = _SHARP_LETTERS[m.group(1).lower()] if m.group(1) else int(m.group(2))
        if not m or not 2 <= radix <= 36:
            raise _error(f"unsupported # syntax {token!r}", start)
        body = _SIGNED_DIGITS.fullmatch(m.group(3))
        value = _parse_digits(body.group(1), body.group(2), radix) if body else None
        if value is None:
            raise _error(f"{token!r} is not an integer in radix {radix}", start)
        return value
    if _DECIMAL_INT.fullmatch(token):
        return int(token[:-1], 10)
    m = _SIGNED_DIGITS.fullmatch(token)
    if m:
        value = _parse_digits(m.group(1), m.group(2), base)
        if value is not None:
            return value
        if base <= 10 and m.group(2).isdigit() and m.group(2).isascii():
            raise DecodeError(
                f"{token!r} has digits that are not valid in base {base} (a decimal number needs its point)",
                offset=start,
                clause=OCTAL_CLAUSE,
            )
    if _FLOAT.fullmatch(token):
        return float(token)
    if set(token) == {"."}:
        raise _error(f"token {token!r} of only dots", start)
    if token.startswith(":"):
        name = token[1:]
        if not name or ":" in name:
            raise _error(f"bad keyword {token!r}", start)
        return Keyword(name)
    if ":" in token:
        raise _error(f"package-qualified symbol {token!r} is not supported", start)
    if token.lower() == "nil":
        return []
    return Symbol(token)


def _build(frame: _Frame) -> LispValue:
    items = frame.items if frame.items is not None else []
    if isinstance(frame.tail, _Missing):
        return items
    value: LispValue = frame.tail
    for item in reversed(items):
        value = cons(item, value)
    return value


class _Reader:
    def __init__(self, text: str, base: int, escape: str, max_depth: int | None = None) -> None:
        _check_base(base)
        self.max_depth = max_depth
        if len(escape) != 1 or escape in _TERMINATORS or escape.isalnum():
            raise ValueError(f"bad escape character {escape!r}")
        self.text = text
        self.base = base
        self.escape = escape
        self.pos = 0

    def skip_blank(self) -> None:
        text, n = self.text, len(self.text)
        while self.pos < n:
            ch = text[self.pos]
            if ch in _WHITESPACE:
                self.pos += 1
            elif ch == ";":
                end = text.find("\n", self.pos)
                self.pos = n if end < 0 else end + 1
            else:
                return

    def read_string(self) -> str:
        start = self.pos
        text, n, esc = self.text, len(self.text), self.escape
        out: list[str] = []
        i = start + 1
        while i < n:
            ch = text[i]
            if ch == '"':
                self.pos = i + 1
                return "".join(out)
            if ch == esc:
                i += 1
                if i >= n:
                    break
                ch = text[i]
            out.append(ch)
            i += 1
        raise _error("unterminated string", start)

    def read_token(self) -> str:
        start = self.pos
        text, n = self.text, len(self.text)
        i = start
        while i < n and text[i] not in _TERMINATORS:
            i += 1
        self.pos = i
        return text[start:i]

    def read(self) -> LispValue | _Missing:
        """The next datum, or ``_MISSING`` at the end of the text."""
        stack: list[_Frame] = []
        while True:
            self.skip_blank()
            if self.pos >= len(self.text):
                if stack:
                    what = "quote" if stack[-1].quote else "list"
                    raise _error(f"end of text inside a {what} opened here", stack[-1].start)
                return _MISSING
            start = self.pos
            ch = self.text[start]
            value: LispValue
            if ch in "('" and self.max_depth is not None and len(stack) >= self.max_depth:
                raise _error(f"lists nested deeper than {self.max_depth} (manip reads no deeper)", start)
            if ch == "(":
                stack.append(_Frame(start, items=[]))
                self.pos += 1
                continue
            if ch == "'":
                stack.append(_Frame(start, quote=True))
                self.pos += 1
                continue
            if ch == ")":
                if not stack:
                    raise _error("unbalanced ')'", start)
                frame = stack.pop()
                if frame.quote:
                    raise _error("quote with nothing to quote", frame.start)
                if frame.dot is not None and isinstance(frame.tail, _Missing):
                    raise _error("nothing after the dot of a dotted list", frame.dot)
                self.pos += 1
                value = _build(frame)
            elif ch == '"':
                value = self.read_string()
            elif ch in "`,":
                raise _error(f"{ch!r} syntax is not supported", start)
            else:
                token = self.read_token()
                if token == ".":
                    top = stack[-1] if stack else None
                    if top is None or top.quote or not top.items or top.dot is not None:
                        raise _error("misplaced dot", start)
                    top.dot = start
                    continue
                value = _classify(token, self.base, start, self.escape)
            while stack:
                top = stack[-1]
                if top.quote:
                    stack.pop()
                    value = [Symbol("quote"), value]
                    continue
                if top.dot is None:
                    assert top.items is not None
                    top.items.append(value)
                elif isinstance(top.tail, _Missing):
                    top.tail = value
                else:
                    raise _error("more than one datum after the dot of a dotted list", start)
                break
            else:
                return value


def read_all(text: str, *, base: int = 8, escape: str = "/", max_depth: int | None = None) -> list[LispValue]:
    """Every datum of ``text`` in order (an empty or blank text gives ``[]``); ``max_depth``: see
    :func:`read_lisp`."""
    reader = _Reader(text, base, escape, max_depth)
    out: list[LispValue] = []
    while not isinstance(value := reader.read(), _Missing):
        out.append(value)
    return out


def read_lisp(text: str, *, base: int = 8, escape: str = "/", max_depth: int | None = None) -> LispValue:
    """Exactly one datum, optionally surrounded by whitespace and comments.  The reader itself is not
    recursive and reads any depth; ``max_depth`` refuses lists nested deeper (a DecodeError)."""
    reader = _Reader(text, base, escape, max_depth)
    value = reader.read()
    if isinstance(value, _Missing):
        raise _error("no datum in the text", len(text))
    reader.skip_blank()
    if reader.pos < len(text):
        raise _error("text after the datum", reader.pos)
    return value


# --------------------------------------------------------------------------------------------- printer


@dataclass(frozen=True, slots=True)
class _Lit:
    text: str


def _format_int(v: int, base: int, nopoint: bool) -> str:
    if base == 10:
        return f"{v}" if nopoint else f"{v}."
    sign = "-" if v < 0 else ""
    v = abs(v)
    digits = []
    while True:
        v, d = divmod(v, base)
        digits.append(_DIGITS[d].upper())
        if v == 0:
            break
    return sign + "".join(reversed(digits))


def _format_float(v: float) -> str:
    if not math.isfinite(v):
        raise EncodeError(f"{v!r} has no printed representation", clause=READ_CLAUSE)
    text = repr(v)
    mantissa, _, exponent = text.partition("e")
    if "." not in mantissa:
        mantissa += ".0"
    return f"{mantissa}e{int(exponent)}" if exponent else mantissa


def _format_name(prefix: str, name: str, value: Keyword | Symbol, base: int, upper: bool, esc: str) -> str:
    token = prefix + (name.upper() if upper else name)
    ok = bool(name) and not any(ch in _TERMINATORS for ch in token)
    if ok:
        try:
            ok = _classify(token, base, 0, esc) == value
        except DecodeError:
            ok = False
    if not ok:
        raise EncodeError(f"{value!r} cannot be printed as a plain token in base {base}", clause=READ_CLAUSE)
    return token


def _format_string(s: str, esc: str) -> str:
    return '"' + s.replace(esc, esc + esc).replace('"', esc + '"') + '"'


def print_lisp(
    value: LispValue, *, base: int = 8, nopoint: bool = False, upper: bool = True, escape: str = "/"
) -> str:
    """Print ``value`` so that :func:`read_lisp` with the same ``base`` and ``escape`` reads it back."""
    _check_base(base)
    out: list[str] = []
    stack: list[LispValue | _Lit] = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, _Lit):
            out.append(item.text)
        elif isinstance(item, bool):
            raise EncodeError(f"{item!r} is not a Lisp value", clause=READ_CLAUSE)
        elif isinstance(item, int):
            out.append(_format_int(item, base, nopoint))
        elif isinstance(item, float):
            out.append(_format_float(item))
        elif isinstance(item, str):
            out.append(_format_string(item, escape))
        elif isinstance(item, Keyword):
            out.append(_format_name(":", item.name, item, base, upper, escape))
        elif isinstance(item, Symbol):
            out.append(_format_name("", item.name, item, base, upper, escape))
        elif isinstance(item, list):
            if not item:
                out.append("NIL" if upper else "nil")
                continue
            stack.append(_Lit(")"))
            for i, element in enumerate(reversed(item)):
                if i:
                    stack.append(_Lit(" "))
                stack.append(element)
            stack.append(_Lit("("))
        elif isinstance(item, Cons):
            elements: list[LispValue] = [item.car]
            tail = item.cdr
            while isinstance(tail, Cons):
                elements.append(tail.car)
                tail = tail.cdr
            stack.extend((_Lit(")"), tail, _Lit(" . ")))
            for i, element in enumerate(reversed(elements)):
                if i:
                    stack.append(_Lit(" "))
                stack.append(element)
            stack.append(_Lit("("))
        else:
            raise EncodeError(f"{type(item).__name__} is not a Lisp value", clause=READ_CLAUSE)
    return "".join(out)


# ---------------------------------------------------------------------------------------------- alists


def alist_to_dict(value: LispValue) -> dict[str, LispValue]:
    """An alist as a dict keyed by keyword name (lower case).

    An entry ``(:key . value)`` gives ``value``; an entry ``(:key v1 v2 ...)`` gives the list
    ``[v1, v2, ...]`` (in both cases the entry's cdr).  Anything else, and a key given twice, is a
    :class:`DecodeError` with clause ``describe.alist-shape``.
    """
    if not isinstance(value, list):
        raise DecodeError("the description is not a list", path="alist", clause=SHAPE_CLAUSE)
    out: dict[str, LispValue] = {}
    for i, entry in enumerate(value):
        path = f"alist[{i}]"
        key: LispValue
        if isinstance(entry, Cons):
            key, rest = entry.car, entry.cdr
        elif isinstance(entry, list) and entry:
            key, rest = entry[0], entry[1:]
        else:
            raise DecodeError("entry is not a (key . value) pair or a list", path=path, clause=SHAPE_CLAUSE)
        if not isinstance(key, Keyword):
            raise DecodeError("entry key is not a keyword", path=path, clause=SHAPE_CLAUSE)
        if key.name in out:
            raise DecodeError(f"keyword :{key.name} appears twice", path=path, clause=SHAPE_CLAUSE)
        out[key.name] = rest
    return out


def dict_to_alist(d: Mapping[str, LispValue]) -> list[LispValue]:
    """The inverse of :func:`alist_to_dict`: list values become ``(:key v ...)``, others ``(:key . v)``.

    Keys are keyword names; they are lower-cased like every keyword.
    """
    return [cons(Keyword(k), v) for k, v in d.items()]


def read_alist(
    text: str, *, base: int = 8, escape: str = "/", max_depth: int | None = MAX_DEPTH
) -> dict[str, LispValue]:
    """:func:`read_lisp` then :func:`alist_to_dict`: the describe-self text as a dict, its lists nested
    at most ``max_depth`` deep (:data:`MAX_DEPTH`, erratum ``lisp-nesting-depth``)."""
    return alist_to_dict(read_lisp(text, base=base, escape=escape, max_depth=max_depth))
