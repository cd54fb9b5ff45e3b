"""Is a verdict stable?  Comparing the runs of ``manip-conform run --repeat N``.

A conformance verdict is only worth something if it does not depend on the draw.  ``--repeat N`` runs
the selection with N seeds (the given one first, then seeds derived from it) and once more with the
first seed; :func:`instability` then names every case whose outcome changed between seeds, and every
case whose outcome (or, in virtual time, whose packets on the wire) changed between the two runs of one
seed.  Each is a problem of the suite, not of the target: the run exits 4.  (Against an external target
a property case may find a real defect with some seeds only: rerun with the seed that failed.)
"""

from __future__ import annotations

import hashlib
from collections import defaultdict
from collections.abc import Sequence

from manip.conformance.suite.results import CaseResult, RunReport

__all__ = ["instability", "repeat_seeds"]

SEEDS_SHOWN = 4


def repeat_seeds(seed: int, runs: int) -> list[int]:
    """The seeds of ``runs`` runs: ``seed`` first, then 32-bit seeds derived from it."""
    derived = [
        int.from_bytes(hashlib.sha256(f"{seed}:repeat:{i}".encode()).digest()[:4], "big")
        for i in range(1, runs)
    ]
    return [seed, *derived]


def instability(reports: Sequence[RunReport], *, compare_packets: bool) -> list[str]:
    """What changed across ``reports``, whose last run repeats the first one's seed (see the module
    docstring).  ``compare_packets``: the two runs of one seed must also have put the same packets on the
    wire (true of a simulated run, not of a real-time one)."""
    problems: list[str] = []
    seeded = reports[:-1] if len(reports) > 1 else reports
    outcomes: dict[str, dict[str, list[int]]] = defaultdict(lambda: defaultdict(list))
    for report in seeded:
        for result in report.results:
            outcomes[result.id][result.outcome].append(report.seed)
    for case_id, by_outcome in sorted(outcomes.items()):
        if len(by_outcome) > 1:
            shown = "; ".join(f"{outcome} with seed {_seeds(seeds)}" for outcome, seeds in by_outcome.items())
            problems.append(f"case {case_id} changes its verdict with the seed: {shown}")
    if len(reports) > 1:
        problems += _same_seed(reports[0], reports[-1], compare_packets)
    return problems


def _same_seed(first: RunReport, again: RunReport, compare_packets: bool) -> list[str]:
    problems = []
    repeated = {r.id: r for r in again.results}
    for a in first.results:
        b = repeated.get(a.id)
        if b is None:
            continue
        if a.outcome != b.outcome:
            problems.append(f"case {a.id} gave {a.outcome}, then {b.outcome} with the same seed {first.seed}")
        elif compare_packets and (where := _first_difference(a, b)) is not None:
            problems.append(
                f"case {a.id} put different packets on the wire in two runs of seed {first.seed} "
                f"(first at packet {where})"
            )
    return problems


def _first_difference(a: CaseResult, b: CaseResult) -> int | None:
    for index, (x, y) in enumerate(zip(a.packets, b.packets, strict=False)):
        if x != y:
            return index
    return None if len(a.packets) == len(b.packets) else min(len(a.packets), len(b.packets))


def _seeds(seeds: list[int]) -> str:
    shown = ", ".join(str(s) for s in seeds[:SEEDS_SHOWN])
    return shown + (f" and {len(seeds) - SEEDS_SHOWN} more" if len(seeds) > SEEDS_SHOWN else "")
