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
Matrix = npt.NDArray[np.float64]


def _buffer_address(memory: Memory, front: bool) -> int:
    bit = memory.word("jacob_front") & 1
    index = bit if front else bit ^ 1
    return region(f"jbuf{index}").address


def front_buffer(memory: Memory) -> tuple[Matrix, Matrix, Matrix]:
    """(J, Jᵀ, P) as the foreground sees them: from the buffer ``jacob_front`` points at."""
    base = _buffer_address(memory, front=True)
    values = memory.read_floats(base, 108)
    return (
        values[JBUF_J : JBUF_J + 36].reshape(6, 6),
        values[JBUF_JT : JBUF_JT + 36].reshape(6, 6),
        values[JBUF_P : JBUF_P + 36].reshape(6, 6),
    )


@dataclass
class Jacob:
    """The background task's registers: which step is next and the Jacobian being built."""

    geometry: PumaGeometry
    step_index: int = 0
    cycles: int = 0
    _j: Matrix = field(default_factory=lambda: np.zeros((6, 6)))
    _bji: Matrix = field(default_factory=lambda: np.zeros(6))

    def step(self, memory: Memory) -> None:
        """Run one step of the computation."""
        back = _buffer_address(memory, front=False)
        if self.step_index == 0:
            theta = memory.get("theta_sensed")
            fv = memory.get("fv")
            self._bji = memory.get("bji")
            # angles that are not angles (a bad deposit) keep the last Jacobian
            with contextlib.suppress(ValueError):
                self._j = centre_jacobian(theta, fv, self.geometry)
            memory.write_floats(back + 4 * JBUF_J, self._j)
        elif self.step_index == 1:
            memory.write_floats(back + 4 * JBUF_JT, self._j.T)
        elif self.step_index == 2:
            memory.write_floats(back + 4 * JBUF_P, self._bji[:, None] * self._j.T)
        else:
            memory.set_word("jacob_front", (memory.word("jacob_front") & 1) ^ 1)
            self.cycles += 1
        self.step_index = (self.step_index + 1) % STEPS

    def run(self, memory: Memory, steps: int) -> None:
        for _ in range(steps):
            self.step(memory)
