"""What the campaign tools share (``damaged_files.py``, ``hostile_campaign.py``, ``hostile_servers.py``): a
process's peak resident memory as it runs, and the line a campaign ends with."""

from __future__ import annotations

import contextlib
import time
from collections import Counter
from collections.abc import Sequence, Set
from typing import Protocol


class Tallied(Protocol):
    """An outcome of one run: its verdict word and the peak resident memory it measured (0 in-process)."""

    @property
    def outcome(self) -> str: ...

    @property
    def rss_mb(self) -> float: ...


def peak_rss_mb(pid: int) -> float:
    """Process ``pid``'s peak resident set so far (VmHWM, MB); 0 once it is gone."""
    with contextlib.suppress(OSError), open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return 0.0


def tally(
    outcomes: Sequence[Tallied], runs: str, *, started: float, kinds: Sequence[str], bad: Set[str], peak: bool
) -> int:
    """Print the campaign's last line (``runs`` says what was run, e.g. "on 100 inputs (seed 1)"): its
    time, each kind of outcome counted and, with ``peak``, the highest peak RSS; return the exit status,
    1 when any outcome is ``bad``."""
    counts = Counter(o.outcome for o in outcomes)
    highest = max((o.rss_mb for o in outcomes), default=0.0)
    print(
        f"{len(outcomes)} runs {runs} in {time.monotonic() - started:.0f} s: "
        + ", ".join(f"{k} {counts[k]}" for k in kinds)
        + (f"; peak RSS {highest:.0f} MB" if peak else "")
    )
    return 1 if any(counts[k] for k in bad) else 0
