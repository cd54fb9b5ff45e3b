"""Run a fuzz campaign against the reference server with each protocol fault switch on, one at a time,
and say which faults the campaign finds.

A fault is *found* when the campaign reports a violation citing one of the clauses the fault breaks
(``manip-server --list-faults`` names them); *found otherwise* when it reports violations, none of them
on those clauses; *not found* when the campaign sees nothing wrong.  Environment faults (the panic
button, an obstacle, a calibration failure) change the arm's world, not the protocol, and are not
judged themselves.  Two protocol faults only show when the arm's world gives them the chance, so their
campaigns also switch on an environment fault (:data:`WITH`): a fatal error comes from calibrate violation
no zero index, an abort from an obstacle that joint 2 runs into on its way to the ready position.
Those environment faults are also run alone first: a conformant server meeting them must give no
violation.  Each line gives the violations (kind and clause), how many inputs the first one was shrunk to,
and the campaign's time.

    .venv/bin/python tools/fuzz_faults.py                    # 3,000 inputs per fault, seed 1
    .venv/bin/python tools/fuzz_faults.py --inputs 10000 --seed 7 --markdown
    .venv/bin/python tools/fuzz_faults.py --fault wrong-severity --fault no-jor

Options it does not know go to ``manip-conform fuzz`` (``--batch 200``...).  Exit status: 0 when the
campaigns without a protocol fault have no violation and every campaign ran, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from manip.reference_server.faults import Fault

WITH: dict[str, tuple[str, ...]] = {
    "fatal-without-close": ("calibrate-nzi",),
    "awa-ignored": ("obstacle=2:-45:",),
}
"""Environment faults a protocol fault needs to show (see the module docstring)."""


@dataclass
class Outcome:
    name: str
    clauses: tuple[str, ...]
    verdict: str
    found: list[str]
    shrunk_to: int | None
    seconds: float
    exit_code: int


def campaign(
    faults: tuple[str, ...], inputs: int, seed: int, extra: list[str]
) -> tuple[dict[str, Any], float, int]:
    """Run ``manip-conform fuzz`` with ``faults``; its JSON report, time and exit code."""
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "fuzz.json"
        cmd = [sys.executable, "-m", "manip.conformance.cli", "fuzz", "-q", "--json", str(report)]
        cmd += ["--inputs", str(inputs), "--seed", str(seed), *extra]
        for fault in faults:
            cmd += ["--server-fault", fault]
        started = time.monotonic()
        done = subprocess.run(cmd, capture_output=True, text=True, check=False)
        elapsed = time.monotonic() - started
        if not report.exists():
            output = done.stdout + done.stderr
            raise SystemExit(f"{' '.join(cmd)} wrote no report (exit {done.returncode}):\n{output}")
        return json.loads(report.read_text()), elapsed, done.returncode


def judge(name: str, clauses: tuple[str, ...], report: dict[str, Any], seconds: float, code: int) -> Outcome:
    violations = report["campaign"]["violations"]
    named = [f"{f['kind']} {f['clause'] or ''}".strip() for f in violations]
    hits = [f for f in violations if f["clause"] in clauses]
    verdict = "found" if hits else "found otherwise" if violations else "not found"
    first = (hits or violations)[:1]
    shrunk = len(first[0]["minimal"]) if first and first[0]["shrunk"] else None
    return Outcome(name, clauses, verdict, named, shrunk, seconds, code)


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--inputs", type=int, default=3000, help="inputs per campaign (default 3000)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--fault", action="append", default=[], help="only these faults (repeatable)")
    parser.add_argument("--markdown", action="store_true", help="a Markdown table")
    args, extra = parser.parse_known_args()
    faults = list(Fault)
    if args.fault:
        wanted = {Fault.named(name) for name in args.fault}
        faults = [fault for fault in faults if fault in wanted]
    clean = True
    for environment in [(), *sorted({(env,) for envs in WITH.values() for env in envs})]:
        report, seconds, code = campaign(environment, args.inputs, args.seed, extra)
        clean = clean and code == 0 and not report["campaign"]["violations"]
        violations = report["campaign"]["violations"]
        seen = "; ".join(f"{f['kind']} {f['clause'] or ''}" for f in violations) or "none"
        print(f"{' + '.join(environment) or 'no fault'}: exit {code}, violations: {seen}, {seconds:.1f} s")
    outcomes: list[Outcome] = []
    for fault in faults:
        switched = (fault.value, *WITH.get(fault.value, ()))
        report, seconds, code = campaign(switched, args.inputs, args.seed, extra)
        outcome = judge(" + ".join(switched), fault.clauses, report, seconds, code)
        outcomes.append(outcome)
        if not args.markdown:
            shrunk = f", shrunk to {outcome.shrunk_to} input(s)" if outcome.shrunk_to else ""
            kinds = ", ".join(outcome.found)
            print(f"{outcome.name}: {outcome.verdict}{shrunk} ({seconds:.1f} s) [{kinds}]", flush=True)
    if args.markdown:
        print("| fault | clauses it breaks | campaign | violations (kind clause) | first shrunk to |")
        print("|---|---|---|---|---|")
        for o in outcomes:
            shrunk = str(o.shrunk_to) if o.shrunk_to else "-"
            kinds = "; ".join(o.found) or "-"
            print(f"| {o.name} | {', '.join(o.clauses)} | {o.verdict} | {kinds} | {shrunk} |")
    hits = sum(o.verdict == "found" for o in outcomes)
    other = sum(o.verdict == "found otherwise" for o in outcomes)
    print(
        f"{hits} of {len(outcomes)} protocol faults found on their clauses, {other} found otherwise, "
        f"{len(outcomes) - hits - other} not found ({args.inputs} inputs each, seed {args.seed})"
    )
    return 0 if clean and all(o.exit_code in (0, 1) for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
