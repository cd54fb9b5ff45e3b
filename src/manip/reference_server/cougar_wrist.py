"""The Puma's wrist processes: the Puma extension opcodes served by talking to Cougar over a port.

Theory of operation
===================

:class:`CougarWrist` is the :class:`~manip.reference_server.wrist.Wrist` of a Puma with a Cougar.  It is
sans-I/O: the words go through a :class:`~manip.reference_server.cougar_port.CougarPort` (in-process
simulator or emulated DRV-11J), and time comes in as arguments.  It plays the two wrist processes of
Part II §5.3 and the move process's part in compliance (§5.2, §6.4):

* **Output process.**  Each Puma clock tick (:meth:`CougarWrist.tick`, once per servo cycle the arm has
  run) it sends, in the 1985 guide's priority order: the *New Position and Rate* command (NPR; a flag with the
  latest data, set by the compliant interpolation), *Reset Wrist* (RST; a flag), the *interrupt queue*
  (wrist packets from the move process: the sensed angles, SEN, whenever the arm has moved and no NPR
  told Cougar where it is -- erratum ``wrist-sen``), then the *user queue* (commands from requests),
  and then ticks Cougar.  Cycles the driver skipped are caught up with extra ticks (at most
  :data:`MAX_CATCH_UP`) so Cougar's filters see the servo rate.
* **Input process.**  Words from Cougar go through a :class:`~manip.codecs.cougar.WordStream`: New
  Theta Dot (NTD) is stored for the compliant interpolation; replies (forces, raw gauges, examine data,
  version) resolve the oldest request waiting for that response code; guard trips become
  :class:`~manip.reference_server.wrist.GuardHit` events (a stop-the-move guard halts the arm first:
  current and queued segments dropped, :meth:`~manip.arm.sim.ArmSim.halt`, and the segments dropped
  are named in an asynchronous warning, ``wrist: W AWA``, since they will never be reported complete --
  erratum ``guard-stop``); out-of-sync and undecodable words become asynchronous warnings.
* **Requests.**  Configuration opcodes (spring, damping, joint damping, frame vector, weight, guards,
  gauge offsets, commanded force, deposit) put their command on the user queue and are answered done at
  once (§5.1).  Opcodes that need Cougar's data (read forces -- preceded by SEN as §6.3 says --, raw
  gauges, examine, version) answer with a :class:`~manip.reference_server.wrist.Pending` resolved by the
  reply, or failed after ``reply_timeout`` seconds with ``wrist: E WNR`` (erratum ``wrist-timeout``).
  A reply that comes after its request timed out is recognised (replies come back in order) and dropped.
  Compliant move queues a segment of one of the two compliant schemes; calibrate-wrist is a small
  procedure (:class:`_Calibration`) that moves the arm through two poses (§8.3).
* **Compliance** (:meth:`CougarWrist.adjust`, the arm's :class:`~manip.arm.sim.Compliance`).  Every servo
  cycle of a compliant segment it sets the NPR flag with the sensed angles, the nominal commanded
  angles and the difference of their rates, and uses the latest NTD received (from an earlier tick, as
  §6.4 says).  NTD is a joint-rate correction in deg/s (erratum ``compliant-schemes``): the *motion*
  scheme integrates it into an offset from the nominal path (commanded = nominal + Σ NTD·T, clamped to
  the joint limits); the *debugging* scheme exchanges NPR/NTD the same way but follows the nominal path,
  only recording the corrections (:attr:`CougarWrist.meter`, the last 128 cycles) -- compliance run
  open loop.  A compliant episode starts with a reset (RST) and zero offset; so does the first cycle
  after a break.  When the episode ends the arm keeps the last offset -- it stays where the contact let
  it go -- and what follows starts from there (the arm's side, erratum ``compliant-segment-end``).
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

from manip.arm.kinematics import Joints, forward
from manip.arm.sim import AbortCause, ArmSim, MotionAborted
from manip.arm.trajectory import Scheme
from manip.codecs.cougar import CougarMsg, Malformed, OutOfSync, WordStream, encode, lookup
from manip.codecs.error_string import SPECIALS, ErrorMessage
from manip.codecs.messages import Value
from manip.cougar.environment import Environment
from manip.cougar.memory import region
from manip.cougar.sim import CougarSim
from manip.links.drv11j import Drv11jPort
from manip.reference_server import errors
from manip.reference_server.cougar_port import CougarPort, SimPort
from manip.reference_server.errors import RequestError
from manip.reference_server.session import WRIST_OPERATIONS
from manip.reference_server.wrist import GuardHit, Pending, WristDefects, WristEvent, WristNotice
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import CougarCommand, CougarResponse

__all__ = [
    "DEFAULT_REPLY_TIMEOUT",
    "GUARD_INDEX_MASK",
    "GUARD_STOP_BIT",
    "MAX_CATCH_UP",
    "METER_CYCLES",
    "PUMA_WRIST_VERSION",
    "CalibrationSettings",
    "CougarWrist",
    "MeterEntry",
    "WristStats",
    "calibration_poses",
    "dropped_warning",
    "make_cougar_wrist",
]

DEFAULT_REPLY_TIMEOUT: Final = 0.5
"""Seconds a request waits for Cougar's reply before it fails with E WNR (erratum ``wrist-timeout``)."""
MAX_CATCH_UP: Final = 64
"""Most Cougar ticks run for one call of :meth:`CougarWrist.tick` when the driver fell behind."""
IDLE_GRACE: Final = 8
"""Servo cycles a lazily ticked Cougar (``CougarWrist(lazy=True)``) is still ticked once nothing is
left for it to do, so that the last commands sent are read and answered before it sleeps."""
METER_CYCLES: Final = 128
"""Compliance cycles kept in :attr:`CougarWrist.meter` (the Puma's meters kept the last 128)."""
PUMA_WRIST_VERSION: Final = 1
"""The version number the Puma sends with VERS."""
GUARD_STOP_BIT: Final = 0x8000
GUARD_INDEX_MASK: Final = 0x000F
MAX_EXAMINE: Final = 242
"""Most words one examine-wrist reply carries (a Chaos packet's 488 data bytes: number, count, words)."""

