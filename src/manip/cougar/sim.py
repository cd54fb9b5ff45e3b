"""The Cougar wrist computer, simulated behind its 16-bit word protocol (the 1985 guide, Part III,
Appendices B and C).

Sans-I/O: :meth:`CougarSim.receive` buffers words from the Puma, :meth:`CougarSim.tick` is one Puma clock
tick and returns the words Cougar sends back during it.  Time is only ever an argument; given a seed the
simulation is deterministic.

Theory of operation (one tick = one GUTS interrupt, B.6, then background time):

1. Re-entry check (errata ``cougar-guts-reentry``).  GUTS must never interrupt itself; the 1985 guide's GUTS
   checks on entry and, if it finds itself already running, sends a character to the terminal and returns
   from the interrupt.  A sans-I/O simulator sees re-entry two ways: ``tick`` called while a ``tick`` is
   running (e.g. from an :class:`~manip.cougar.environment.Environment` callback), or a tick arriving
   before the previous GUTS would have finished on the LSI-11/23 by the cost model (``guts_base_s`` plus
   ``guts_per_command_s`` per command and ``guts_per_word_s`` per data word).  Either way the tick does
   nothing but append ``reentry_char`` to :attr:`CougarSim.terminal` and count ``guts_reentries``; it
   returns no words and its gauge sample is lost.
2. ADC8 (B.4): the physical wrench on the hand (contact from the environment at the pose of the joint
   angles Cougar was last sent, plus gravity on the true hand and payload) becomes eight 12-bit gauge
   counts through the wrist model; the gauge offsets are subtracted from each sample (§8.3: "prior to
   any other processing"), then each channel is filtered in integers (:mod:`manip.cougar.adc`).
3. Conversion (§8.2): force = voltmat · Y.
4. GRAVITY (B.8), then LIMIT (B.5) if bit 0 of ``flags`` is set (it is not, by default).
5. GUARDM (B.9): every armed guard whose dot(force, dvec) reaches tol (>=, erratum
   ``guard-trip-comparison``) trips: response 6 (stop the move: a bit of its type word's high byte set,
   erratum ``guard-type-bit``) or 7 (continue) with its index, and it is disarmed.
6. COMINT (B.7, :mod:`manip.cougar.comint`): every complete command in the input buffer runs, in order.
7. Background: JACOB (:mod:`manip.cougar.jacob`) runs ``jacob_steps_per_tick`` steps.

Everything Cougar keeps is in its simulated memory (:mod:`manip.cougar.memory`), so EXMN and DPST see
and change what the routines use.  ``CougarConfig.readings`` (:mod:`manip.cougar.readings`) switches to
other readings of the 1985 guide the conformance suite must accept: EXMN's count at a bad address, a
bare out-of-sync, a guard at tol, the guard type bit, no GUTS cost model, ADC8 rounding to nearest,
lengths in inches, offsets after the filter, RRAW unfiltered, and the memory map moved on the link.  The
commands (Table 1):

=======  ====  =========================================================================================
NOP      0     nothing
WINIT    1     nothing (obsolete)
SEN      2     θ_sensed to memory; the simulated arm moves there
FINIT    3     as SEN (obsolete)
NPR      4     θ_sensed, θ_commanded, rate difference to memory; the arm moves; answers NTD (1) with Δθ̇
NFC      5     force commanded to memory
NK/NB    6/7   spring constants (6, diagonal) / damping matrix (36, row after row) to memory
NBJI     8     joint damping inverse (6, diagonal) to memory; JACOB folds it into P
NFV      9     frame vector to memory; voltmat's torque rows and the GRAVITY model are redone
RST      10    FILTER state and the last Δθ̇ set to zero
DPST     11    memory[address] = value (no answer; a bad address is counted)
EXMN     12    answers 4, n, then n words from address (n < count at the end of memory; 0 if bad)
VERS     13    stores the Puma's word; answers 8 with Cougar's version
RFRC     14    answers 5 with the six force floats
NEWWC    15    object weight and cg to memory; the GRAVITY model is redone
GUARDS   16    arms guard (word & 15)
GUARDC   17    disarms guard (word & 15)
RRAW     18    answers 9 with the eight filtered gauge readings with the offsets added back
WGOV     19    gauge offset vector to memory
=======  ====  =========================================================================================

The compliance equation NPR answers is in :mod:`manip.cougar.compliance`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Final

import numpy as np
import numpy.typing as npt

from manip.arm import PUMA560_LEE, READY, PumaGeometry, Transform, forward
from manip.cougar.adc import GAUGES, GaugeModel, adc8_filter
from manip.cougar.comint import COMMANDS, Comint, Executable, OutOfSyncEvent
from manip.cougar.compliance import (
    MM_PER_INCH,
    compliance_sample,
    cross,
    filter_constants,
    gravity_load,
    gravity_model,
    hand_rotation,
    limit,
    output_filter,
    voltmat,
    voltmat_torque_rows,
)
from manip.cougar.environment import Environment, FreeSpace
from manip.cougar.faults import CougarDefects, cougar_defects, parse_faults
from manip.cougar.jacob import STEPS, Jacob, front_buffer
from manip.cougar.memory import GUARD_DVEC, GUARD_TOL, GUARD_WORDS, MAP_BASE, MEMORY_BYTES, Memory, region
from manip.cougar.readings import MAP_SHIFT, parse_readings
from manip.spec.constants import CougarCommand, CougarResponse

__all__ = ["CougarConfig", "CougarSim", "CougarStats"]

Vector = npt.NDArray[np.float64]
#: Bit 15 of a guard's type word: what a sender sets for a guard whose trip stops the move.
GUARD_STOP_BIT: Final = 0x8000
#: The bits of the type word any of which makes a trip stop the move: the high byte (errata
#: ``guard-type-bit``: Table 1's "hi bit" and B.9's "high byte" both read so; stop is the safe side).
GUARD_STOP_MASK: Final = 0xFF00
#: Bit 7 of a guard's type word, the sign of its low byte (fault guard-type-low-byte reads the type there).
GUARD_LOW_BYTE_SIGN: Final = 0x0080
#: Bit 0 of the ``flags`` word: LIMIT is applied.
FLAG_LIMIT: Final = 1
_UNTOUCHED: Final = (0.0,) * 6


@dataclass(frozen=True)
class CougarConfig:
    """The simulated machine: the arm and wrist it is attached to, and Cougar's start-up values."""

    geometry: PumaGeometry = PUMA560_LEE
    tool: Transform = field(default_factory=lambda: Transform.trans(0.0, 0.0, 150.0))
    """End frame (wrist centre) to the tool point the environment touches, mm."""
    initial_angles: tuple[float, ...] = READY
    gauges: GaugeModel = field(default_factory=GaugeModel)
    hand_weight_oz: float = 32.0
    hand_cg_mm: tuple[float, float, float] = (0.0, 0.0, 60.0)
    """The real hand (from the wrist centre, hand axes); Cougar's GRAVITY model starts equal to it."""
    payload_weight_oz: float = 0.0
    payload_cg_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """A real held object (from the wrist centre); Cougar learns of it only through NEWWC."""
    calibration: tuple[float, ...] | None = None
    """Cougar's calibration matrix (48 floats, oz/V, row after row); None: exact for ``gauges``."""
    version: int = 1
    tick_hz: float = 60.0
    """Puma clock rate, used only for FILTER's constants (a·T)."""
    filter_cutoff_hz: float = 2.0
    filter_con3: float = 0.0
    filter_con4: float = 1.0
    limit_on: bool = False
    limit_dead: float = 0.5
    limit_clamp: float = 500.0
    jacob_steps_per_tick: int = STEPS
    """Background steps run after each GUTS (STEPS = one whole Jacobian per tick)."""
    guts_base_s: float = 0.004
    guts_per_command_s: float = 0.0002
    guts_per_word_s: float = 0.00002
    """The GUTS cost model for re-entry detection; all zero disables it."""
    reentry_char: str = "!"
    wake_message: str = "Cougar {version}\r\n"
    faults: frozenset[str] = frozenset()
    """Defects to simulate (:class:`manip.cougar.faults.CougarFault`), for testing conformance suites."""
    readings: frozenset[str] = frozenset()
    """Other readings of the 1985 guide to take (:data:`manip.cougar.readings.READINGS`): conforming."""

    def __post_init__(self) -> None:
        if len(self.initial_angles) != 6:
            raise ValueError("CougarConfig.initial_angles needs six joint angles")
        if self.calibration is not None and len(self.calibration) != 48:
            raise ValueError("CougarConfig.calibration needs 48 floats (6x8)")
        if not 0 <= self.version <= 0xFFFF:
            raise ValueError("CougarConfig.version must be a 16-bit word")
        if self.jacob_steps_per_tick < 0 or self.tick_hz <= 0:
            raise ValueError("CougarConfig needs jacob_steps_per_tick >= 0 and tick_hz > 0")
        object.__setattr__(self, "faults", parse_faults(self.faults))
        object.__setattr__(self, "readings", parse_readings(self.readings))

    @property
    def defects(self) -> CougarDefects:
        """The behaviours :attr:`faults` give the simulator (none: the 1985 guide's)."""
        return cougar_defects(self.faults)

    @property
    def map_shift(self) -> int:
        """How far the memory map sits above manip's own on the link (reading ``relocated-map``)."""
        return MAP_SHIFT if "relocated-map" in self.readings else 0

    @property
    def mm_per_unit(self) -> float:
        """Millimetres per unit of the lengths the Puma sends (reading ``lengths-in-inches``)."""
        return MM_PER_INCH if "lengths-in-inches" in self.readings else 1.0


