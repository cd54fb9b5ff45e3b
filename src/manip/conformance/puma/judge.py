"""The judging Cougar: the wrist computer played by the suite, for a Puma server under test.

Theory of operation
===================

:class:`JudgingCougar` is a Cougar model (``receive(words)`` / ``tick(now) -> words``, the contract of
:class:`manip.cougar.CougarSim`), so it is served exactly as ``manip-cougar`` serves the simulator: over
the emulated DRV-11J on a ``tcp://`` address (:func:`manip.cougar.cli.serve_cougar`), or, in a
virtual-time run, through the same frame codec in-process (:class:`FramedPort`, no socket, so the run
stays deterministic).  Behind it a :class:`~manip.cougar.CougarSim` answers as a conformant Cougar
would; the judge sits between the Puma and it and

* **records** every command the Puma sends, decoded by Table 1 (:class:`Heard`: the tick it came
  before, the message, or the out-of-sync run or undecodable message it was), and every response it
  gives (:class:`Said`);
* **scripts** the answers per case (:class:`CougarScript`): chosen forces, raw gauge readings computed from
  the pose the Puma last reported, New Theta Dot values, a response held back some ticks or never sent,
  guard trips at chosen ticks (:meth:`JudgingCougar.inject`).  Guard commands are kept from the
  simulator so that only the trips a case asks for happen.

A case takes the judge with :func:`current_judge`, calls :meth:`JudgingCougar.begin` with its script
(which also marks where its record starts), drives the Puma through its Chaos side, and reads
:attr:`JudgingCougar.heard` from its mark.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Final

from manip.codecs.cougar import CougarMsg, OutOfSync, StreamItem, WordStream, encode
from manip.cougar.link import CougarEnd, PumaEnd
from manip.cougar.sim import CougarSim
from manip.spec.constants import CougarCommand, CougarResponse

__all__ = [
    "CougarScript",
    "FramedPort",
    "Heard",
    "JudgingCougar",
    "NoJudgeError",
    "Said",
    "current_judge",
    "judging",
]

SENSED: Final = (CougarCommand.SEN, CougarCommand.NPR)
"""Commands that carry the sensed joint angles (``theta_sensed``)."""
_KEPT_FROM_SIM: Final = (CougarCommand.GUARDS, CougarCommand.GUARDC)


@dataclass(frozen=True, slots=True)
class Heard:
    """One item from the Puma: before tick ``tick`` (0-based count of ticks run before it)."""

    tick: int
    item: StreamItem

    @property
    def msg(self) -> CougarMsg | None:
        return self.item if isinstance(self.item, CougarMsg) else None

    @property
    def code(self) -> int | None:
        """The command code (None for an out-of-sync run or a message that did not decode)."""
        return self.item.code if isinstance(self.item, CougarMsg) else None

    def __str__(self) -> str:
        item = self.item
        if isinstance(item, CougarMsg):
            return f"tick {self.tick}: {item.name} {list(item.words[1:])}"
        if isinstance(item, OutOfSync):
            return f"tick {self.tick}: unknown code word {item.code} ({len(item.discarded)} words dumped)"
        return f"tick {self.tick}: undecodable {list(item.words)} ({item.error})"


@dataclass(frozen=True, slots=True)
class Said:
    """One response the judge sent, on tick ``tick``."""

    tick: int
    msg: CougarMsg


Gauges = Callable[[Sequence[float]], Sequence[int]]
"""Raw gauge readings (8 ints) for the sensed joint angles the Puma last sent."""


@dataclass
class CougarScript:
    """How the judge answers during one case (the defaults: as the simulator does)."""

    forces: Sequence[float] | None = None
    """FORCES responses carry these six values."""
    forces_delay: int = 0
    """Ticks a FORCES response is held back."""
    forces_omitted: bool = False
    """FORCES responses are never sent."""
    ntd: Sequence[float] | None = None
    """NTD responses carry these six values (deg/s)."""
    gauges: Gauges | None = None
    """RAW responses carry these readings."""


class JudgingCougar:
    """See the module docstring.  ``seed`` seeds the simulator behind the judge."""

    def __init__(self, seed: int = 0) -> None:
        self.sim = CougarSim(seed=seed)
        self.script = CougarScript()
        self.heard: list[Heard] = []
        self.said: list[Said] = []
        self.ticks = 0
        """Ticks run (TICK frames received)."""
        self.time: float | None = None
        """The Puma's time at the last tick."""
        self.pose: tuple[float, ...] | None = None
        """The sensed joint angles of the last SEN or NPR."""
        self.links = 0
        """DRV-11J links served (set by the server that serves the judge)."""
        self._commands = WordStream("command")
        self._responses = WordStream("response")
        self._held: list[tuple[int, list[int]]] = []
        """(tick due, words): responses held back or injected, in order."""

    # ------------------------------------------------------------------------------ cases' side
    def begin(self, script: CougarScript | None = None) -> int:
        """Start a case: its script, nothing held over from the last one; returns the record's mark
        (an index into :attr:`heard`)."""
        self.script = script or CougarScript()
        self._held.clear()
        return len(self.heard)

    def mark(self) -> int:
        """Where the record stands now (for :meth:`since`)."""
        return len(self.heard)

    def since(self, mark: int) -> list[Heard]:
        return self.heard[mark:]

    def commands(self, mark: int, code: int) -> list[Heard]:
        """The decoded commands of ``code`` heard since ``mark``."""
        return [h for h in self.heard[mark:] if h.code == code]

    def inject(self, name: str, *, after: int = 0, **values: float | int | tuple[float, ...]) -> None:
        """Send response ``name`` (Table 1) with ``values`` on the tick ``after`` ticks from now."""
        self._held.append((self.ticks + after, encode("response", name, **values)))

    async def wait_ticks(self, n: int, timeout: float) -> bool:
        """Until ``n`` more ticks have run (False when ``timeout`` seconds pass first)."""
        goal = self.ticks + n
        return await self.wait_for(lambda: self.ticks >= goal, timeout)

    async def wait_for(self, condition: Callable[[], bool], timeout: float) -> bool:
        """Until ``condition()`` holds after a tick or a word (False on timeout)."""
        loop = asyncio.get_running_loop()
        end = loop.time() + timeout
        while not condition():
            left = end - loop.time()
            if left <= 0:
                return False
            await asyncio.sleep(min(left, 0.004))
        return True

    # ------------------------------------------------------------------------------ the model
    def receive(self, words: Iterable[int]) -> None:
        items = self._commands.feed(words)
        for item in items:
            self.heard.append(Heard(self.ticks, item))
            if not isinstance(item, CougarMsg):
                continue
            if item.code in SENSED:
                sensed = item.values["theta_sensed"]
                assert isinstance(sensed, tuple)
                self.pose = tuple(float(v) for v in sensed)
            if item.code not in _KEPT_FROM_SIM:
                self.sim.receive(item.words)

    def tick(self, now: float) -> list[int]:
        self.time = now
        out: list[int] = []
        for item in self._responses.feed(self.sim.tick(now)):
            if isinstance(item, CougarMsg):
                out += self._scripted(item)
        due = [w for t, w in self._held if t <= self.ticks]
        self._held = [(t, w) for t, w in self._held if t > self.ticks]
        for words in due:
            out += words
        for item in WordStream("response").feed(out):
            if isinstance(item, CougarMsg):
                self.said.append(Said(self.ticks, item))
        self.ticks += 1
        return out

    def _scripted(self, msg: CougarMsg) -> list[int]:
        """The words the judge sends for the simulator's response ``msg``."""
        s = self.script
        if msg.code == CougarResponse.FORCES:
            words = list(msg.words)
            if s.forces is not None:
                words = encode("response", "FORCES", forces=tuple(s.forces))
            if s.forces_omitted:
                return []
            if s.forces_delay:
                self._held.append((self.ticks + s.forces_delay, words))
                return []
            return words
        if msg.code == CougarResponse.NTD and s.ntd is not None:
            return encode("response", "NTD", delta_theta=tuple(s.ntd))
        if msg.code == CougarResponse.RAW and s.gauges is not None and self.pose is not None:
            return encode("response", "RAW", gauges=tuple(int(g) for g in s.gauges(self.pose)))
        return list(msg.words)