_SCHEMES: Final[Mapping[int, Scheme]] = {0: Scheme.COMPLIANT_MOTION, 1: Scheme.COMPLIANT_DEBUG}
_GUARD_ACTIVE: Final = region("guard_active").address
"""Where Cougar keeps the bits of the armed guards (erratum cougar-memory-map)."""
_ZERO6: Final[Joints] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
_ARRIVED_DEG: Final = 1e-6


# ------------------------------------------------------------------------------------------ errors
def _plain(text: str) -> str:
    return "".join(ch if " " <= ch <= "~" and ch not in SPECIALS else "?" for ch in text)


def _timeout_error(command: int, seconds: float) -> RequestError:
    return RequestError(
        ErrorMessage(
            errors.WRIST,
            "E",
            "WNR",
            "Wrist computer did not answer command ~ within ~ ms",
            (command, min(round(seconds * 1000), 0xFFFF)),
        )
    )


def _link_error(reason: str) -> RequestError:
    return RequestError(ErrorMessage(errors.WRIST, "E", "WLK", f"Wrist link down: {_plain(reason)}"))


def _sync_error(command: int) -> RequestError:
    return RequestError(
        ErrorMessage(
            errors.WRIST, "E", "OOS", "Wrist computer lost sync; command ~ was discarded", (command,)
        )
    )


def dropped_warning(guard: int, dropped: Sequence[int]) -> ErrorMessage:
    """The asynchronous warning naming the segments a stop-the-move guard dropped (erratum
    ``guard-stop``): how many, and the first and last of them in queue order (they were numbered
    consecutively, so a client can tell exactly which segments will never be reported complete)."""
    return ErrorMessage(
        errors.WRIST,
        "W",
        "AWA",
        "Guard ~ stopped the move; ~ segment(s) dropped, ~ to ~",
        (guard, min(len(dropped), 0xFFFF), dropped[0], dropped[-1]),
    )


def _calibration_error(detail: str) -> RequestError:
    return RequestError(ErrorMessage(errors.WRIST, "E", "CAL", f"Calibration failed: {_plain(detail)}"))


# --------------------------------------------------------------------------------------- records
@dataclass(frozen=True, slots=True)
class MeterEntry:
    """One compliance cycle: time, scheme, sensed and nominal angles, the NTD used, the command sent."""

    time: float
    scheme: Scheme
    sensed: Joints
    nominal: Joints
    ntd: Joints
    commanded: Joints


@dataclass(slots=True)
class WristStats:
    """What the wrist processes did."""

    ticks: int = 0
    """Cougar ticks (GUTS) driven."""
    commands: int = 0
    """Commands sent (NPR and SEN included)."""
    npr: int = 0
    ntd: int = 0
    timeouts: int = 0
    stale_replies: int = 0
    """Replies dropped because their request had timed out."""
    unexpected: int = 0
    """Replies nobody waited for (dropped, with a warning)."""
    guard_hits: int = 0
    out_of_sync: int = 0


@dataclass(frozen=True)
class CalibrationSettings:
    """How calibrate-wrist samples the gauges (Part III §8.3: two positions compensate gravity)."""

    settle_ticks: int = 24
    """Ticks to wait after arriving before reading (the ADC8 filter reaches 95 % in 10)."""
    samples: int = 8
    """Raw readings averaged at each position (one per tick)."""
    return_to_start: bool = True
    """Move back to where the arm stood once the readings are taken."""


@dataclass
class _Waiter:
    """A command sent (or queued) whose reply someone waits for."""

    command: int
    response: int
    deadline: float
    on_reply: Callable[[CougarMsg], None]
    on_fail: Callable[[RequestError], None]
    cancelled: Callable[[], bool] = lambda: False