@dataclass
class CougarStats:
    """Counters since start-up."""

    ticks: int = 0
    """GUTS runs that did their work (re-entries not included)."""
    commands: int = 0
    out_of_sync: int = 0
    """Out-of-sync dumps (each sends one response 2)."""
    discarded_words: int = 0
    guts_reentries: int = 0
    words_received: int = 0
    words_sent: int = 0
    guards_tripped: int = 0
    jacob_cycles: int = 0
    bad_addresses: int = 0
    """EXMN/DPST at an odd address or outside memory."""
    float_faults: int = 0
    """Floats that overflowed the F range (saturated) or were not finite when stored."""


class CougarSim:
    """Cougar behind its word protocol; see the module docstring."""

    def __init__(
        self,
        config: CougarConfig | None = None,
        *,
        environment: Environment | None = None,
        seed: int | None = None,
    ) -> None:
        self.config = config or CougarConfig()
        self.environment: Environment = environment if environment is not None else FreeSpace()
        self.memory = Memory()
        self._rng = np.random.default_rng(seed)
        self._defects = defects = self.config.defects
        self._readings = self.config.readings
        self._comint = self._new_comint()
        self._tripped_once: set[int] = set()  # a guard that trips twice (CougarDefects.guard_trips_once)
        self._guard_values: dict[int, tuple[list[int], Vector, float]] = {}
        """Guard i's table words, and its dvec and tol decoded from them."""
        self._jacob = Jacob(
            self.config.geometry,
            mm_per_unit=self.config.mm_per_unit,
            transpose_stored=defects.jacobian_transpose_stored,
            bji_per_joint=defects.bji_per_joint,
            double_buffered=defects.jacob_double_buffered,
            joint_signs_right=defects.jacobian_joint_signs_right,
        )
        self._stats = CougarStats()
        self._pose: tuple[float, ...] = tuple(float(q) for q in self.config.initial_angles)
        self._busy_until: float | None = None
        self._last_now: float | None = None
        self._terminal: list[str] = []
        self._out: list[int] = []
        self._init()

    # ------------------------------------------------------------------ public surface
    @property
    def stats(self) -> CougarStats:
        """A snapshot of the counters."""
        s = self._stats
        return CougarStats(**{**s.__dict__, "jacob_cycles": self._jacob.cycles})

    @property
    def terminal(self) -> str:
        """Everything Cougar printed on its console terminal (wake-up message, re-entry characters)."""
        return "".join(self._terminal)

    @property
    def pose(self) -> tuple[float, ...]:
        """The simulated arm's joint angles (deg): the θ_sensed Cougar was last sent."""
        return self._pose

    @property
    def pending(self) -> tuple[int, ...]:
        """Input words waiting for the rest of their command."""
        return self._comint.pending

    def tool_pose(self) -> Transform:
        """The tool frame the environment sees (world, mm)."""
        return forward(self._pose, self.config.geometry) @ self.config.tool

    def receive(self, words: Iterable[int]) -> None:
        """Words from the Puma (the DRV-11J input port); they wait in the input buffer for COMINT."""
        self._stats.words_received += self._comint.receive(words)

    def tick(self, now: float) -> list[int]:
        """One Puma clock tick at time ``now`` (seconds): GUTS, then background; the words sent, in order."""
        mem = self.memory
        nested = mem.word("guts_busy") != 0
        if not nested and self._last_now is not None and now < self._last_now:
            raise ValueError(f"tick time went backwards: {now} after {self._last_now}")
        if nested or (self._busy_until is not None and now < self._busy_until):
            self._stats.guts_reentries += 1
            self._terminal.append(self.config.reentry_char)
            return [] if nested or self._defects.reentry_returns_at_once else self._comint_part()
        self._last_now = now
        mem.set_word("guts_busy", 1)
        self._out = []
        try:
            self._adc8()
            self._convert()
            self._gravity()
            if self._defects.guardm_before_comint:
                self._guardm()
            commands, words = self._comint_run()
            if not self._defects.guardm_before_comint:
                self._guardm()
        finally:
            mem.set_word("guts_busy", 0)
        c = self.config
        cost = c.guts_base_s + c.guts_per_command_s * commands + c.guts_per_word_s * words
        if "guts-every-tick" in self._readings:
            cost = 0.0
        self._busy_until = now + cost if cost > 0 else None
        self._stats.ticks += 1
        self._jacob.run(mem, c.jacob_steps_per_tick)
        out, self._out = self._out, []
        self._stats.words_sent += len(out)
        self._stats.float_faults = mem.float_faults
        return out

    def _new_comint(self) -> Comint:
        """COMINT with its table (NOP and FINIT as Table 1 has them but for a defect of the table)."""
        d = self._defects
        table = dict(COMMANDS)
        if not d.nop_known:
            del table[CougarCommand.NOP]
        if not d.finit_takes_data:
            table[CougarCommand.FINIT] = replace(table[CougarCommand.FINIT], data_words=0, destination=None)
        return Comint(execute_partial=not d.comint_waits_for_data, table=table)

    def _comint_part(self) -> list[int]:
        """The answers of the commands waiting, which stay waiting (fault guts-part-on-reentry)."""
        real, self._comint = self._comint, self._new_comint()
        self._comint.receive(real.pending)
        self._out = []
        try:
            self._comint_run()
        finally:
            self._comint = real
        out, self._out = self._out, []
        return out

    def run_background(self, steps: int) -> None:
        """Run JACOB for ``steps`` more steps (background time between ticks, for tests and tools)."""
        self._jacob.run(self.memory, steps)

    # ------------------------------------------------------------------ INIT (B.1)
    def _init(self) -> None:
        c, mem = self.config, self.memory
        mem.set_word("version", c.version)
        mem.set_word("flags", FLAG_LIMIT if c.limit_on else 0)
        mem.put("limit_dead", [c.limit_dead])
        mem.put("limit_clamp", [c.limit_clamp])
        mem.put("con", filter_constants(c.filter_cutoff_hz, c.tick_hz, c.filter_con3, c.filter_con4))
        mem.put("hand_weight", [c.hand_weight_oz])
        mem.put("hand_cg", c.hand_cg_mm)
        mem.put("theta_sensed", self._pose)
        cal = (
            np.array(c.calibration, dtype=np.float64)
            if c.calibration is not None
            else c.gauges.calibration_matrix()
        )
        mem.put("calmat", cal.reshape(-1))
        mem.put("voltmat", voltmat(mem.get("calmat"), mem.get("fv")).reshape(-1))
        self._newwc()
        u = c.gauges.convert(c.gauges.analog(self._physical_load(), self._rng))
        corrected = self._corrected(u)
        mem.put_int16s("gauge_raw", corrected)  # prime the filter with a first reading
        mem.put_int16s("gauge_filtered", corrected)
        self._jacob.run(mem, STEPS)
        if c.wake_message:
            self._terminal.append(c.wake_message.format(version=c.version))

    # ------------------------------------------------------------------ GUTS parts
    # Plain floats wherever numpy would only add, multiply or compare elementwise (the same operations,
    # so the same bits); numpy for the matrix products, whose rounding its BLAS decides.

    def _physical_load(self) -> Vector:
        """The wrench on the hand (oz, oz-in; hand axes, about the wrist centre): contact plus gravity."""
        c = self.config
        t6 = forward(self._pose, c.geometry)
        rows = t6.rotation.tolist()
        hand = gravity_load(rows, c.hand_weight_oz, c.hand_cg_mm)
        payload = gravity_load(rows, c.payload_weight_oz, c.payload_cg_mm)
        # FreeSpace touches nothing anywhere: no tool pose needed
        touch = _UNTOUCHED if type(self.environment) is FreeSpace else self._contact(t6)
        return np.array([(t + h) + p for t, h, p in zip(touch, hand, payload, strict=True)])

    def _contact(self, t6: Transform) -> Sequence[float]:
        """The environment's wrench on the tool, moved to the wrist centre in hand axes."""
        tool = t6 @ self.config.tool
        contact = self.environment.wrench(tool)
        if not (any(contact.force) or any(contact.torque)):
            return _UNTOUCHED  # Rᵀ·0 is +0.0 throughout
        r = np.array(t6.rotation)  # C order, as the products below have always had it
        f = [float(v) for v in contact.force]
        lever_in = [(a - b) / MM_PER_INCH for a, b in zip(tool.p.tolist(), t6.p.tolist(), strict=True)]
        tau = [float(t) + c for t, c in zip(contact.torque, cross(lever_in, f), strict=True)]
        touch: list[float] = (r.T @ np.array(f)).tolist() + (r.T @ np.array(tau)).tolist()
        return touch

    def _adc8(self) -> None:
        mem, gauges = self.memory, self.config.gauges
        # The offsets go first, so a WGOV reaches the forces through the filter (erratum
        # cougar-filter-rounding); the previous sample keeps the offsets it was taken with.
        sample = gauges.convert(gauges.analog(self._physical_load(), self._rng))
        u = self._corrected(sample)
        u_previous = mem.int16s("gauge_raw")
        y_previous = mem.int16s("gauge_filtered")
        if "filter-rounds-to-nearest" in self._readings:
            y = [round((u[i] + u_previous[i] + 6 * y_previous[i]) / 8) for i in range(GAUGES)]
        elif not self._defects.adc8_sums_then_shifts:
            y = [(u[i] >> 3) + (u_previous[i] >> 3) + (6 * y_previous[i] >> 3) for i in range(GAUGES)]
        else:
            y = [adc8_filter(u[i], u_previous[i], y_previous[i]) for i in range(GAUGES)]
        mem.put_int16s("gauge_raw", u)
        mem.put_int16s("gauge_filtered", y)

    def _corrected(self, sample: list[int]) -> list[int]:
        """A sample less the gauge offsets (§8.3: before the filter), or as it is when the offsets are
        subtracted after the filter (reading ``offsets-after-filter``)."""
        if "offsets-after-filter" in self._readings:
            return list(sample)
        return _less(sample, self.memory.int16s("gauge_offsets"))

    def _convert(self) -> None:
        mem = self.memory
        filtered = mem.int16s("gauge_filtered")
        if "offsets-after-filter" in self._readings:
            filtered = _less(filtered, mem.int16s("gauge_offsets"))
        counts = np.array(filtered, dtype=np.float64)
        force = (mem.array("voltmat").reshape(6, 8) @ counts).tolist()
        if not self._defects.conversion_negated:
            force = [-1.0 * f for f in force]
        mem.put("force_sensed", force)

    def _gravity(self) -> None:
        mem = self.memory
        theta = mem.floats("theta_sensed") if self._defects.gravity_follows_angles else READY
        r = hand_rotation(theta, self.config.geometry)
        cg = mem.floats("grav_cg") if self._defects.gravity_torque_about_cg else _UNTOUCHED[:3]
        load = gravity_load(r, mem.floats("grav_weight")[0], cg)
        force = [s + g for s, g in zip(mem.floats("force_sensed"), load, strict=True)]
        if mem.word("flags") & FLAG_LIMIT:
            force = limit(force, mem.floats("limit_dead")[0], mem.floats("limit_clamp")[0])
        mem.put("force", force)

    def _guardm(self) -> None:
        mem = self.memory
        active = mem.word("guard_active")
        if not active:
            return
        force = mem.array("force" if self._defects.guards_on_corrected_force else "force_sensed")
        base = region("guards").address
        for i in range(16):
            if not active >> i & 1:
                continue
            entry = base + 2 * GUARD_WORDS * i
            words = mem.read_words(entry, GUARD_WORDS)
            kept = self._guard_values.get(i)
            if kept is None or kept[0] != words:  # decoded again only when its words changed
                tol = float(mem.read_floats(entry + 2 * GUARD_TOL, 1)[0])
                kept = self._guard_values[i] = (words, mem.read_floats(entry + 2 * GUARD_DVEC, 6), tol)
            _, dvec, tol = kept
            dot = float(np.dot(force, dvec))
            if not self._defects.guard_compare_ordered:
                trips = dot < tol
            else:  # erratum guard-trip-comparison
                trips = dot > tol if "guard-trips-above-tol" in self._readings else dot >= tol
            if trips:
                if not self._defects.guard_trips_once and i not in self._tripped_once:
                    self._tripped_once.add(i)
                else:
                    self._tripped_once.discard(i)
                    active &= ~(1 << i)
                stop = mem.read_word(entry) & GUARD_STOP_BIT
                code = CougarResponse.GUARD_STOP if stop else CougarResponse.GUARD_CONTINUE
                self._send(code, [i])
                self._stats.guards_tripped += 1
        mem.set_word("guard_active", active)

    def _comint_run(self) -> tuple[int, int]:
        commands = words = 0
        while (item := self._comint.take()) is not None:
            if isinstance(item, OutOfSyncEvent):
                self._stats.out_of_sync += 1
                self._stats.discarded_words += len(item.discarded)
                if self._defects.sends_out_of_sync:
                    bare = "out-of-sync-bare" in self._readings
                    self._send(CougarResponse.OUT_OF_SYNC, [] if bare else [item.code])
                continue
            self._execute(item)
            commands += 1
            words += len(item.data)
        self._stats.commands += commands
        return commands, words

    def _send(self, code: int, words: Sequence[int]) -> None:
        if len(self._out) > 1 and not self._defects.idxs_checks_in_progress:
            del self._out[1]  # IDXS restarted while sending: the word due next went before the Puma was ready
        self._out.append(int(code))
        self._out.extend(int(w) for w in words)

    # ------------------------------------------------------------------ commands
    def _execute(self, cmd: Executable) -> None:
        if cmd.entry.destination is not None:
            self.memory.write_words(cmd.entry.destination, cmd.data)
        handler = _HANDLERS.get(cmd.entry.name)
        if handler is not None:
            handler(self)

    def _moved(self) -> None:
        """SEN, FINIT: the arm is where the Puma says (the simulated arm follows θ_sensed)."""
        self._pose = self.memory.floats("theta_sensed")

    def _newpr(self) -> None:
        self._moved()
        mem = self.memory
        j, _, p = front_buffer(mem)
        theta_error = mem.array("theta_sensed") - mem.array("theta_commanded")
        b = mem.array("b").reshape(6, 6)
        sample = compliance_sample(
            j,
            p,
            k=mem.array("k") if self._defects.npr_spring_term else np.zeros(6),
            b=b if self._defects.nb_by_rows else b.T,
            fc=mem.array("fc") if self._defects.npr_commanded_force else np.zeros(6),
            force=mem.array("force" if self._defects.compliance_on_corrected_force else "force_sensed"),
            theta_error=theta_error,
            rate_difference=mem.array("rate_difference"),
        )
        con = mem.array("con")
        if not self._defects.filter_cons_in_order:
            con = con[[0, 1, 3, 2]]
        previous, last = mem.array("dtheta_previous"), mem.array("dtheta_filtered")
        filtered, output = output_filter(sample, previous, last, con)
        mem.put("dtheta_previous", sample)
        mem.put("dtheta_filtered", filtered)
        mem.put("dtheta_out", output)  # RATEO
        self._send(CougarResponse.NTD, self._region_words("dtheta_out"))

    def _lengths_mm(self, name: str) -> Vector:
        """A length vector the Puma sent (``fv``, or ``object``'s cg), in millimetres."""
        values = self.memory.get(name)
        if name == "object":
            values = values[1:]
        return values * self.config.mm_per_unit if "lengths-in-inches" in self._readings else values

    def _newfv(self) -> None:
        mem = self.memory
        rows = voltmat_torque_rows(mem.get("calmat"), self._lengths_mm("fv"))
        mem.write_floats(region("voltmat").at(24), rows.reshape(-1))  # rows 4-6 only
        if self._defects.nfv_redoes_gravity:
            self._newwc()

    def _newwc(self) -> None:
        mem = self.memory
        obj = mem.get("object")
        weight, cg = gravity_model(
            float(mem.get("hand_weight")[0]),
            mem.get("hand_cg"),
            float(obj[0]),
            self._lengths_mm("object"),
            self._lengths_mm("fv"),
        )
        mem.put("grav_weight", [weight])
        mem.put("grav_cg", cg)

    def _resetw(self) -> None:
        if not self._defects.rst_zeroes_velocities:
            return
        for name in ("dtheta_previous", "dtheta_filtered", "dtheta_out", "rate_difference"):
            self.memory.put(name, np.zeros(6))

    def _inside(self, address: int) -> int:
        """The simulated memory's address of an even DPST or EXMN address inside memory.  They are the
        same but for reading ``relocated-map``, under which the memory above the PDP-11's vectors
        (MAP_BASE up) is rotated by the shift on the link: the map sits that much higher, the vectors
        stay at 0 and every address of memory is still one word."""
        shift = self.config.map_shift
        if not shift or not MAP_BASE <= address < MEMORY_BYTES:
            return address
        return MAP_BASE + (address - MAP_BASE - shift) % (MEMORY_BYTES - MAP_BASE)

    def _read(self, address: int, count: int) -> list[int]:
        """``count`` words of memory from link address ``address`` (all inside memory)."""
        if not self.config.map_shift:
            return self.memory.read_words(address, count)
        return [self.memory.read_word(self._inside(a)) for a in range(address, address + 2 * count, 2)]

    def _dep(self) -> None:
        address, value = self.memory.read_words(region("args").address, 2)
        if Memory.valid(address):
            self.memory.write_word(self._inside(address), value)
        else:
            self._stats.bad_addresses += 1

    def _exp(self) -> None:
        address, count = self.memory.read_words(region("args").address, 2)
        if "exmn-always-full" in self._readings:
            self._send(CougarResponse.EXMN_DATA, [count, *self._examine_full(address, count)])
            return
        if Memory.valid(address):
            n = min(count, (MEMORY_BYTES - address) // 2)
            if not self._defects.exmn_whole_count and n > 0:
                n -= 1
        else:
            n = 0
            self._stats.bad_addresses += 1
        words = self._read(address, n) if n else []
        self._send(CougarResponse.EXMN_DATA, [n, *words])

    def _examine_full(self, address: int, count: int) -> list[int]:
        """``count`` words from ``address`` (made even), 0 for each one outside memory."""
        start = address & ~1
        if start != address or not Memory.valid(start, count):
            self._stats.bad_addresses += 1
        return [self._read(a, 1)[0] if Memory.valid(a) else 0 for a in range(start, start + 2 * count, 2)]

    def _version(self) -> None:
        d, mem = self._defects, self.memory
        code = CougarResponse.VERSION if d.version_code_right else 3
        version = mem.word("version") if d.vers_reads_memory else self.config.version
        self._send(code, [version] if d.version_one_word else [version, mem.word("puma_version")])

    def _rfr(self) -> None:
        code = CougarResponse.FORCES if self._defects.rfrc_code_forces else CougarResponse.NTD
        self._send(code, self._region_words("force"))

    def _guards(self) -> None:
        mem = self.memory
        data = mem.read_words(region("guard_in").address, GUARD_WORDS)
        index = data[0] & 0xF
        mask = GUARD_STOP_BIT if "guard-hi-bit-only" in self._readings else GUARD_STOP_MASK
        if not self._defects.guard_type_in_high_byte:
            mask = GUARD_LOW_BYTE_SIGN
        stop = GUARD_STOP_BIT if data[0] & mask else 0
        data[0] = (
            stop | data[0] & 0xF
        )  # any high-byte bit stops; bits 4-7 are ignored (errata guard-type-bit)
        mem.write_words(region("guards").address + 2 * GUARD_WORDS * index, data)
        mem.set_word("guard_active", mem.word("guard_active") | 1 << index)

    def _guardc(self) -> None:
        if not self._defects.guardc_disarms:
            return
        index = self.memory.word("args") & 0xF
        self.memory.set_word("guard_active", self.memory.word("guard_active") & ~(1 << index) & 0xFFFF)

    def _reraw(self) -> None:
        # the gauges as the wrist reads them: the filtered readings with the offsets added back
        unfiltered = "rraw-unfiltered" in self._readings
        raw = self.memory.int16s("gauge_raw" if unfiltered else "gauge_filtered")
        if not self._defects.rraw_before_offsets:  # the readings as corrected, offsets subtracted
            if "offsets-after-filter" in self._readings:
                raw = _less(raw, self.memory.int16s("gauge_offsets"))
        elif "offsets-after-filter" not in self._readings:  # there, the readings have them
            raw = _plus(raw, self.memory.int16s("gauge_offsets"))
        d = self._defects
        words = [v & (0xFFFF if d.rraw_sign_extended else 0o7777) for v in raw]
        self._send(CougarResponse.RAW, words if d.rraw_all_gauges else words[:-1])

    def _region_words(self, name: str) -> list[int]:
        r = region(name)
        return self.memory.read_words(r.address, r.words)


def _wrap16(v: int) -> int:
    """A PDP-11 ADD or SUB result: two's complement, 16 bits."""
    return ((v + 0x8000) & 0xFFFF) - 0x8000


def _less(values: Iterable[int], offsets: Iterable[int]) -> list[int]:
    return [_wrap16(int(v) - int(o)) for v, o in zip(values, offsets, strict=True)]


def _plus(values: Iterable[int], offsets: Iterable[int]) -> list[int]:
    return [_wrap16(int(v) + int(o)) for v, o in zip(values, offsets, strict=True)]


_HANDLERS: Final[dict[str, Callable[[CougarSim], None]]] = {
    "SEN": CougarSim._moved,
    "FINIT": CougarSim._moved,
    "NPR": CougarSim._newpr,
    "NFV": CougarSim._newfv,
    "RST": CougarSim._resetw,
    "DPST": CougarSim._dep,
    "EXMN": CougarSim._exp,
    "VERS": CougarSim._version,
    "RFRC": CougarSim._rfr,
    "NEWWC": CougarSim._newwc,
    "GUARDS": CougarSim._guards,
    "GUARDC": CougarSim._guardc,
    "RRAW": CougarSim._reraw,
}
