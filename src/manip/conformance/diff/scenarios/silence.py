"""The diff's scenario of a silent client: a connection whose peer falls silent must be given up after
the server's broken-connection timer (clause ``ncp.broken``).

The 1985 guide sets no Chaos timer: each server's is its own (erratum ``ncp-timers``; 90 s on manip's
NCP, the ITS NCP's interval), so the scenario is sent only when the diff is told the sides' timers
(``--broken-after``, as ``manip-conform run`` tells ``server.ncp.broken``), and waits out the longer
of them plus the directed case's margin.  Its connection, every answer in and receipted, then sends
nothing at all (no packet, no receipt, no STS for the server's SNS probes); past the timer it sends an
SNS on it.  A server that gave the connection up answers that SNS with a LOS (a packet for a connection
that no longer exists); one that kept it answers with an STS, which this module's check names.
An embedded side runs the silence in virtual time.  Sans-I/O.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Final

from manip.conformance.cases.server.ncp import broken_slack
from manip.conformance.diff.scenarios.chaos import ANSWER_WAIT
from manip.conformance.diff.scenarios.kit import Events, scenario_inputs, sighting
from manip.conformance.diff.streams import Stream
from manip.conformance.fuzz.judge import Sighting
from manip.conformance.fuzz.steps import ConnPacket, Pause, Silence, Step
from manip.ncp import NcpConfig
from manip.spec.constants import ChaosOp

NAME: Final = "silent-peer"
REFERENCE_TIMER: Final = NcpConfig().broken_after
"""The reference server's broken-connection timer (s): the one the scenario is shown with before the
diff knows the sides' (it is made again for theirs)."""
_STS: Final = f"0{ChaosOp.STS:o}"


def _kept(timer: float, silent: float, events: Events) -> list[Sighting]:
    """The SNS sent past the timer answered with an STS, and no LOS or CLS ending the connection: the
    server kept a connection whose peer was silent for ``silent`` seconds, past ``timer``."""
    got = events.get(0, [])
    if any(e.kind == "end" for e in got):
        return []
    answered = [e for e in got if e.kind == "stray" and e.text.startswith("sts:") and _STS in e.text.split()]
    return [
        sighting(
            0,
            "ncp.broken",
            f"the connection was kept through {silent:g} s of silence from its peer (its timer: "
            f"{timer:g} s): an SNS on it was answered with an STS",
            f"the connection given up after {timer:g} s of silence: the SNS answered with a LOS",
            e,
        )
        for e in answered[:1]
    ]


def silent_peer(timer: float) -> Stream:
    """The connection silent for ``timer`` and the directed case's margin, then an SNS on it, which a
    server whose broken-connection timer is ``timer`` must answer with a LOS (module docstring)."""
    silent = timer + broken_slack(timer)
    probe = ConnPacket("sns", ChaosOp.SNS, clause="ncp.los")
    groups: list[tuple[str, list[Step]]] = [
        (
            f"silent for {silent:g} s (the timer {timer:g} s), then an SNS on the connection",
            [Silence(silent), probe, Pause(ANSWER_WAIT)],
        ),
    ]
    check = functools.partial(_kept, timer, silent)
    return Stream(None, scenario_inputs(NAME, groups), scenario=NAME, check=check, timed=silent_peer)


SCENARIOS: Final[dict[str, Callable[[], Stream]]] = {
    NAME: functools.partial(silent_peer, REFERENCE_TIMER),
}
"""This module's scenarios by name, in the order a diff sends them."""
