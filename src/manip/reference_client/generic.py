"""The generic operations of Appendix E.1 (opcodes 0200-0221), common to every manipulator.

Units are millimetres and degrees (erratum ``units``); joint angles start at the base (the Lee/VAL
convention, erratum ``joint-convention``).  Solve forwards takes a transform and returns joint
angles, solve backwards the reverse (erratum ``solve-direction``).  Motion operations return the
segment number as soon as the server has queued the segment; use ``wait_for_segment`` to wait for
the motion itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import SupportsFloat

from manip.arm.transform import Transform
from manip.codecs.lisp import LispValue
from manip.reference_client.arguments import JOINTS, float_vector, scalar, word
from manip.reference_client.extractors import (
    extract_alist,
    extract_done,
    extract_floats,
    extract_segment,
    extract_transform,
)
from manip.reference_client.issuer import DEFAULT, RequestIssuer, Timeout

LEFTY = 1
RIGHTY = 0


class GenericOperations(RequestIssuer):
    async def describe(self, *, timeout: Timeout = DEFAULT) -> dict[str, LispValue]:
        """Describe self (0200): the alist, keyword names without the colon (``"brand-name"``)."""
        return await self._call("describe-self", extract_alist, timeout=timeout)

    async def here(self, *, timeout: Timeout = DEFAULT) -> Transform:
        """Here (0201): where the hand is."""
        return await self._call("here", extract_transform, timeout=timeout)

    async def joint_angles(self, *, timeout: Timeout = DEFAULT) -> tuple[float, ...]:
        """Joint angles (0202), degrees, base first."""
        return await self._call("joint-angles", extract_floats, timeout=timeout)

    async def calibrate(self, *, timeout: Timeout = DEFAULT) -> None:
        """Calibrate (0203)."""
        await self._call("calibrate", extract_done, timeout=timeout)

    async def move(self, target: Transform, *, timeout: Timeout = DEFAULT) -> int:
        """Joint-interpolated move (0204) to ``target``; returns the segment number."""
        return await self._call("move", extract_segment, {"transform": target.to_floats()}, timeout=timeout)

    async def straight_move(self, target: Transform, *, timeout: Timeout = DEFAULT) -> int:
        """Straight-line move (0205) to ``target``; returns the segment number."""
        return await self._call(
            "straight-move", extract_segment, {"transform": target.to_floats()}, timeout=timeout
        )

    async def kill_power(self, *, timeout: Timeout = DEFAULT) -> None:
        """Kill arm power (0206)."""
        await self._call("kill-power", extract_done, timeout=timeout)

    async def set_configuration(self, lefty: bool, *, timeout: Timeout = DEFAULT) -> None:
        """Set configuration (0207): lefty or righty, sent as one word (erratum set-configuration)."""
        await self._call(
            "set-configuration", extract_done, {"configuration": LEFTY if lefty else RIGHTY}, timeout=timeout
        )

    async def hand(self, amount: int, *, timeout: Timeout = DEFAULT) -> None:
        """Open or close the hand (0210); on a binary hand 0 closes and anything else opens."""
        await self._call("hand", extract_done, {"amount": word(amount, "amount")}, timeout=timeout)

    async def open_hand(self, *, timeout: Timeout = DEFAULT) -> None:
        await self.hand(1, timeout=timeout)

    async def close_hand(self, *, timeout: Timeout = DEFAULT) -> None:
        await self.hand(0, timeout=timeout)

    async def incremental_move(
        self,
        dx: float = 0.0,
        dy: float = 0.0,
        dz: float = 0.0,
        do: float = 0.0,
        da: float = 0.0,
        dt: float = 0.0,
        *,
        timeout: Timeout = DEFAULT,
    ) -> int:
        """Incremental move (0211) by mm and VAL O, A, T degrees; returns the segment number."""
        delta = float_vector([dx, dy, dz, do, da, dt], 6, "delta")
        return await self._call("incremental-move", extract_segment, {"delta": delta}, timeout=timeout)

    async def incremental_straight_move(
        self,
        dx: float = 0.0,
        dy: float = 0.0,
        dz: float = 0.0,
        do: float = 0.0,
        da: float = 0.0,
        dt: float = 0.0,
        *,
        timeout: Timeout = DEFAULT,
    ) -> int:
        """Incremental straight-line move (0212); returns the segment number."""
        delta = float_vector([dx, dy, dz, do, da, dt], 6, "delta")
        return await self._call(
            "incremental-straight-move", extract_segment, {"delta": delta}, timeout=timeout
        )

    async def ready(self, *, timeout: Timeout = DEFAULT) -> int:
        """Move to the ready position (0214); returns the segment number."""
        return await self._call("ready", extract_segment, timeout=timeout)

    async def set_joint_angles(self, joints: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT) -> int:
        """Move to joint angles (0215), degrees; returns the segment number."""
        q = float_vector(joints, JOINTS, "joints")
        return await self._call("set-joint-angles", extract_segment, {"joints": q}, timeout=timeout)

    async def set_speed(self, factor: float, *, timeout: Timeout = DEFAULT) -> None:
        """Set the speed factor (0216), 0 < factor <= 1 (checked here; clause speed.range)."""
        value = scalar(factor, "factor")
        if not 0.0 < value <= 1.0:
            raise ValueError(f"the speed factor must be in (0, 1], got {value}")
        await self._call("set-speed", extract_done, {"factor": value}, timeout=timeout)

    async def enable_power(self, *, timeout: Timeout = DEFAULT) -> None:
        """Enable high power (0217); it also clears an aborted-motion condition (erratum abort-reset)."""
        await self._call("enable-power", extract_done, timeout=timeout)

    async def solve_forwards(
        self, target: Transform, current: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT
    ) -> tuple[float, ...]:
        """Solve forwards (0220): the joint angles reaching ``target``, choosing near ``current``."""
        q = float_vector(current, JOINTS, "current")
        return await self._call(
            "solve-forwards",
            extract_floats,
            {"transform": target.to_floats(), "current": q},
            timeout=timeout,
        )

    async def solve_backwards(
        self, joints: Sequence[SupportsFloat], *, timeout: Timeout = DEFAULT
    ) -> Transform:
        """Solve backwards (0221): the transform of the joint angles."""
        q = float_vector(joints, JOINTS, "joints")
        return await self._call("solve-backwards", extract_transform, {"joints": q}, timeout=timeout)