@dataclass
class _Episode:
    """State of the compliant interpolation across consecutive cycles."""

    last_t: float
    prev_sensed: Joints
    prev_nominal: Joints
    start: Joints
    """Where the arm stood when the episode began."""
    offset: list[float] = field(default_factory=lambda: [0.0] * 6)


# --------------------------------------------------------------------------------------------- wrist
class CougarWrist:
    """The Puma's wrist processes over ``port``.  See the module docstring.

    ``reply_timeout``: seconds a request waits for Cougar; ``calibration``: how calibrate-wrist samples.
    One wrist serves one arm at a time: the arm passed to :meth:`handle`/:meth:`tick` is bound (its
    ``compliance`` is set to this wrist); a new arm (a new connection) resets the compliance state.
    """

    def __init__(
        self,
        port: CougarPort,
        *,
        reply_timeout: float = DEFAULT_REPLY_TIMEOUT,
        calibration: CalibrationSettings | None = None,
        version: int = PUMA_WRIST_VERSION,
        lazy: bool = False,
    ) -> None:
        if not (math.isfinite(reply_timeout) and reply_timeout > 0.0):
            raise ValueError("reply_timeout must be finite and positive")
        self.port = port
        self.reply_timeout = float(reply_timeout)
        self.calibration = calibration or CalibrationSettings()
        self.version = int(version)
        self.stats = WristStats()
        self.meter: deque[MeterEntry] = deque(maxlen=METER_CYCLES)
        """The last compliance cycles (both schemes), oldest first."""
        self.ntd: Joints | None = None
        """The latest New Theta Dot received (deg/s), None before the first."""
        self._stream = WordStream("response")
        self._arm: ArmSim | None = None
        # One NPR per servo cycle run since the last output: a servo that wakes late catches up several
        # cycles at once, and the wrist must still see each of them.
        self._npr: list[list[int]] = []
        self._reset = False
        self._sen: list[int] | None = None
        self._sen_sent: Joints | None = None
        self._interrupt: deque[list[int]] = deque()
        self._user: deque[list[int]] = deque()
        self._waiters: list[_Waiter] = []
        self._stale: dict[int, deque[float]] = {}
        """Per response code, until when a late reply to a timed-out command is expected (oldest first)."""
        self._now = -math.inf
        self._episode: _Episode | None = None
        self._last_tick: float | None = None
        self._procedures: list[_Calibration] = []
        self._events: list[WristEvent] = []
        self._link_reported = False
        self._cycles = 0
        self._forces: tuple[float, ...] = (0.0,) * 6
        self.defects = WristDefects()
        """Given by each connection as it opens (its fault switches)."""
        self.silent = False
        """Cougar's words never reach the Puma (a condition of the connection's world)."""
        self.lazy = lazy
        """Leave Cougar unticked while nothing can come of a tick (see :meth:`tick`)."""
        self._armed: set[int] = set()
        """Guards armed on Cougar (by set-guard; cleared, or tripped, since)."""
        self._quiet = 0
        self._asleep = False
        self._own_environment: Environment | None = None
        """An in-process Cougar's environment before :meth:`load_hand` first changed it."""

    # ------------------------------------------------------------------------------ Wrist API
    def condition(self, defects: WristDefects, *, silent: bool = False) -> None:
        """A connection opens: its defects and world, and no guard an earlier connection left armed
        (erratum cougar-connection-state: Cougar's settings stay, its guards are cleared)."""
        self.defects, self.silent = defects, silent
        if defects.clears_old_guards:
            for index in sorted(self._armed):
                self.queue_command(CougarCommand.GUARDC, index=index)
            self._armed.clear()

    def load_hand(self, environment: Environment | None) -> bool:
        """Put ``environment`` on the hand of an in-process Cougar from now on (None: what it had before
        the first call); False, and nothing changed, for a Cougar elsewhere, whose world is its own."""
        cougar = getattr(self.port, "cougar", None)
        if cougar is None or not hasattr(cougar, "environment"):
            return False
        if self._own_environment is None:
            self._own_environment = cougar.environment
        cougar.environment = self._own_environment if environment is None else environment
        return True

    @property
    def served(self) -> frozenset[int]:
        return frozenset(SPEC.request(name).opcode for name in WRIST_OPERATIONS)

    def handle(
        self, op: RequestOpcode, values: Mapping[str, Value], now: float, arm: ArmSim
    ) -> dict[str, Any] | Pending:
        self._bind(arm)
        if op.name == "deposit-wrist" and values.get("address") == _GUARD_ACTIVE:
            # A deposit there arms (or disarms) guards by hand: the only one a sleeping Cougar could act on.
            active = values.get("value")
            assert isinstance(active, int)
            self._armed = {i for i in range(GUARD_INDEX_MASK + 1) if active >> i & 1}
        handler = _HANDLERS.get(op.name)
        if handler is None:
            raise RequestError(
                ErrorMessage(errors.WRIST, "C", "UIM", "Opcode ~ is not a wrist operation", (op.opcode,))
            )
        error = self.port.error
        if error is not None:
            raise _link_error(error)
        return handler(self, values, now, arm)

    def tick(self, now: float, arm: ArmSim) -> list[WristEvent]:
        """The wrist processes' turn: send what is queued, tick Cougar, take in what it sent.

        A lazy wrist (a simulated Cougar, whose ticks cost CPU) leaves Cougar unticked once it has had
        nothing to do for :data:`IDLE_GRACE` cycles: no request waiting, nothing queued, no compliance,
        no guard armed.  Cougar then sends nothing however long it is ticked, so nothing the Puma sees
        changes; when there is something to send again, Cougar is first told where the arm stands and
        ticked up to :data:`MAX_CATCH_UP` cycles of the time it slept, so its filters have settled there."""
        self._bind(arm)
        self._now = now
        t = arm.time
        if math.isfinite(t) and (self._last_tick is None or t > self._last_tick + 1e-9):
            self._procedures_step(t, arm)
            self._quiet = self._quiet + 1 if self._idle() else 0
            if self._quiet > IDLE_GRACE:
                self._asleep = True
            else:
                if self._asleep:
                    self._wake(t, arm)
                self._output(arm)
                self._drive(t, arm.tick_period)
        self._input(arm)
        self._expire(now)
        self._check_link()
        events, self._events = self._events, []
        return events

    # ------------------------------------------------------------------------- compliance hook
    def adjust(self, t: float, nominal: Joints, actual: Joints) -> Joints:
        """One cycle of a compliant segment (called by the arm's move process)."""
        arm = self._arm
        h = arm.tick_period if arm is not None else 0.016
        scheme = (arm.current_scheme if arm is not None else None) or Scheme.COMPLIANT_MOTION
        ep = self._episode
        follows = self.defects.compliant_follows_nominal
        if ep is None or t - ep.last_t > 1.5 * h:
            ep = self._episode = _Episode(t - h, actual, nominal if follows else actual, actual)
            self._reset = True
            self.ntd = None
        if not follows:
            nominal = ep.start  # a defect: the segment's nominal path left out
        dt = t - ep.last_t
        rate = tuple(
            ((s - ps) - (n - pn)) / dt
            for s, ps, n, pn in zip(actual, ep.prev_sensed, nominal, ep.prev_nominal, strict=True)
        )
        self._cycles += 1
        if self.defects.npr_every_cycle or self._cycles % 2:
            self._npr.append(
                encode(
                    "command",
                    CougarCommand.NPR,
                    theta_sensed=actual,
                    theta_commanded=nominal,
                    rate_difference=rate,
                )
            )
        ntd = self.ntd or _ZERO6
        if scheme is Scheme.COMPLIANT_MOTION:
            for i in range(6):
                ep.offset[i] += ntd[i] * h
        q = tuple(n + o for n, o in zip(nominal, ep.offset, strict=True))
        if arm is not None:
            lim = arm.model.limits
            q = tuple(min(max(v, lo), hi) for v, lo, hi in zip(q, lim.lower, lim.upper, strict=True))
            ep.offset = [v - n for v, n in zip(q, nominal, strict=True)]
        commanded: Joints = (q[0], q[1], q[2], q[3], q[4], q[5])
        self.meter.append(MeterEntry(t, scheme, actual, nominal, ntd, commanded))
        ep.last_t, ep.prev_sensed, ep.prev_nominal = t, actual, nominal
        return commanded

    # ---------------------------------------------------------------------------- internals
    def _bind(self, arm: ArmSim) -> None:
        if arm is self._arm:
            return
        self._arm = arm
        arm.compliance = self
        self._episode = None
        self._sen_sent = None

    def queue_command(self, name: str | int, **values: Any) -> None:
        """Put a command on the user queue (sent on the next tick)."""
        words = encode("command", name, **values)
        if self.defects.command_floats_swapped:
            words = _swap_float_words(words)
        self._user.append(words)

    def _ask(
        self,
        now: float,
        command: CougarCommand,
        response: CougarResponse,
        on_reply: Callable[[CougarMsg], None],
        on_fail: Callable[[RequestError], None],
        cancelled: Callable[[], bool] = lambda: False,
        **values: Any,
    ) -> None:
        self.queue_command(command, **values)
        self._waiters.append(
            _Waiter(command, response, now + self.reply_timeout, on_reply, on_fail, cancelled)
        )

    def _request(
        self,
        now: float,
        what: str,
        command: CougarCommand,
        response: CougarResponse,
        convert: Callable[[CougarMsg], dict[str, Any]],
        **values: Any,
    ) -> Pending:
        """A request answered from Cougar's reply."""
        pending = Pending(what)
        self._ask(
            now,
            command,
            response,
            lambda msg: pending.resolve(convert(msg)),
            pending.fail,
            lambda: pending.cancelled,
            **values,
        )
        return pending

    def _output(self, arm: ArmSim) -> None:
        """The output process: everything queued, in the 1985 guide's priority order."""
        words: list[int] = []
        defects = self.defects
        held = (not defects.user_while_moving and arm.moving) or (
            not defects.user_while_compliant and bool(self._npr)
        )  # a defect either way: the user's commands wait
        if defects.user_commands_first and not held:
            while self._user:
                words += self._user.popleft()
                self.stats.commands += 1
        if self._npr:
            for npr in self._npr:
                words += npr
            self.stats.npr += len(self._npr)
            self.stats.commands += len(self._npr)
            self._sen_sent = arm.actual  # NPR carries the sensed angles too
            self._npr.clear()
        if self._reset:
            words += encode("command", CougarCommand.RST)
            self.stats.commands += 1
            self._reset = False
        if arm.actual != self._sen_sent:
            self._interrupt.append(encode("command", CougarCommand.SEN, theta_sensed=arm.actual))
            self._sen_sent = arm.actual
        move: list[int] = []
        while self._interrupt:
            move += self._interrupt.popleft()
            self.stats.commands += 1
        user: list[int] = []
        while self._user and not held:
            user += self._user.popleft()
            self.stats.commands += 1
        words += move + user if defects.move_queue_before_user else user + move
        if words:
            self.port.send(words)

    def _idle(self) -> bool:
        return (
            self.lazy
            and not self._armed
            and not self._waiters
            and not self._procedures
            and not self._user
            and not self._interrupt
            and self._npr is None
            and not self._reset
        )

    def _wake(self, t: float, arm: ArmSim) -> None:
        """Bring a sleeping Cougar up to ``t``: the arm's angles, then the ticks it missed but one."""
        self._asleep = False
        if arm.actual != self._sen_sent:
            self.port.send(encode("command", CougarCommand.SEN, theta_sensed=arm.actual))
            self.stats.commands += 1
            self._sen_sent = arm.actual
        h = arm.tick_period
        last = self._last_tick
        n = MAX_CATCH_UP if last is None else min(MAX_CATCH_UP, max(1, round((t - last) / h)))
        for k in range(n - 1, 0, -1):
            self.port.tick(t - k * h)
            self.stats.ticks += 1
        self._last_tick = t - h

    def _drive(self, t: float, h: float) -> None:
        """Tick Cougar for every servo cycle since the last one (the last ``MAX_CATCH_UP`` of them)."""
        last = self._last_tick
        n = 1 if last is None else max(1, round((t - last) / h))
        for k in range(min(n, MAX_CATCH_UP) - 1, -1, -1):
            self.port.tick(t - k * h)
            self.stats.ticks += 1
        self._last_tick = t

    def _input(self, arm: ArmSim) -> None:
        """The input process: decode what Cougar sent and act on it."""
        words = self.port.receive()
        if not words or self.silent:
            return
        for item in self._stream.feed(words):
            if isinstance(item, CougarMsg):
                self._dispatch(item, arm)
            elif isinstance(item, OutOfSync):
                self.stats.out_of_sync += 1
                self._warn(
                    ErrorMessage(
                        errors.WRIST,
                        "W",
                        "OOS",
                        "Unknown word ~ from the wrist computer; ~ words discarded",
                        (item.code, min(len(item.discarded), 0xFFFF)),
                    )
                )
            else:
                self._warn(self._malformed(item))

    def _malformed(self, item: Malformed) -> ErrorMessage:
        return ErrorMessage(
            errors.WRIST, "W", "BWD", "Undecodable message from the wrist computer (code ~)", (item.words[0],)
        )

    def _dispatch(self, msg: CougarMsg, arm: ArmSim) -> None:
        code = msg.code
        if code == CougarResponse.NTD:
            delta = msg.values["delta_theta"]
            assert isinstance(delta, tuple)
            self.ntd = (delta[0], delta[1], delta[2], delta[3], delta[4], delta[5])
            self.stats.ntd += 1
            return
        if code in (CougarResponse.GUARD_STOP, CougarResponse.GUARD_CONTINUE):
            self._guard(msg, arm)
            return
        if code == CougarResponse.OUT_OF_SYNC:
            if self.defects.handles_out_of_sync:
                self._lost_sync(msg)
            return
        stale = self._stale.get(code)
        while stale and stale[0] < self._now:
            stale.popleft()  # that late reply never came: stop expecting it
        if stale:
            stale.popleft()
            self.stats.stale_replies += 1
            return
        for i, waiter in enumerate(self._waiters):
            if waiter.response == code:
                del self._waiters[i]
                if not waiter.cancelled():
                    waiter.on_reply(msg)
                return
        self.stats.unexpected += 1
        self._warn(
            ErrorMessage(errors.WRIST, "W", "UNX", "Unexpected reply ~ from the wrist computer", (code,))
        )

    def _guard(self, msg: CougarMsg, arm: ArmSim) -> None:
        word = msg.values["index"]
        assert isinstance(word, int)
        index = word & GUARD_INDEX_MASK
        stop = msg.code == CougarResponse.GUARD_STOP
        self.stats.guard_hits += 1
        self._armed.discard(index)
        halts = stop and self.defects.guard_stops_arm
        arm_events = tuple(arm.halt(AbortCause.GUARD)) if halts else ()
        if halts:
            self._reset = True
            self._episode = None
        self._events.append(GuardHit(index, stop, arm.time, arm_events))
        dropped = [s for e in arm_events if isinstance(e, MotionAborted) for s in e.dropped]
        if dropped:
            self._warn(dropped_warning(index, dropped))

    def _lost_sync(self, msg: CougarMsg) -> None:
        """Cougar dumped its input buffer: nothing sent before will be answered."""
        self.stats.out_of_sync += 1
        bad = msg.values["code"]
        assert isinstance(bad, int)
        self._warn(
            ErrorMessage(
                errors.WRIST,
                "W",
                "OOS",
                "Wrist computer lost sync at word ~; its input was discarded",
                (bad,),
            )
        )
        waiters, self._waiters = self._waiters, []
        self._stale.clear()
        for waiter in waiters:
            if not waiter.cancelled():
                waiter.on_fail(_sync_error(waiter.command))

    def _expire(self, now: float) -> None:
        keep: list[_Waiter] = []
        for waiter in self._waiters:
            if (waiter.cancelled() or now >= waiter.deadline) and not self.silent:
                # Its reply may still come (replies keep their order): drop it if it comes soon.
                self._stale.setdefault(waiter.response, deque()).append(now + self.reply_timeout)
            if waiter.cancelled():
                pass
            elif now >= waiter.deadline:
                self.stats.timeouts += 1
                if self.defects.answer_timeouts:
                    waiter.on_fail(_timeout_error(waiter.command, self.reply_timeout))
            else:
                keep.append(waiter)
        self._waiters = keep

    def _check_link(self) -> None:
        error = self.port.error
        if error is None:
            self._link_reported = False
            return
        waiters, self._waiters = self._waiters, []
        for waiter in waiters:
            if not waiter.cancelled():
                waiter.on_fail(_link_error(error))
        if not self._link_reported:
            self._link_reported = True
            self._events.append(
                WristNotice(
                    ErrorMessage(errors.WRIST, "E", "WLK", f"Wrist link down: {_plain(error)}"), error=True
                )
            )

    def _warn(self, message: ErrorMessage) -> None:
        self._events.append(WristNotice(message))

    def _procedures_step(self, t: float, arm: ArmSim) -> None:
        for proc in list(self._procedures):
            if proc.step(t, arm):
                self._procedures.remove(proc)

    # ------------------------------------------------------------------------------ handlers
    def _read_forces(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> Pending | dict[str, Any]:
        # §6.3: the current joint angles go first, so Cougar's gravity correction is up to date.
        if self.defects.read_forces_sends_angles:
            self._interrupt.append(encode("command", CougarCommand.SEN, theta_sensed=arm.actual))
            self._sen_sent = arm.actual
        if not self.defects.read_forces_waits:
            self.queue_command(CougarCommand.RFRC)
            return {"forces": self._forces}
        return self._request(
            now,
            "read-forces",
            CougarCommand.RFRC,
            CougarResponse.FORCES,
            lambda msg: {"forces": self._keep_forces(msg)},
        )

    def _keep_forces(self, msg: CougarMsg) -> tuple[float, ...]:
        forces = msg.values["forces"]
        assert isinstance(forces, tuple)
        self._forces = tuple(float(f) for f in forces)
        return self._forces

    def _read_raw(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> Pending:
        return self._request(
            now,
            "read-raw-gauges",
            CougarCommand.RRAW,
            CougarResponse.RAW,
            lambda msg: {"gauges": msg.values["gauges"]},
        )

    def _examine(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> Pending:
        count = _int(values["count"])
        if count > MAX_EXAMINE:
            raise errors.bad_value("examine-wrist", f"count {count} is more than {MAX_EXAMINE} words")
        return self._request(
            now,
            "examine-wrist",
            CougarCommand.EXMN,
            CougarResponse.EXMN_DATA,
            lambda msg: {"words": msg.values["words"]},
            address=_int(values["address"]),
            count=count,
        )

    def _version(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> Pending:
        return self._request(
            now,
            "wrist-version",
            CougarCommand.VERS,
            CougarResponse.VERSION,
            lambda msg: {"version": msg.values["version"]},
            version=self.version,
        )

    def _set_guard(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> dict[str, Any]:
        # Erratum guard-type-bit: any bit of the high byte asks for a stop guard, sent to Cougar as bit 15
        # alone; bits 4-14 are sent as 0.
        raw = _int(values["type_index"])
        type_index = (GUARD_STOP_BIT if raw & 0xFF00 else 0) | raw & GUARD_INDEX_MASK
        self._armed.add(type_index & GUARD_INDEX_MASK)
        self.queue_command(
            CougarCommand.GUARDS, type_index=type_index, dvec=values["dvec"], tol=values["tol"]
        )
        return {}

    def _clear_guard(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> dict[str, Any]:
        index = _int(values["index"])
        if index > GUARD_INDEX_MASK:
            raise errors.bad_value("clear-guard", f"guard {index} is not 0..15")
        self._armed.discard(index)
        self.queue_command(CougarCommand.GUARDC, index=index)
        return {}

    def _compliant_move(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> dict[str, Any]:
        code = _int(values["scheme"])
        scheme = _SCHEMES.get(code)
        if scheme is None:
            raise errors.bad_value("compliant-move", f"scheme {code} is not 0 (motion) or 1 (debugging)")
        goal = values["joints"]
        assert isinstance(goal, tuple)
        return {"segment": arm.move_joints(tuple(float(x) for x in goal), now, scheme=scheme)}

    def _calibrate(self, values: Mapping[str, Value], now: float, arm: ArmSim) -> Pending:
        arm.check_motion(now)
        pending = Pending("calibrate-wrist")
        proc = _Calibration(self, arm, pending, now)
        self._procedures.append(proc)
        return pending


def _swap_float_words(words: list[int]) -> list[int]:
    """``words`` (one command) with the two words of every float swapped (a faulty Puma's)."""
    out = list(words)
    pos = 1
    for f in lookup("command", words[0]).data:
        n = 1 if f.count is None else f.count
        if f.element == "float":
            for i in range(pos, pos + 2 * n, 2):
                out[i], out[i + 1] = out[i + 1], out[i]
            pos += 2 * n
        else:
            pos += n
    return out


def _int(value: Value) -> int:
    assert isinstance(value, int)
    return value


def _forward(
    command: CougarCommand, **fields: str
) -> Callable[[CougarWrist, Mapping[str, Value], float, ArmSim], dict[str, Any]]:
    """A configuration request: its fields become the command's (by ``fields``: command field = request
    field), queued on the user queue; answered done at once."""

    def handler(wrist: CougarWrist, values: Mapping[str, Value], now: float, arm: ArmSim) -> dict[str, Any]:
        wrist.queue_command(command, **{cf: values[rf] for cf, rf in fields.items()})
        return {}

    return handler


Handler = Callable[[CougarWrist, Mapping[str, Value], float, ArmSim], "dict[str, Any] | Pending"]

_HANDLERS: Final[Mapping[str, Handler]] = {
    "read-forces": CougarWrist._read_forces,
    "read-raw-gauges": CougarWrist._read_raw,
    "set-gauge-offsets": _forward(CougarCommand.WGOV, offsets="offsets"),
    "calibrate-wrist": CougarWrist._calibrate,
    "set-spring": _forward(CougarCommand.NK, k="k"),
    "set-damping": _forward(CougarCommand.NB, b="b"),
    "set-joint-damping": _forward(CougarCommand.NBJI, bji="bji"),
    "set-frame-vector": _forward(CougarCommand.NFV, offset="offset"),
    "set-weight": _forward(CougarCommand.NEWWC, weight="weight", cg="cg"),
    "set-guard": CougarWrist._set_guard,
    "clear-guard": CougarWrist._clear_guard,
    "compliant-move": CougarWrist._compliant_move,
    "examine-wrist": CougarWrist._examine,
    "deposit-wrist": _forward(CougarCommand.DPST, address="address", value="value"),
    "wrist-version": CougarWrist._version,
    "set-commanded-force": _forward(CougarCommand.NFC, force="force"),
}


def _check_handlers() -> None:
    if set(_HANDLERS) != set(WRIST_OPERATIONS):
        raise RuntimeError(
            f"wrist handlers do not match the wrist operations: {set(_HANDLERS) ^ WRIST_OPERATIONS}"
        )


_check_handlers()


def make_cougar_wrist(
    where: str, *, seed: int | None = None, environment: Environment | None = None, **options: Any
) -> CougarWrist:
    """A wrist for ``manip-server --cougar WHERE``: ``sim`` (the simulator in-process, with ``seed`` and
    ``environment``) or ``tcp://HOST:PORT`` (an external Cougar over the emulated DRV-11J; call this in
    a running event loop -- it connects in the background).  ``options`` go to :class:`CougarWrist`."""
    port: CougarPort
    port = SimPort(CougarSim(environment=environment, seed=seed)) if where == "sim" else Drv11jPort(where)
    # A simulated Cougar sleeps while idle (its ticks cost CPU); an external one keeps the Puma's clock.
    options.setdefault("lazy", where == "sim")
    return CougarWrist(port, **options)


# ------------------------------------------------------------------------------- calibrate-wrist
def calibration_poses(arm: ArmSim, start: Joints) -> tuple[Joints, Joints]:
    """Two poses whose gravity loads on the wrist are opposite: the tool axis horizontal (joint 5 chosen
    nearest ``start``), then joint 6 turned half a turn.  Gauges are linear in the load, so the mean of
    the readings in the two poses is the offset (§8.3).  Raises RequestError when no such pose exists."""
    g, lim = arm.model.geometry, arm.model.limits

    def tilt(q5: float) -> float:
        q = (start[0], start[1], start[2], start[3], q5, start[5])
        return float(forward(q, g).matrix[2, 2])  # world z of the approach vector

    lo, hi = lim.lower[4], lim.upper[4]
    grid = [lo + (hi - lo) * k / 200 for k in range(201)]
    roots: list[float] = []
    for a, b in itertools.pairwise(grid):
        fa, fb = tilt(a), tilt(b)
        if fa == 0.0:
            roots.append(a)
        elif fa * fb < 0.0:
            for _ in range(50):
                m = 0.5 * (a + b)
                fm = tilt(m)
                if fa * fm <= 0.0:
                    b = m
                else:
                    a, fa = m, fm
            roots.append(0.5 * (a + b))
    if not roots:
        raise _calibration_error("no pose puts the tool axis horizontal from here")
    q5 = min(roots, key=lambda r: abs(r - start[4]))
    q6 = start[5] + 180.0 if start[5] + 180.0 <= lim.upper[5] else start[5] - 180.0
    p1: Joints = (start[0], start[1], start[2], start[3], q5, start[5])
    p2: Joints = (start[0], start[1], start[2], start[3], q5, q6)
    return p1, p2


class _Calibration:
    """calibrate-wrist as a procedure stepped once per Cougar tick (before the output process).

    Phases: move to the first pose, wait until the arm is there and still, let the filter settle, read
    ``samples`` raw gauge vectors; the same at the second pose; move back; send WGOV with the mean and
    answer it.  The main process waits all along (the request is pending)."""

    def __init__(self, wrist: CougarWrist, arm: ArmSim, pending: Pending, now: float) -> None:
        self.wrist = wrist
        self.arm = arm
        self.pending = pending
        self.settings = wrist.calibration
        self.start = arm.planned
        self.poses = calibration_poses(arm, self.start)
        self.readings: list[list[tuple[int, ...]]] = [[], []]
        self.position = 0
        self.settled = 0
        self.asked = 0
        self.failed: RequestError | None = None
        arm.move_joints(self.poses[0], now)

    def _fail(self, error: RequestError) -> bool:
        self.pending.fail(error)
        return True

    def step(self, t: float, arm: ArmSim) -> bool:
        """Advance; True when finished (answered or failed)."""
        if self.pending.cancelled or self.pending.done:
            return True
        if self.failed is not None:
            return self._fail(self.failed)
        if arm is not self.arm:
            return self._fail(_calibration_error("the connection changed"))
        if arm.aborted:
            return self._fail(_calibration_error("motion was aborted"))
        target = self.poses[self.position]
        here = max(abs(a - b) for a, b in zip(arm.actual, target, strict=True))
        if arm.moving or here > _ARRIVED_DEG:
            self.settled = 0
            return False
        self.settled += 1
        if self.settled < self.settings.settle_ticks:
            return False
        if self.asked < self.settings.samples:
            self.asked += 1
            position = self.position
            self.wrist._ask(
                t,
                CougarCommand.RRAW,
                CougarResponse.RAW,
                lambda msg: self._reading(position, msg),
                self._failure,
                lambda: self.pending.cancelled,
            )
            return False
        if len(self.readings[self.position]) < self.settings.samples:
            return False  # replies still to come (or a timeout, which fails us)
        if self.position == 0 and self.wrist.defects.calibrate_two_poses:
            self.position, self.settled, self.asked = 1, 0, 0
            try:
                arm.move_joints(self.poses[1], t)
            except Exception as exc:  # Refused: the arm will not move (power, abort)
                return self._fail(_calibration_error(f"cannot move to the second pose ({exc})"))
            return False
        samples = self.readings[0] + self.readings[1]  # (only the first with calibrate-one-pose)
        offsets = tuple(round(sum(s[i] for s in samples) / len(samples)) for i in range(8))
        offsets = tuple(min(max(v, -0x8000), 0x7FFF) for v in offsets)
        self.wrist.queue_command(CougarCommand.WGOV, offsets=offsets)
        if self.settings.return_to_start and self.wrist.defects.calibrate_moves_back:
            try:
                arm.move_joints(self.start, t)
            except Exception as exc:
                return self._fail(_calibration_error(f"cannot move back ({exc})"))
        self.pending.resolve({"offsets": offsets})
        return True

    def _reading(self, position: int, msg: CougarMsg) -> None:
        gauges = msg.values["gauges"]
        assert isinstance(gauges, tuple)
        self.readings[position].append(tuple(int(g) for g in gauges))

    def _failure(self, error: RequestError) -> None:
        self.failed = error