class FramedPort:
    """The Puma's port to a judge in the same process, through the DRV-11J frame codec (PUMA, TICK,
    COUGAR and TICKED frames as bytes, both ends' state machines), without a socket: what a
    virtual-time run uses, since a TCP peer's delivery is not bound to the virtual clock."""

    def __init__(self, judge: JudgingCougar) -> None:
        self.judge = judge
        self.puma = PumaEnd()
        self.cougar = CougarEnd(judge)
        self.cougar.receive(self.puma.hello())
        self.puma.receive(self.cougar.hello())
        self._inbox: list[int] = []
        self._closed = False
        judge.links += 1

    def send(self, words: Sequence[int]) -> None:
        if not self._closed:
            self.cougar.receive(self.puma.send(words))

    def tick(self, now: float) -> None:
        if not self._closed:
            self._inbox += self.puma.receive(self.cougar.receive(self.puma.tick(now)))

    def receive(self) -> list[int]:
        out, self._inbox = self._inbox, []
        return out

    @property
    def error(self) -> str | None:
        return "port closed" if self._closed else self.puma.closed

    def close(self) -> None:
        self._closed = True


class NoJudgeError(RuntimeError):
    """A Puma case ran without a judging Cougar (not under ``manip-conform run --puma``)."""


_CURRENT: list[JudgingCougar] = []


def current_judge() -> JudgingCougar:
    """The judging Cougar of the run (NoJudgeError outside ``manip-conform run --puma``)."""
    if not _CURRENT:
        raise NoJudgeError("no judging Cougar: the puma cases run under manip-conform run --puma")
    return _CURRENT[-1]


@contextlib.contextmanager
def judging(judge: JudgingCougar) -> Iterator[JudgingCougar]:
    """Make ``judge`` the run's judging Cougar for the block."""
    _CURRENT.append(judge)
    try:
        yield judge
    finally:
        _CURRENT.remove(judge)
