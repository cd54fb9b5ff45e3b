"""The long fuzz campaign: a million inputs against the reference server, its memory and descriptors
sampled on the way, the figures printed at the end.

It runs ``manip-conform fuzz`` (which starts the reference server itself) with ``--json`` and samples
the server process, the fuzzer's child, every ``--interval`` seconds: resident memory (VmRSS) and open
descriptors.  The campaign passes with no violation at all: no crash, hang, traceback, silent drop,
wrong answer or uncounted drop.

    .venv/bin/python tools/fuzz_long.py > fuzz-long.txt                # 1,000,000 inputs, seed 1985
    .venv/bin/python tools/fuzz_long.py --inputs 200000 --seed 7 -- --link chudp

Options after ``--`` go to ``manip-conform fuzz``.  Exit status: the campaign's (0: no violation).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def children(pid: int) -> list[int]:
    out: list[int] = []
    with_tasks = Path(f"/proc/{pid}/task")
    for task in with_tasks.iterdir() if with_tasks.exists() else ():
        try:
            out += [int(x) for x in (task / "children").read_text().split()]
        except OSError:
            continue
    return out


def sample(pid: int) -> tuple[int, int] | None:
    """(resident kB, open descriptors) of ``pid``, or None once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        rss = next(int(line.split()[1]) for line in status.splitlines() if line.startswith("VmRSS:"))
        return rss, len(os.listdir(f"/proc/{pid}/fd"))
    except (OSError, StopIteration):
        return None


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--inputs", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=1985)
    parser.add_argument("--batch", type=int, default=200)
    parser.add_argument("--interval", type=float, default=30.0, help="seconds between samples (default 30)")
    argv = sys.argv[1:]
    extra: list[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, extra = argv[:cut], argv[cut + 1 :]
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        report_path = Path(tmp) / "fuzz.json"
        cmd = [sys.executable, "-m", "manip.conformance.cli", "fuzz", "-q", "--inputs", str(args.inputs)]
        cmd += ["--seed", str(args.seed), "--batch", str(args.batch), "--json", str(report_path), *extra]
        print(" ".join(cmd[2:]), flush=True)
        started = time.monotonic()
        fuzzer = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
        samples: list[tuple[float, int, int]] = []
        server: int | None = None
        while fuzzer.poll() is None:
            time.sleep(args.interval if server else 1.0)
            found = children(fuzzer.pid)
            server = found[0] if found else None
            taken = sample(server) if server else None
            if taken is not None:
                samples.append((time.monotonic() - started, *taken))
                at, kb, held = samples[-1]
                print(f"{at:8.0f} s  server rss {kb / 1024:7.1f} MB  fds {held:4d}", flush=True)
        output = fuzzer.stdout.read() if fuzzer.stdout is not None else ""
        print(output, end="")
        if not report_path.exists():
            print(f"no report (exit {fuzzer.returncode})")
            return fuzzer.returncode or 4
        whole = json.loads(report_path.read_text())
    report = {**whole, **whole["campaign"]}  # the campaign's facts, beside the report's duration and exit
    checks = report["liveness"]["checks"]
    passed = checks - report["liveness"]["failed"]
    print(
        f"campaign: {report['inputs']} inputs, {report['requests']} requests, {report['batches']} batches in "
        f"{report['duration']:.0f} s ({report['rate']:.0f} inputs/s); liveness checks {passed} of {checks} "
        f"passed; restarts {report['restarts']}"
    )
    print(f"violations by kind: {report['counts']}; warnings {report['warnings']}")
    print(
        f"tracebacks in the server's log: {report['tracebacks_seen']}; bad frames sent {report['bad_frames']}"
    )
    if samples:
        rss = [s[1] / 1024 for s in samples]
        fds = [s[2] for s in samples]
        print(
            f"server rss MB: first {rss[0]:.1f}, min {min(rss):.1f}, max {max(rss):.1f}, last {rss[-1]:.1f}; "
            f"fds: first {fds[0]}, min {min(fds)}, max {max(fds)}, last {fds[-1]} ({len(samples)} samples)"
        )
    for v in report["violations"]:
        print(f"violation: {v['kind']} {v['clause']}: {v['message']} -> {v['reproduce']}")
    return int(report["exit_code"])


if __name__ == "__main__":
    sys.exit(main())
