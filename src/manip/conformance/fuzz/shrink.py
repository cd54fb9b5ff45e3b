"""Shrinking a violation to the fewest inputs that still cause it: delta debugging over the batch.

:func:`ddmin` is Zeller's minimizing delta debugging: split the inputs in ``n`` parts, keep a part
(or the rest without a part) that still fails, else split finer; it ends with a set from which no
single part can be left out.  Inputs keep their order.  Every trial is a real batch sent to the
target (:meth:`~.campaign.Campaign.reproduces`), so the ``budget`` bounds their number and the time
they take; when it runs out, the smallest failing set found so far is the answer.
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field

__all__ = ["Budget", "BudgetError", "ddmin"]


class BudgetError(Exception):
    """The shrinking budget ran out."""


@dataclass
class Budget:
    """At most ``trials`` trials within ``seconds``."""

    trials: int = 200
    seconds: float = 60.0
    used: int = 0
    started: float = field(default_factory=time.monotonic)

    def spend(self) -> None:
        if self.used >= self.trials or time.monotonic() - self.started > self.seconds:
            raise BudgetError(f"{self.used} trials in {time.monotonic() - self.started:.1f} s")
        self.used += 1


Test = Callable[[list[int]], Awaitable[bool]]


async def ddmin(items: Sequence[int], fails: Test, budget: Budget) -> tuple[list[int], bool]:
    """The smallest sublist of ``items`` (which must fail) found to fail; True when it is 1-minimal
    (no part can be left out), False when the budget ran out first."""
    current = list(items)
    seen: dict[tuple[int, ...], bool] = {tuple(current): True}

    async def test(candidate: list[int]) -> bool:
        key = tuple(candidate)
        if key not in seen:
            budget.spend()
            seen[key] = await fails(candidate)
        return seen[key]

    n = 2
    try:
        while len(current) >= 2:
            size = len(current)
            parts = [current[size * i // n : size * (i + 1) // n] for i in range(n)]
            parts = [p for p in parts if p]
            for part in parts:
                if await test(part):
                    current, n = part, 2
                    break
            else:
                for i in range(len(parts)):
                    rest = [x for j, p in enumerate(parts) if j != i for x in p]
                    if rest and await test(rest):
                        current, n = rest, max(n - 1, 2)
                        break
                else:
                    if n >= size:
                        return current, True
                    n = min(size, 2 * n)
    except BudgetError:
        return current, False
    return current, True
