"""The emulated DRV-11J: the Puma <-> Cougar word link and the Puma's clock tick over a byte stream.

Theory of operation
===================

On the 1985 hardware Puma and Cougar were joined by two DRV-11J ports (16-bit words each way) and the
Puma's KWV-11C clock drove Cougar's (Appendix A).  manip carries both over one TCP connection with the
framing of ``docs/drv11j.md`` (erratum ``drv11j-framing``), all numbers little-endian 16-bit words:

    frame   = type, count, count payload words
    HELLO   (1)  magic 0x444A ("JD"), version 1, role (1 Puma, 2 Cougar)   -- first frame each way
    PUMA    (2)  words from the Puma to Cougar
    COUGAR  (3)  words from Cougar to the Puma
    TICK    (4)  tick number (32 bits, low word first), time (signed 64-bit microseconds, low word first)
    TICKED  (5)  tick number: Cougar has run that tick; its output words were sent before this frame
    BYE     (6)  byte count, then the text bytes two to a word (low byte first): why the link ends

This module is sans-I/O: :func:`encode_frame` / :class:`FrameDecoder` (bytes in any chunks, frames out)
and the two ends as state machines -- :class:`PumaEnd` (words and ticks in, bytes out; bytes in, Cougar's
words out) and :class:`CougarEnd` (bytes in, a Cougar model driven, bytes out).  The asyncio drivers are
:mod:`manip.links.drv11j` (the Puma's port) and :mod:`manip.cougar.cli` (``manip-cougar``).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final, Protocol
from urllib.parse import urlsplit

from manip.cougar.faults import LinkDefects

__all__ = [
    "DEFAULT_PORT",
    "MAGIC",
    "MAX_PAYLOAD",
    "VERSION",
    "Bye",
    "CougarEnd",
    "CougarModel",
    "Drv11jError",
    "Frame",
    "FrameDecoder",
    "FrameType",
    "Hello",
    "PumaEnd",
    "Role",
    "Tick",
    "Ticked",
    "Words",
    "encode_frame",
    "parse_drv11j_address",
]

MAGIC: Final = 0x444A
VERSION: Final = 1
MAX_PAYLOAD: Final = 0xFFFF
"""Most payload words in one frame (longer word runs are split over several WORDS frames)."""
_US: Final = 1_000_000
RESUME_GAP: Final = 1.0 / 60.0
"""Model time between the last tick of one link and the first of the next (one 60 Hz period)."""
DEFAULT_PORT: Final = 42011
"""TCP port of ``manip-cougar`` when the address names none ("DRV-11")."""


def parse_drv11j_address(text: str) -> tuple[str, int]:
    """``tcp://HOST[:PORT]`` (port 0 = any free one, when listening) -> (host, port); ValueError."""
    parts = urlsplit(text)
    if parts.scheme != "tcp" or not parts.hostname or parts.path not in ("", "/") or parts.query:
        raise ValueError(f"{text!r} is not a DRV-11J link address (tcp://HOST:PORT)")
    try:
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"{text!r}: {exc}") from None
    return parts.hostname, DEFAULT_PORT if port is None else port


class Drv11jError(Exception):
    """The byte stream is not a valid DRV-11J link (bad frame, wrong order, wrong peer)."""


class FrameType(enum.IntEnum):
    HELLO = 1
    PUMA = 2
    COUGAR = 3
    TICK = 4
    TICKED = 5
    BYE = 6


class Role(enum.IntEnum):
    PUMA = 1
    COUGAR = 2


@dataclass(frozen=True, slots=True)
class Hello:
    role: Role
    version: int = VERSION


@dataclass(frozen=True, slots=True)
class Words:
    """Words crossing the link; ``source`` says which way."""

    source: Role
    words: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class Tick:
    """The Puma clock ticked: tick ``index`` (mod 2^32) at ``time`` seconds (microsecond resolution)."""

    index: int
    time: float


@dataclass(frozen=True, slots=True)
class Ticked:
    index: int


@dataclass(frozen=True, slots=True)
class Bye:
    reason: str


Frame = Hello | Words | Tick | Ticked | Bye


# ------------------------------------------------------------------------------------------ codec
def _pack(words: Iterable[int]) -> bytes:
    return b"".join(w.to_bytes(2, "little") for w in words)


def _frame(kind: FrameType, payload: Sequence[int]) -> bytes:
    return _pack((kind, len(payload))) + _pack(payload)


def _check_word(w: int) -> int:
    if isinstance(w, bool) or not isinstance(w, int) or not 0 <= w <= 0xFFFF:
        raise ValueError(f"{w!r} is not a 16-bit word")
    return w


