"""Count what ``manip-conform diff`` shows of every protocol fault of the reference server: the fault on
side B (embedded, virtual time) against a clean side A, over the scenarios and a few generated streams
of one seed, as ``tests/conformance/diff/test_faults.py`` runs them (without stopping at the first stream
that shows the fault).

    .venv/bin/python tools/diff_faults.py                      # every protocol fault, seed 7, 2 streams
    .venv/bin/python tools/diff_faults.py --fault joints-reversed --fault keeps-abort --streams 4
    .venv/bin/python tools/diff_faults.py --link chudp --fault chudp-lsb-first   # both sides over CHUDP
    .venv/bin/python tools/diff_faults.py --fault silent-peer-kept --broken-after 90   # the timer told
    .venv/bin/python tools/diff_faults.py --link chaosd --fault chaosd-msb-first # both behind a chaosd

One line per fault: its differences by class, (a) violation, (b) both allowed, (c) unexplained;
``shown`` when a class (a) difference with side B the violator names one of the fault's clauses; the
clauses the (a) differences name.  Then the totals, and the CPU seconds the run took.  The clean side's
observations are the same for every fault, so each stream is observed on it once.  Exit status 0, or 1
when the clean side is named a violator.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import replace

from manip.conformance.diff.classify import CLASSES, Finding
from manip.conformance.diff.driver import DiffConfig, run_diff
from manip.conformance.diff.scenarios import scenarios
from manip.conformance.diff.sides import Side, input_link
from manip.conformance.diff.streams import Stream, make_streams
from manip.conformance.fuzz.generators import GenOptions
from manip.conformance.suite.embedded import SimulatedLink
from manip.reference_server import FaultSet, ServerConfig
from manip.reference_server.faults import WRIST_SIDE, Fault

CLEAN = Side("A", "clean", config=ServerConfig())
LINKS = ("unix", "chudp", "chaosd")


def protocol_faults() -> list[Fault]:
    """The server's protocol faults but the wrist side's (the Puma cases' to catch), by name."""
    return sorted((f for f in Fault if f.kind == "protocol" and f not in WRIST_SIDE), key=lambda f: f.value)


def side_pair(fault: Fault, link: SimulatedLink, timer: float | None = None) -> tuple[Side, Side]:
    """The clean side A and side B with ``fault`` on, both reached over ``link``; ``timer``: both sides'
    broken-connection timer (None: not told, and the scenario that waits it out is not sent)."""
    config_b = ServerConfig(faults=FaultSet.parse([fault.value]))
    faulty = Side("B", fault.value, config=config_b, link=link, broken_after=timer)
    return replace(CLEAN, link=link, broken_after=timer), faulty


def named_by_b(found: list[Finding]) -> set[str]:
    """The clauses the class (a) differences name with side B the violator."""
    return {n for f in found if f.cls == "violation" and f.violator == "B" for n in f.names}


def findings(
    fault: Fault, streams: list[Stream], config: DiffConfig, link: SimulatedLink, timer: float | None = None
) -> list[Finding]:
    """The differences of ``fault`` on side B (:func:`side_pair`)."""
    return [f for r in run_diff(*side_pair(fault, link, timer), streams, config) for f in r.findings]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--streams", type=int, default=2, help="generated streams after the scenarios")
    parser.add_argument("--length", type=int, default=8, help="inputs per generated stream")
    parser.add_argument("--fault", action="append", default=[], help="only this fault (repeatable)")
    parser.add_argument("--link", choices=LINKS, default="unix", help="how both sides are reached")
    parser.add_argument(
        "--broken-after",
        type=float,
        default=None,
        help="both sides' broken-connection timer, s (without it the silent-peer scenario is not sent)",
    )
    args = parser.parse_args()
    link: SimulatedLink = args.link
    chosen = [f for f in protocol_faults() if not args.fault or f.value in args.fault]
    gen = GenOptions(link=input_link(link))
    streams = [*scenarios(), *make_streams(args.seed, args.streams, args.length, gen)]
    config = DiffConfig(args.seed, shrink=False, seen_a={})  # the clean side observed once per stream
    started = time.process_time()
    totals: Counter[str] = Counter()
    shown = 0
    status = 0
    print("fault\ta\tb\tc\tshown\tclauses named (a)")
    for fault in chosen:
        found = findings(fault, streams, config, link, args.broken_after)
        counts = Counter(f.cls for f in found)
        totals.update(counts)
        named = sorted(named_by_b(found))
        hit = bool(set(named) & set(fault.clauses))
        shown += hit
        if any(f.cls == "violation" and f.violator in ("A", "both") for f in found):
            status = 1
        cells = "\t".join(str(counts[c]) for c in CLASSES)
        print(f"{fault.value}\t{cells}\t{'shown' if hit else '-'}\t{', '.join(named)}", flush=True)
    cells = "\t".join(str(totals[c]) for c in CLASSES)
    print(f"total ({len(chosen)} faults)\t{cells}\t{shown} shown")
    print(f"{time.process_time() - started:.1f} s of CPU", file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
