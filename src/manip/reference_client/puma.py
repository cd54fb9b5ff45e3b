"""The Puma wrist and compliance operations (manip's extension opcodes 0240-0261, manipulator type puma).

They reach the Cougar wrist computer through the Puma (Part II §6.3, Table 1).  Forces are ounces and
ounce-inches (Fx Fy Fz Tx Ty Tz), raw gauges are 12-bit readings, the damping matrix is 6x6 row major.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final, SupportsFloat, SupportsInt

from manip.reference_client.arguments import JOINTS, FloatArray, float_vector, int_vector, scalar, word
from manip.reference_client.extractors import (
    extract_done,
    extract_floats,
    extract_ints,
    extract_segment,
    extract_word,
)
from manip.reference_client.issuer import DEFAULT, RequestIssuer, Timeout

GAUGES: Final = 8
GAUGE_MIN: Final = -0x8000
GAUGE_MAX: Final = 0x7FFF
GUARDS: Final = 16
GUARD_STOPS_MOVE: Final = 0x8000
"""Bit 15 of the guard's first word: a trip stops the move (erratum guard-type-bit)."""


class PumaOperations(RequestIssuer):
    async def read_forces(self, *, timeout: Timeout = DEFAULT) -> tuple[float, ...]:
        """Read forces (0240): the latest gravity-corrected force/torque vector."""
        return await self._call("read-forces", extract_floats, timeout=timeout)

    async def read_raw_gauges(self, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        """Read raw wrist gauges (0241): eight signed readings."""
        return await self._call("read-raw-gauges", extract_ints, timeout=timeout)

    async def set_gauge_offsets(self, offsets: Sequence[SupportsInt], *, timeout: Timeout = DEFAULT) -> None:
        """Set the gauge offset vector (0242) subtracted from the raw readings."""
        values = int_vector(offsets, GAUGES, "offsets", GAUGE_MIN, GAUGE_MAX)
        await self._call("set-gauge-offsets", extract_done, {"offsets": values}, timeout=timeout)

    async def calibrate_wrist(self, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        """Calibrate the wrist (0243); returns the offsets it set."""
        return await self._call("calibrate-wrist", extract_ints, timeout=timeout)

    async def set_spring(self, k: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        """Spring constants (0244): the diagonal of the compliance spring matrix."""
        await self._call("set-spring", extract_done, {"k": float_vector(k, 6, "k")}, timeout=timeout)

    async def set_damping(self, b: FloatArray, *, timeout: Timeout = DEFAULT) -> None:
        """Damping matrix (0245): 36 numbers row major, or a 6x6 nested sequence or array."""
        await self._call("set-damping", extract_done, {"b": float_vector(b, 36, "b")}, timeout=timeout)

    async def set_joint_damping(self, bji: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        """Inverse joint damping (0246), diagonal terms."""
        await self._call(
            "set-joint-damping", extract_done, {"bji": float_vector(bji, 6, "bji")}, timeout=timeout
        )

    async def set_frame_vector(self, offset: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> None:
        """Frame vector (0247): the centre of compliance, offset from the wrist centre."""
        await self._call(
            "set-frame-vector", extract_done, {"offset": float_vector(offset, 3, "offset")}, timeout=timeout
        )

    async def set_weight(
        self, weight: float, cg: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT
    ) -> None:
        """Weight (ounces) and centre of gravity (0250) of the held object."""
        fields = {"weight": scalar(weight, "weight"), "cg": float_vector(cg, 3, "cg")}
        await self._call("set-weight", extract_done, fields, timeout=timeout)

    async def set_guard(
        self,
        index: int,
        dvec: Sequence[SupportsFloat],
        tol: float,
        *,
        stop: bool = True,
        timeout: Timeout = DEFAULT,
    ) -> None:
        """Arm guard ``index`` (0251, 0..15): it trips when force . ``dvec`` exceeds ``tol``; ``stop``
        makes a trip stop the move.  A trip arrives as an asynchronous guard-hit response."""
        type_index = word(index, "index", 0, GUARDS - 1) | (GUARD_STOPS_MOVE if stop else 0)
        fields = {"type_index": type_index, "dvec": float_vector(dvec, 6, "dvec"), "tol": scalar(tol, "tol")}
        await self._call("set-guard", extract_done, fields, timeout=timeout)

    async def clear_guard(self, index: int, *, timeout: Timeout = DEFAULT) -> None:
        """Disarm guard ``index`` (0252)."""
        await self._call(
            "clear-guard", extract_done, {"index": word(index, "index", 0, GUARDS - 1)}, timeout=timeout
        )

    async def compliant_move(
        self, joints: Sequence[SupportsFloat], scheme: int = 0, *, timeout: Timeout = DEFAULT
    ) -> int:
        """Move to joint angles under compliance (0253); returns the segment number."""
        fields = {"joints": float_vector(joints, JOINTS, "joints"), "scheme": word(scheme, "scheme")}
        return await self._call("compliant-move", extract_segment, fields, timeout=timeout)

    async def examine_wrist(self, address: int, count: int, *, timeout: Timeout = DEFAULT) -> tuple[int, ...]:
        """Read ``count`` words of wrist memory at ``address`` (0254)."""
        fields = {"address": word(address, "address"), "count": word(count, "count")}
        return await self._call("examine-wrist", extract_ints, fields, timeout=timeout)

    async def deposit_wrist(self, address: int, value: int, *, timeout: Timeout = DEFAULT) -> None:
        """Write one word of wrist memory (0255)."""
        fields = {"address": word(address, "address"), "value": word(value, "value")}
        await self._call("deposit-wrist", extract_done, fields, timeout=timeout)

    async def wrist_version(self, *, timeout: Timeout = DEFAULT) -> int:
        """The wrist software's version number (0256)."""
        return await self._call("wrist-version", extract_word, timeout=timeout)

    async def reset_abort(self, *, timeout: Timeout = DEFAULT) -> None:
        """Clear the aborted-motion condition (0260) without touching power (erratum abort-reset)."""
        await self._call("reset-abort", extract_done, timeout=timeout)

    async def set_commanded_force(
        self, force: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT
    ) -> None:
        """The force/torque the compliance law should hold (0261)."""
        await self._call(
            "set-commanded-force", extract_done, {"force": float_vector(force, 6, "force")}, timeout=timeout
        )