def encode_frame(frame: Frame) -> bytes:
    """The bytes of ``frame`` (a long WORDS frame becomes several frames)."""
    match frame:
        case Hello(role, version):
            return _frame(FrameType.HELLO, (MAGIC, version & 0xFFFF, int(role)))
        case Words(source, words):
            kind = FrameType.PUMA if source is Role.PUMA else FrameType.COUGAR
            ws = [_check_word(w) for w in words]
            chunks = [ws[i : i + MAX_PAYLOAD] for i in range(0, len(ws), MAX_PAYLOAD)] or [[]]
            return b"".join(_frame(kind, c) for c in chunks)
        case Tick(index, time):
            if not math.isfinite(time):
                raise ValueError("tick time must be finite")
            us = round(time * _US) & 0xFFFF_FFFF_FFFF_FFFF
            i = index & 0xFFFF_FFFF
            return _frame(
                FrameType.TICK, (i & 0xFFFF, i >> 16, *((us >> s) & 0xFFFF for s in (0, 16, 32, 48)))
            )
        case Ticked(index):
            i = index & 0xFFFF_FFFF
            return _frame(FrameType.TICKED, (i & 0xFFFF, i >> 16))
        case Bye(reason):
            raw = reason.encode("ascii", "replace")[: 2 * (MAX_PAYLOAD - 1)]
            padded = raw + b"\0" * (len(raw) % 2)
            return _frame(
                FrameType.BYE,
                (len(raw), *(int.from_bytes(padded[i : i + 2], "little") for i in range(0, len(padded), 2))),
            )
    raise TypeError(f"not a frame: {frame!r}")


def _decode(kind: int, payload: list[int]) -> Frame:
    try:
        ftype = FrameType(kind)
    except ValueError:
        raise Drv11jError(f"unknown frame type {kind}") from None
    n = len(payload)
    match ftype:
        case FrameType.HELLO:
            if n != 3 or payload[0] != MAGIC:
                raise Drv11jError("not a DRV-11J link (bad HELLO)")
            try:
                role = Role(payload[2])
            except ValueError:
                raise Drv11jError(f"HELLO names unknown role {payload[2]}") from None
            return Hello(role, payload[1])
        case FrameType.PUMA | FrameType.COUGAR:
            return Words(Role.PUMA if ftype is FrameType.PUMA else Role.COUGAR, tuple(payload))
        case FrameType.TICK:
            if n != 6:
                raise Drv11jError(f"TICK has {n} words, 6 expected")
            us = sum(w << s for w, s in zip(payload[2:], (0, 16, 32, 48), strict=True))
            if us >= 1 << 63:
                us -= 1 << 64
            return Tick(payload[0] | payload[1] << 16, us / _US)
        case FrameType.TICKED:
            if n != 2:
                raise Drv11jError(f"TICKED has {n} words, 2 expected")
            return Ticked(payload[0] | payload[1] << 16)
        case FrameType.BYE:
            if n < 1 or payload[0] > 2 * (n - 1):
                raise Drv11jError("BYE text length does not match the frame")
            raw = _pack(payload[1:])[: payload[0]]
            return Bye(raw.decode("ascii", "replace"))
    raise AssertionError(ftype)  # pragma: no cover


class FrameDecoder:
    """Bytes in, in any chunks; complete frames out, in order.  A bad frame raises Drv11jError."""

    def __init__(self, *, skip_bad: bool = False) -> None:
        self._buf = bytearray()
        self._skip_bad = skip_bad
        """Drop a frame that cannot be decoded and go on (only for the fault ``link-skips-bad-frames``)."""

    @property
    def pending(self) -> int:
        """Bytes waiting for the rest of their frame."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        out: list[Frame] = []
        buf = self._buf
        pos = 0
        while len(buf) - pos >= 4:
            kind = int.from_bytes(buf[pos : pos + 2], "little")
            n = int.from_bytes(buf[pos + 2 : pos + 4], "little")
            end = pos + 4 + 2 * n
            if len(buf) < end:
                break
            payload = [int.from_bytes(buf[i : i + 2], "little") for i in range(pos + 4, end, 2)]
            pos = end
            try:
                out.append(_decode(kind, payload))
            except Drv11jError:
                if not self._skip_bad:
                    raise
        del buf[:pos]
        return out


# ------------------------------------------------------------------------------------------ the ends
class CougarModel(Protocol):
    """What :class:`CougarEnd` drives (the contract of :class:`manip.cougar.CougarSim`)."""

    def receive(self, words: Iterable[int]) -> None: ...

    def tick(self, now: float) -> list[int]: ...


class _End:
    role: Role

    def __init__(self, defects: LinkDefects | None = None) -> None:
        self._defects = defects or LinkDefects()
        """Defects of the link (:mod:`manip.cougar.faults`, ``link-*``): only a Cougar's end has any."""
        self._decoder = FrameDecoder(skip_bad=not self._defects.ends_on_bad_frame)
        self.peer_ready = False
        """The peer's HELLO has arrived."""
        self.closed: str | None = None
        """Why the link ended (the peer's BYE, or the error found), None while it runs."""

    def hello(self) -> bytes:
        """The first bytes to send."""
        return encode_frame(Hello(self.role))

    def _frames(self, data: bytes) -> list[Frame]:
        if self.closed is not None:
            return []
        try:
            frames = self._decoder.feed(data)
        except Drv11jError as exc:
            self.closed = str(exc)
            raise
        good: list[Frame] = []
        for frame in frames:
            if not self.peer_ready and self._greeted(frame):
                continue
            if isinstance(frame, Bye) and not self._defects.ends_on_bye:
                continue
            if isinstance(frame, Bye):
                self.closed = frame.reason or "closed by the peer"
                break
            good.append(frame)
        return good

    def _greeted(self, frame: Frame) -> bool:
        """Check the peer's first frame: True if it was the HELLO (taken), False if a defect let the link
        start without one (the frame is then taken as any other); Drv11jError for a bad first frame."""
        if not isinstance(frame, Hello):
            if not self._defects.requires_hello_first:
                self.peer_ready = True
                return False
            self.closed = "the peer did not start with HELLO"
            raise Drv11jError(self.closed)
        wrong_side = frame.role is self.role and self._defects.ends_on_wrong_side
        wrong_version = frame.version != VERSION and self._defects.checks_version
        if wrong_version or wrong_side:
            self.closed = f"incompatible peer (role {frame.role.name}, version {frame.version})"
            raise Drv11jError(self.closed)
        self.peer_ready = True
        return True

    def bye(self, reason: str) -> bytes:
        """Bytes that end the link."""
        self.closed = self.closed or reason
        return encode_frame(Bye(reason))


