"""The client judge's harness handling is bounded in time: a harness that floods its stdout, stays
silent, never says hello (at the start or when started again), exits mid-case or writes an endless line
fails its case, is started again for the next one, and the run ends with a verdict.  Every harness here
runs under ``sh`` with children of its own, so a kill that missed them would leave the pipes open (the
hang these tests guard against)."""

from __future__ import annotations

import asyncio
import json
import os
import sys
import time
from pathlib import Path

import pytest

from manip.conformance.client.cli import client_cases
from manip.conformance.client.process import LINE_LIMIT, Limits
from manip.conformance.client.runner import ClientRunConfig, run_client_suite
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.results import ExitCode, RunReport
from manip.conformance.suite.selection import PatternSet

pytestmark = pytest.mark.waits

HELLO = json.dumps(
    {
        "type": "hello",
        "contract": 1,
        "name": "hostile",
        "version": "0",
        "links": ["tcp"],
        "operations": ["connect", "close", "here", "joint-angles"],
    }
)
CASES = ("client.reply.here", "client.reply.joint-angles")
LIMITS = Limits(hello=1.0, exit_grace=0.5, kill_wait=2.0, write=1.0)
BOUND = 30.0
"""Seconds any of these runs may take in all (each is a few seconds; a hang would be endless)."""


def run(argv: list[str], select: tuple[str, ...] = CASES) -> tuple[RunReport, float]:
    config = ClientRunConfig(
        argv=argv,
        link="tcp",
        seed=7,
        options=RunOptions(reply_timeout=0.5),
        select=PatternSet.of(select, "--select"),
        slack=0.5,
        limits=LIMITS,
    )
    t0 = time.monotonic()
    report = asyncio.run(asyncio.wait_for(run_client_suite(config, client_cases()), BOUND))
    return report, time.monotonic() - t0


def shell(tmp_path: Path, body: str) -> list[str]:
    """``sh -c`` running ``body`` after recording its process group in ``pgid``."""
    return ["sh", "-c", f"echo $$ > {tmp_path}/pgid; {body}"]


def hello_then(tmp_path: Path, body: str) -> list[str]:
    """A harness that says hello, reads one case, then runs ``body``."""
    return shell(tmp_path, f"echo '{HELLO}'; read case; {body}")


def assert_group_gone(tmp_path: Path) -> None:
    """Nothing of the harness's process group is left (its children were killed with it)."""
    pgid = int((tmp_path / "pgid").read_text())
    for _ in range(50):
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    pytest.fail(f"process group {pgid} of the harness is still alive")


def problems(report: RunReport) -> list[tuple[str, str, str]]:
    return [
        (r.id, r.outcome, r.failure.message if r.failure is not None else r.reason) for r in report.results
    ]


def test_a_flood_of_garbage_after_hello_fails_the_case_and_the_harness_is_restarted(tmp_path: Path) -> None:
    report, took = run(hello_then(tmp_path, "yes garbage; echo never"))
    got = problems(report)
    assert [o for _, o, _ in got] == ["fail", "fail"], got
    assert all("garbage" in m for _, _, m in got), got
    assert report.exit_code == ExitCode.NON_CONFORMANT and took < BOUND
    assert_group_gone(tmp_path)


def test_a_flood_instead_of_hello_makes_the_harness_unreachable(tmp_path: Path) -> None:
    report, _ = run(shell(tmp_path, "yes garbage; echo never"))
    assert report.exit_code == ExitCode.UNREACHABLE
    assert "bad hello line" in report.problems[0]
    assert_group_gone(tmp_path)


def test_a_harness_silent_in_a_case_fails_it_at_its_deadline_and_is_restarted(tmp_path: Path) -> None:
    report, _ = run(hello_then(tmp_path, "sleep 1000; echo never"))
    got = problems(report)
    assert [o for _, o, _ in got] == ["fail", "fail"], got
    assert all("hung" in m for _, _, m in got), got
    assert report.exit_code == ExitCode.NON_CONFORMANT
    assert_group_gone(tmp_path)


def test_a_harness_that_never_says_hello_is_unreachable_within_the_hello_limit(tmp_path: Path) -> None:
    report, took = run(shell(tmp_path, "sleep 1000; echo never"))
    assert report.exit_code == ExitCode.UNREACHABLE
    assert "no hello line within 1 s" in report.problems[0]
    assert took < LIMITS.hello + LIMITS.kill_wait + 5
    assert_group_gone(tmp_path)


def test_a_restart_without_hello_fails_that_case_and_ends_the_run_with_a_verdict(tmp_path: Path) -> None:
    marker = tmp_path / "started"
    again = f"if [ -e {marker} ]; then sleep 1000; echo never; fi"
    body = f"{again}; touch {marker}; echo '{HELLO}'; read case; exit 3"
    select = (*CASES, "client.reply.read-forces")
    report, _ = run(shell(tmp_path, body), select=select)
    got = problems(report)
    outcomes = [o for _, o, _ in got]
    assert outcomes[:2] == ["fail", "fail"] and set(outcomes[2:]) <= {"skip", "unsupported"}, got
    assert "crashed" in got[0][2] and "no-hello" in got[1][2] and "no hello line" in got[1][2], got
    assert any("could not be started again" in p for p in report.problems)
    assert report.exit_code == ExitCode.NON_CONFORMANT
    assert_group_gone(tmp_path)


def test_a_harness_exiting_mid_case_fails_it_and_is_restarted(tmp_path: Path) -> None:
    script = tmp_path / "exits.py"
    script.write_text(
        "import json, sys\n"
        f"print({HELLO!r}, flush=True)\n"
        "case = json.loads(sys.stdin.readline())['case']\n"
        "print(json.dumps({'type': 'state', 'case': case, 'op': 0, 'state': 'connected'}), flush=True)\n"
        "sys.exit(5)\n"
    )
    report, _ = run([sys.executable, str(script)])
    got = problems(report)
    assert [o for _, o, _ in got] == ["fail", "fail"], got
    assert all("crashed" in m and "status 5" in m for _, _, m in got), got


def test_a_line_past_the_limit_is_a_harness_error_not_unbounded_memory(tmp_path: Path) -> None:
    script = tmp_path / "long.py"
    script.write_text(
        "import sys\n"
        f"print({HELLO!r}, flush=True)\n"
        "sys.stdin.readline()\n"
        f"sys.stdout.write('x' * {LINE_LIMIT * 3}); sys.stdout.flush()\n"
        "sys.stdin.readline()\n"
    )
    report, _ = run([sys.executable, str(script)])
    got = problems(report)
    assert [o for _, o, _ in got] == ["fail", "fail"], got
    assert all(f"longer than {LINE_LIMIT} bytes" in m for _, _, m in got), got
