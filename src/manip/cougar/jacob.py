"""JACOB, the background task (B.2, B.3, §8.1): the Jacobian, its transpose and P = BJI·Jᵀ, double-buffered.

Theory of operation.  Two buffers, ``jbuf0`` and ``jbuf1``, each hold J, Jᵀ (stored explicitly after J,
as in B.2) and P.  The low bit of the ``jacob_front`` word says which one the foreground (NPR, under
GUTS) reads; the background writes only the other.  One computation runs in :data:`STEPS` steps, and
the simulator runs a configurable number of steps after each GUTS (the time left before the next clock
tick), so a computation may span ticks:

1. ``snapshot``: take θ_sensed, the frame vector and BJI from memory, compute J; write J.
2. ``transpose``: write Jᵀ.
3. ``premultiply``: write P = BJI·Jᵀ.
4. ``swap``: flip the ``jacob_front`` bit, publishing the new buffer at once.

Until step 4 the foreground keeps reading the previous complete buffer, so it never sees a half-computed
one; inputs that change during a computation are picked up by the next one.  The computation then starts
again, even when nothing changed (§7.1: it "runs continuously").
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from typing import Final

import numpy as np
import numpy.typing as npt

from manip.arm import PumaGeometry
from manip.cougar.compliance import centre_jacobian
from manip.cougar.memory import JBUF_J, JBUF_JT, JBUF_P, Memory, region

__all__ = ["STEPS", "Jacob", "front_buffer"]

STEPS: Final = 4
_ROWS: Final = 6
_ROW_BYTES: Final = 4 * 6
"""One row of J: six floats of two words."""
IN_PLACE_STEPS: Final = _ROWS + 2
"""Steps of one computation written in place (fault ``jacob-one-buffer``): J's six rows, Jᵀ, P."""
Matrix = npt.NDArray[np.float64]


_BUFFERS: Final = (region("jbuf0").address, region("jbuf1").address)


def _buffer_address(memory: Memory, front: bool) -> int:
    bit = memory.word("jacob_front") & 1
    return _BUFFERS[bit if front else bit ^ 1]


def front_buffer(memory: Memory) -> tuple[Matrix, Matrix, Matrix]:
    """(J, Jᵀ, P) as the foreground sees them: from the buffer ``jacob_front`` points at (read-only)."""
    values = memory.array(f"jbuf{memory.word('jacob_front') & 1}")
    return (
        values[JBUF_J : JBUF_J + 36].reshape(6, 6),
        values[JBUF_JT : JBUF_JT + 36].reshape(6, 6),
        values[JBUF_P : JBUF_P + 36].reshape(6, 6),
    )


Encoded = tuple[bytes, bool]
"""Floats as :meth:`Memory.encode_floats` gives them: the words, and whether storing them saturates."""


