"""The start shared by the runs over a capture (verify, replay, serve): an empty report, and the
sessions asked for, read from the capture.

A capture that cannot be read, or that lacks the sessions asked for, is not an exception here: the
report is marked ``unreachable`` (exit 3) with the reason in ``problems``, and no session is returned.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from datetime import UTC, datetime

from manip.captures import Capture, CaptureError, Session, read_capture
from manip.conformance.suite.results import RunReport


def capture_report(
    target: str, *, embedded: bool, strict: bool, options: dict[str, object], command: str
) -> RunReport:
    """An empty report of a run over a capture, started now (seed 0: such runs draw nothing at random)."""
    return RunReport(
        target=target,
        embedded=embedded,
        seed=0,
        strict=strict,
        options=options,
        command=command,
        started=datetime.now(UTC).isoformat(timespec="seconds"),
    )


def select_sessions(
    sessions: Sequence[Session], wanted: Sequence[int], report: RunReport
) -> list[tuple[int, Session]]:
    """(1-based number, session) of the sessions asked for; marks ``report`` unreachable when there
    is nothing to judge."""
    numbered = list(enumerate(sessions, start=1))
    if not numbered:
        report.capture_problem("the capture holds no session (no Chaos connection was recorded)")
        return []
    if wanted:
        missing = [n for n in wanted if not 1 <= n <= len(numbered)]
        if missing:
            report.capture_problem(
                f"no session {', '.join(map(str, missing))} in the capture (it has {len(numbered)})"
            )
            return []
        numbered = [item for item in numbered if item[0] in wanted]
    return numbered


def open_capture(path: str | os.PathLike[str], report: RunReport) -> Capture | None:
    """The capture at ``path``; None, with ``report`` marked unreachable, when it cannot be read."""
    try:
        return read_capture(path)
    except CaptureError as exc:
        report.capture_problem(f"the capture cannot be read: {exc}")
        return None


def read_sessions(
    path: str | os.PathLike[str], wanted: Sequence[int], report: RunReport
) -> list[tuple[int, Session]]:
    """The sessions of the capture at ``path`` numbered in ``wanted`` (all when empty), 1-based; none,
    with ``report`` marked unreachable, when the capture cannot be read or lacks them."""
    capture = open_capture(path, report)
    return [] if capture is None else select_sessions(capture.sessions, wanted, report)
