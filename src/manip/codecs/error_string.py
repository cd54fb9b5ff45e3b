"""The server error string of E.2: ``where: severity code message``, optionally a NUL and 16-bit numbers.

Layout decided for manip (erratum ``error-arg-layout``; the 1985 guide's NZI example calls the NUL and the
joint mask "single bytes", which we read as loose wording, since the format paragraph says 16-bit numbers):

* the text is Lisp Machine text (:mod:`manip.codecs.lispm_text`);
* an optional NUL byte ends the text; only then are ``~`` and ``$`` in the message special;
* the numbers follow as 16-bit words, low byte first, in one of two layouts, both conformant
  (clause ``error-string.arg-layout``): *packed*, straight after the NUL, as the 1985 guide's NZI example
  writes them; or *aligned*, at an even offset *of the error string as it sits in the response data* (the
  data begin with the 2-byte request number, so an even offset within the string is an even offset in the
  packet, where a PDP-11 stores a word), with one zero pad byte after a NUL that ends at an odd offset;
* a reader tells them apart by parity (``align_args=None``, the default): an odd count of bytes after the
  NUL means the first is the pad, which must be zero.  ``align_args=True`` reads only the aligned layout,
  ``align_args=False`` only the packed one; :meth:`ErrorMessage.encode` writes either.

Substitutions (clause ``error-string.substitution``, erratum ``error-substitution``): each ``~`` takes one
number, printed as an unsigned integer; each ``$`` takes one number as a joint bit mask (bit 0 = joint 1):
6 -> ``2 and 3``.  The 1985 guide calls each special character "a place where one or more numbers should
be substituted" without saying how a reader tells how many; manip writes one number per character, and a
reader chooses (``reading=``): ``"one-to-one"`` (the default) lists surplus numbers as a problem that names
the other reading, ``"one-or-more"`` gives the surplus to the last special character, the only split a
reader can make without knowing the message (``~`` prints them joined by ", ", ``$`` by "; ").

Hard decode errors (:class:`DecodeError` with the byte offset in the error string): no ``": "`` separator,
a missing severity or code (``error-string.format``), an odd number of argument bytes
(``error-string.args``), a non-zero pad byte (``error-string.arg-layout``).  Everything else that is off
(unknown severity or code, a code that is not three letters, a colon in *where*, numbers and special
characters that do not correspond) is listed in :attr:`ErrorMessage.problems`, so a decoder never fails on it.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass, field, replace
from typing import Final, Literal

from manip.codecs.errors import DecodeError, EncodeError
from manip.codecs.lispm_text import decode_lispm, encode_lispm
from manip.spec import SPEC

RAW = "~"
"""Special character: one number printed as an unsigned integer."""
JOINT_MASK = "$"
"""Special character: one number read as a joint bit mask (bit 0 = joint 1)."""
SPECIALS = RAW + JOINT_MASK
SEPARATOR = ": "
Reading = Literal["one-to-one", "one-or-more"]
READINGS: Final[tuple[Reading, ...]] = ("one-to-one", "one-or-more")


def known_severities() -> frozenset[str]:
    """The severities of the spec (F, E, C, W, BF, BE)."""
    return frozenset(SPEC.severities)


def format_joint_mask(mask: int) -> str:
    """Joints of a bit mask (bit 0 = joint 1) in English.

    6 -> ``2 and 3``, 1 -> ``1``, 0b100011 -> ``1, 2 and 6``, 0 -> ``none``.
    """
    if mask < 0:
        raise ValueError("a joint mask is not negative")
    joints = [str(bit + 1) for bit in range(mask.bit_length()) if mask >> bit & 1]
    if not joints:
        return "none"
    if len(joints) == 1:
        return joints[0]
    return f"{', '.join(joints[:-1])} and {joints[-1]}"


def format_unsigned(value: int, radix: int = 10) -> str:
    """``value`` in ``radix`` (2..36) without a marker, digits above 9 in upper case."""
    if not 2 <= radix <= 36:
        raise ValueError(f"radix must be 2..36, not {radix}")
    if value < 0:
        raise ValueError("the numbers of an error string are unsigned")
    digits = []
    while True:
        value, d = divmod(value, radix)
        digits.append("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ"[d])
        if value == 0:
            return "".join(reversed(digits))


def count_specials(message: str) -> int:
    """How many numbers a message consumes when a NUL is present."""
    return sum(message.count(ch) for ch in SPECIALS)


def assign(message: str, args: Iterable[int], reading: Reading = "one-to-one") -> list[tuple[int, ...]]:
    """The numbers each special character of ``message`` takes, in order (an empty tuple when they ran
    out).  ``"one-or-more"``: numbers left over after the last special character go to it as well."""
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {', '.join(READINGS)}, not {reading!r}")
    numbers = list(args)
    wanted = count_specials(message)
    groups = [tuple(numbers[i : i + 1]) for i in range(wanted)]
    if reading == "one-or-more" and wanted and len(numbers) > wanted:
        groups[-1] = tuple(numbers[wanted - 1 :])
    return groups


def substitute(message: str, args: Iterable[int], *, radix: int = 10, reading: Reading = "one-to-one") -> str:
    """Replace each ``~`` and ``$`` of ``message`` by its numbers (:func:`assign`); specials beyond the
    numbers stay."""
    groups = iter(assign(message, args, reading))
    out: list[str] = []
    for ch in message:
        if ch in SPECIALS:
            numbers = next(groups)
            if numbers:
                if ch == RAW:
                    out.append(", ".join(format_unsigned(n, radix) for n in numbers))
                else:
                    out.append("; ".join(format_joint_mask(n) for n in numbers))
                continue
        out.append(ch)
    return "".join(out)


def split_error_text(text: str) -> tuple[str, str, str, str]:
    """``(where, severity, code, message)`` of the text part; offsets in errors are character offsets."""
    sep = text.find(SEPARATOR)
    if sep < 0:
        raise DecodeError(
            "no ': ' separating where from the severity",
            path="where",
            offset=len(text),
            clause="error-string.format",
        )
    where = text[:sep]
    pos = sep + len(SEPARATOR)
    end = text.find(" ", pos)
    severity = text[pos:] if end < 0 else text[pos:end]
    if not severity:
        raise DecodeError("missing severity", path="severity", offset=pos, clause="error-string.format")
    if end < 0:
        raise DecodeError("missing error code", path="code", offset=len(text), clause="error-string.format")
    pos = end + 1
    end = text.find(" ", pos)
    code = text[pos:] if end < 0 else text[pos:end]
    if not code:
        raise DecodeError("missing error code", path="code", offset=pos, clause="error-string.format")
    message = "" if end < 0 else text[end + 1 :]
    return where, severity, code, message


@dataclass(frozen=True)
class ErrorMessage:
    """One error string.  ``message`` is the template, with ``~`` and ``$`` still in it.

    ``has_nul`` says whether a NUL follows the text (it makes ``~`` and ``$`` special); it is set
    automatically when there are ``args``.  ``known_severities`` is the set
    :attr:`problems` checks severities against (the spec's when None); ``reading`` how numbers are
    matched to special characters (:func:`assign`; erratum ``error-substitution``).  Neither takes part
    in equality.
    Any three-letter code conforms: the spec's table lists the 1985 guide's and the reference server's.
    """

    where: str
    severity: str
    code: str
    message: str
    args: tuple[int, ...] = ()
    has_nul: bool = False
    known_severities: frozenset[str] | None = field(default=None, compare=False, repr=False)
    reading: Reading = field(default="one-to-one", compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "args", tuple(self.args))
        if self.args and not self.has_nul:
            object.__setattr__(self, "has_nul", True)

    @property
    def text(self) -> str:
        """The text part as sent: ``where: severity code message`` (no trailing space if no message)."""
        head = f"{self.where}{SEPARATOR}{self.severity} {self.code}"
        return f"{head} {self.message}" if self.message else head

    def render_message(self, *, radix: int = 10) -> str:
        """The message with the numbers substituted (only when a NUL is present)."""
        if not self.has_nul:
            return self.message
        return substitute(self.message, self.args, radix=radix, reading=self.reading)

    def render(self, *, radix: int = 10) -> str:
        """The whole line for a human: ``where: severity code`` and the substituted message."""
        head = f"{self.where}{SEPARATOR}{self.severity} {self.code}"
        body = self.render_message(radix=radix)
        return f"{head} {body}" if body else head

    @property
    def problems(self) -> tuple[str, ...]:
        """What is off about this error string, for a human; empty when it conforms."""
        severities = known_severities() if self.known_severities is None else self.known_severities
        out: list[str] = []
        if not self.where:
            out.append("where is empty (error-string.where-no-colon)")
        if ":" in self.where:
            out.append(f"where {self.where!r} contains a colon (error-string.where-no-colon)")
        if self.severity not in severities:
            out.append(
                f"unknown severity {self.severity!r}; expected one of {', '.join(sorted(severities))}"
                " (error-string.severity)"
            )
        # Any three letters will do: the 1985 guide lets each manipulator add codes of its own (E.2).
        if not (len(self.code) == 3 and self.code.isascii() and self.code.isalpha()):
            out.append(f"error code {self.code!r} is not three letters (error-string.code)")
        if self.has_nul:
            wanted = count_specials(self.message)
            have = len(self.args)
            surplus_ok = self.reading == "one-or-more" and wanted > 0
            if have < wanted or (have > wanted and not surplus_ok):
                more = "more" if have > wanted else "fewer"
                why = ""
                if have > wanted and wanted:
                    why = (
                        "; the 1985 guide's 'one or more numbers' per special character would give the"
                        " extra ones to the last, but manip reads one number each (erratum"
                        " error-substitution; reading='one-or-more' accepts it)"
                    )
                out.append(
                    f"{have} number(s) follow the NUL, {more} than the {wanted} ~/$ in the message{why}"
                    " (error-string.substitution)"
                )
        return tuple(out)

    def encode(self, *, align_args: bool = True) -> bytes:
        """The error-string bytes, padded as if the string starts at an even offset of the packet data.

        Only what would not read back is refused (a NUL in the text, ``": "`` in *where*, an empty or spaced
        severity or code, numbers outside 0..0xFFFF, characters outside the Lisp Machine set); a
        non-conforming but readable string (unknown severity, say) is encoded so test peers can send it.
        """
        if SEPARATOR in self.where:
            raise EncodeError("where contains ': '", path="where", clause="error-string.where-no-colon")
        for name, value in (("severity", self.severity), ("code", self.code)):
            if not value or " " in value:
                raise EncodeError(
                    f"{name} must be non-empty without spaces", path=name, clause="error-string.format"
                )
        text = self.text
        if "\0" in text:
            raise EncodeError("NUL inside the text", path="message", clause="error-string.args")
        out = bytearray(encode_lispm(text))
        if not self.has_nul:
            return bytes(out)
        out.append(0)
        if self.args and align_args and len(out) % 2:
            out.append(0)
        for i, arg in enumerate(self.args):
            if not 0 <= arg <= 0xFFFF:
                raise EncodeError(
                    f"number {arg} is not a 16-bit word", path=f"args[{i}]", clause="error-string.args"
                )
            out += arg.to_bytes(2, "little")
        return bytes(out)


def parse_error(
    data: bytes,
    *,
    align_args: bool | None = None,
    severities: Collection[str] | None = None,
    body: Literal["auto", "string", "packet"] = "auto",
    reading: Reading = "one-to-one",
) -> ErrorMessage:
    """Decode an error string, from either form of the bytes that hold it.

    ``body="string"``: ``data`` is the error string, the packet data after the 2-byte request number.
    ``body="packet"``: ``data`` is the whole data of the error packet, request number first (the number
    is skipped; :func:`manip.codecs.messages.decode_error` returns it).  ``body="auto"`` (the default)
    reads ``data`` as the string, and when that fails and its first two bytes are not text (a request
    number: a control byte, a NUL or a byte above 0177) as the packet form; an error that neither
    reading explains says which forms were tried.  Offsets in errors count from the start of ``data``.

    ``align_args``: which layout of the numbers to read (None, the default: either, told apart by the
    parity of the bytes after the NUL; True: aligned only; False: packed only; erratum ``error-arg-layout``).
    ``severities`` replaces the spec's table for :attr:`ErrorMessage.problems`; ``reading`` is how
    numbers go with special characters (:func:`assign`, erratum ``error-substitution``).
    """
    if reading not in READINGS:
        raise ValueError(f"reading must be one of {', '.join(READINGS)}, not {reading!r}")
    message = _parse(data, align_args=align_args, severities=severities, body=body)
    return message if reading == "one-to-one" else replace(message, reading=reading)


def _parse(
    data: bytes,
    *,
    align_args: bool | None,
    severities: Collection[str] | None,
    body: Literal["auto", "string", "packet"],
) -> ErrorMessage:
    if body not in ("auto", "string", "packet"):
        raise ValueError(f"body must be 'auto', 'string' or 'packet', not {body!r}")
    if body == "packet":
        return _parse_numbered(data, align_args, severities)
    try:
        return _parse_string(data, align_args, severities)
    except DecodeError as exc:
        numbered = len(data) >= 2 and any(b < 0x20 or b >= 0x80 for b in data[:2])
        if body == "string" or not numbered:
            raise
        try:
            return _parse_numbered(data, align_args, severities)
        except DecodeError:
            raise DecodeError(
                f"{exc.message} (read as an error string; read as a whole error packet, request "
                f"number {int.from_bytes(data[:2], 'little')} first, it does not parse either)",
                exc.path,
                exc.offset,
                exc.clause,
            ) from None


def _parse_numbered(data: bytes, align_args: bool | None, severities: Collection[str] | None) -> ErrorMessage:
    if len(data) < 2:
        raise DecodeError(
            f"{len(data)} bytes: an error packet's data begin with a 2-byte request number",
            path="request_number",
            offset=len(data),
            clause="response.echoes-request-number",
        )
    try:
        return _parse_string(data[2:], align_args, severities)
    except DecodeError as exc:
        raise exc.at("error", 2) from exc


def _padded(data: bytes, after_nul: int, align_args: bool | None) -> bool:
    """Whether a pad byte sits at ``after_nul``: by the parity of the bytes left (``None``), where the
    aligned layout puts one (``True``), never (``False``)."""
    if after_nul >= len(data):
        return False
    if align_args is None:
        return (len(data) - after_nul) % 2 == 1
    return align_args and after_nul % 2 == 1


def _parse_string(data: bytes, align_args: bool | None, severities: Collection[str] | None) -> ErrorMessage:
    nul = data.find(0)
    raw_text = data if nul < 0 else data[:nul]
    text = decode_lispm(bytes(raw_text))
    where, severity, code, message = split_error_text(text)
    args: tuple[int, ...] = ()
    if nul >= 0:
        pos = nul + 1
        if _padded(data, pos, align_args):
            if data[pos] != 0:
                raise DecodeError(
                    f"pad byte before the numbers is {data[pos]:#04x}, not zero",
                    path="args",
                    offset=pos,
                    clause="error-string.arg-layout",
                )
            pos += 1
        rest = data[pos:]
        if len(rest) % 2:
            raise DecodeError(
                f"{len(rest)} bytes of numbers after the NUL: not whole 16-bit words",
                path="args",
                offset=len(data) - 1,
                clause="error-string.args",
            )
        args = tuple(int.from_bytes(rest[i : i + 2], "little") for i in range(0, len(rest), 2))
    return ErrorMessage(
        where,
        severity,
        code,
        message,
        args,
        has_nul=nul >= 0,
        known_severities=None if severities is None else frozenset(severities),
    )