class PumaEnd(_End):
    """The Puma's end: words and ticks out, Cougar's words in."""

    role = Role.PUMA

    def __init__(self) -> None:
        super().__init__()
        self.ticks_sent = 0
        self.ticks_done = 0
        """Ticks Cougar has reported run (TICKED)."""

    def send(self, words: Sequence[int]) -> bytes:
        return encode_frame(Words(Role.PUMA, tuple(words))) if words else b""

    def tick(self, now: float) -> bytes:
        index = self.ticks_sent
        self.ticks_sent += 1
        return encode_frame(Tick(index, now))

    def receive(self, data: bytes) -> list[int]:
        """Cougar's words in ``data``; raises Drv11jError on a bad stream."""
        out: list[int] = []
        for frame in self._frames(data):
            if isinstance(frame, Words) and frame.source is Role.COUGAR:
                if self.ticks_done == self.ticks_sent:  # its tick was over: TICKED comes after its words
                    self.closed = f"words from Cougar after TICKED #{self.ticks_done - 1}, with no TICK since"
                    raise Drv11jError(self.closed)
                out.extend(frame.words)
            elif isinstance(frame, Ticked):
                self.ticks_done = frame.index + 1
            else:
                self.closed = f"unexpected {type(frame).__name__} frame from Cougar"
                raise Drv11jError(self.closed)
        return out


class CougarEnd(_End):
    """Cougar's end: drives ``cougar`` from the frames received and returns the bytes to send back."""

    role = Role.COUGAR

    def __init__(
        self, cougar: CougarModel, *, resume_after: float | None = None, defects: LinkDefects | None = None
    ) -> None:
        super().__init__(defects)
        self.cougar = cougar
        self.ticks = 0
        self.last_time: float | None = resume_after
        """The model time of the last tick run (``resume_after`` before the first): the time a
        Cougar that outlives the link resumes after on the next one (``CougarServer``)."""
        self._shift = 0.0

    def _model_time(self, time: float) -> float:
        """Each link's clock has its own origin (docs/drv11j.md): a first tick behind the model's last
        time is moved to one period after it; a later tick going backwards is a bad stream."""
        last = self.last_time
        if self.ticks == 0 and last is not None and time <= last:
            self._shift = last + RESUME_GAP - time
        now = time + self._shift
        if last is not None and now < last and not self._defects.ends_on_tick_backwards:
            return last
        if last is not None and now < last:
            self.closed = f"tick time went backwards ({time} s after {last - self._shift} s)"
            raise Drv11jError(self.closed)
        return now

    def receive(self, data: bytes) -> bytes:
        out: list[bytes] = []
        for frame in self._frames(data):
            if isinstance(frame, Words) and frame.source is Role.PUMA:
                self.cougar.receive(frame.words)
            elif isinstance(frame, Tick):
                now = self._model_time(frame.time)
                words = self.cougar.tick(now)
                self.ticks += 1
                self.last_time = now
                ticked = encode_frame(Ticked(frame.index))
                if not self._defects.ticked_after_words:
                    out.append(ticked)
                if words:
                    out.append(encode_frame(Words(Role.COUGAR, tuple(words))))
                if self._defects.ticked_after_words:
                    out.append(ticked)
            elif not self._defects.ends_on_wrong_side:
                continue
            else:
                self.closed = f"unexpected {type(frame).__name__} frame from the Puma"
                raise Drv11jError(self.closed)
        return b"".join(out)