@dataclass
class Jacob:
    """The background task's registers: which step is next and the Jacobian being built.

    The computation is the same whether or not its inputs changed (it "runs continuously"), so what it
    stores is kept with the inputs it came from: while θ_sensed, FV and BJI stay the same the steps store
    the kept words again (each store as the computation would have made it, float faults included).
    """

    geometry: PumaGeometry
    mm_per_unit: float = 1.0
    """Millimetres per length unit of the frame vector in memory and of J's translational rows (25.4 for
    a Cougar in inches: reading ``lengths-in-inches``)."""
    transpose_stored: bool = True
    """False only for the fault ``jacobian-transpose-not-stored``: J's words stored again where Jᵀ goes."""
    bji_per_joint: bool = True
    """False only for the fault ``nbji-first-only``: every joint scaled by BJI's first element."""
    double_buffered: bool = True
    """False only for the fault ``jacob-one-buffer``: J written a row per step into the front buffer, which
    never switches (:data:`IN_PLACE_STEPS` steps a computation)."""
    joint_signs_right: bool = True
    """False only for the fault ``jacobian-joint-sign``: J's second column (joint 2) negated."""
    step_index: int = 0
    cycles: int = 0
    _j: Matrix = field(default_factory=lambda: np.zeros((6, 6)))
    _bji: tuple[float, ...] = (0.0,) * 6
    _inputs: tuple[tuple[float, ...], ...] | None = None
    _words: tuple[Encoded, Encoded, Encoded] | None = None
    """J, Jᵀ and P encoded for the inputs ``_inputs`` (θ_sensed, FV, BJI)."""

    def step(self, memory: Memory) -> None:
        """Run one step of the computation."""
        if not self.double_buffered:
            self._step_in_place(memory)
            return
        back = _buffer_address(memory, front=False)
        if self.step_index == 0:
            self._snapshot(memory)
            memory.store_encoded(back + 4 * JBUF_J, *self._stored_words()[0])
        elif self.step_index == 1:
            memory.store_encoded(back + 4 * JBUF_JT, *self._stored_words()[1])
        elif self.step_index == 2:
            memory.store_encoded(back + 4 * JBUF_P, *self._stored_words()[2])
        else:
            memory.set_word("jacob_front", (memory.word("jacob_front") & 1) ^ 1)
            self.cycles += 1
        self.step_index = (self.step_index + 1) % STEPS

    def _snapshot(self, memory: Memory) -> None:
        """Take θ_sensed, the frame vector and BJI from memory; J, Jᵀ and P for them, encoded."""
        theta, fv = memory.floats("theta_sensed"), memory.floats("fv")
        bji = memory.floats("bji")
        self._bji = bji if self.bji_per_joint else (bji[0],) * len(bji)
        inputs = (theta, fv, self._bji)
        if inputs != self._inputs:  # decoded floats, never NaN: equal inputs, the same J and P
            if self._inputs is None or inputs[:2] != self._inputs[:2]:
                # angles that are not angles (a bad deposit) keep the last Jacobian
                with contextlib.suppress(ValueError):
                    self._j = self._jacobian(theta, fv)
            self._inputs = inputs
            self._words = self._encode()

    def _step_in_place(self, memory: Memory) -> None:
        """One step of the fault ``jacob-one-buffer``: rows of J, then Jᵀ, then P, into the front buffer."""
        front, i = _buffer_address(memory, front=True), self.step_index
        if i == 0:
            self._snapshot(memory)
        (j_words, saturated), jt, p = self._stored_words()
        if i < _ROWS:
            row = _ROW_BYTES * i
            memory.store_encoded(front + 4 * JBUF_J + row, j_words[row : row + _ROW_BYTES], saturated)
        else:
            memory.store_encoded(front + 4 * (JBUF_JT if i == _ROWS else JBUF_P), *(jt if i == _ROWS else p))
            self.cycles += i == IN_PLACE_STEPS - 1
        self.step_index = (i + 1) % IN_PLACE_STEPS

    def _jacobian(self, theta: tuple[float, ...], fv: tuple[float, ...]) -> Matrix:
        """J at the compliance centre, in the Cougar's length unit."""
        if self.mm_per_unit == 1.0:
            j = centre_jacobian(theta, fv, self.geometry)
        else:
            j = centre_jacobian(theta, [v * self.mm_per_unit for v in fv], self.geometry)
            j[:3] /= self.mm_per_unit
        if not self.joint_signs_right:
            j[:, 1] = -j[:, 1]
        return j

    def _stored_words(self) -> tuple[Encoded, Encoded, Encoded]:
        if self._words is None:  # steps 1 and 2 before any step 0 (a Jacob started mid-computation)
            self._words = self._encode()
        return self._words

    def _encode(self) -> tuple[Encoded, Encoded, Encoded]:
        """J, Jᵀ and P = BJI·Jᵀ as stored.  Jᵀ's words are J's, transposed (rounding is per element)."""
        j_words, saturated = Memory.encode_floats(self._j)
        j = memoryview(j_words).cast("I")
        jt_words = b"".join(j[i::6].tobytes() for i in range(6)) if self.transpose_stored else j_words
        p = (np.array(self._bji)[:, None]) * self._j.T
        return (j_words, saturated), (jt_words, saturated), Memory.encode_floats(p)

    def run(self, memory: Memory, steps: int) -> None:
        for _ in range(steps):
            self.step(memory)
