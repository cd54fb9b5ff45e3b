"""Run the property tests under the long, randomized Hypothesis profile to find new counterexamples.

The test suite's own runs are derandomized (the same examples every time, see tests/conftest.py); this
run draws fresh random examples, at least ``--examples`` per property test, from a seed it prints.  Each
failure is printed as the ``@example(...)`` line to pin on the test after fixing the defect, so that the
ordinary test run checks it from then on.  Exit status: 0 when nothing failed, else pytest's.

    .venv/bin/python tools/hypothesis_long.py                      # the numeric cores' property tests
    .venv/bin/python tools/hypothesis_long.py --examples 5000 tests/arm/test_kinematics.py
    .venv/bin/python tools/hypothesis_long.py --seed 123 -- -k nearest   # after --: more pytest options
"""

from __future__ import annotations

import argparse
import os
import re
import secrets
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The property tests of the pure numeric code: quick per example, so many examples fit in minutes.
DEFAULT_TESTS = (
    "tests/arm/test_kinematics.py",
    "tests/arm/test_trajectory.py",
    "tests/arm/test_transform.py",
    "tests/codecs/test_pdp11float.py",
)
# Hypothesis's note on a failure: "Failing test case: name(\n    arg=value,\n)" (older versions say
# "Falsifying example"); "explicit" when an @example already pinned fails.
_NOTE = re.compile(r"^(?:Failing|Falsifying) (explicit )?(?:test case|example): (\w+)\((.*)\)\s*$", re.S)


@dataclass
class Counterexample:
    nodeid: str
    explicit: bool
    arguments: str
    """The call's arguments as Hypothesis prints them (keyword form, one per line when long)."""

    def decorator(self) -> str:
        return f"@example({self.arguments})"


@dataclass
class Collector:
    """A pytest plugin that keeps the failing examples Hypothesis notes on each failed test."""

    found: list[Counterexample] = field(default_factory=list)
    failed_without_example: list[str] = field(default_factory=list)

    @pytest.hookimpl(wrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
        report = yield
        if call.when == "call" and call.excinfo is not None:
            before = len(self.found)
            for error in _leaves(call.excinfo.value):
                for note in getattr(error, "__notes__", ()):
                    match = _NOTE.match(str(note))
                    if match:
                        self.found.append(Counterexample(item.nodeid, bool(match[1]), match[3]))
            if len(self.found) == before:
                self.failed_without_example.append(item.nodeid)
        return report


def _leaves(error: BaseException) -> list[BaseException]:
    """The exceptions of a (nested) exception group, or the exception itself."""
    if isinstance(error, BaseExceptionGroup):
        return [leaf for sub in error.exceptions for leaf in _leaves(sub)]
    return [error]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="Run property tests under the long randomized Hypothesis profile; print each new "
        "counterexample as an @example(...) line to pin.",
        epilog="Options after -- go to pytest unchanged.",
    )
    parser.add_argument(
        "tests", nargs="*", help=f"test files or node ids (default: {' '.join(DEFAULT_TESTS)})"
    )
    parser.add_argument(
        "--examples", type=int, default=1000, help="at least this many per test (default 1000)"
    )
    parser.add_argument("--seed", type=int, help="Hypothesis seed (default: a random one, printed)")
    parser.add_argument("--timeout", type=float, default=3600.0, help="seconds per test (default 3600)")
    argv = sys.argv[1:] if argv is None else argv
    cut = argv.index("--") if "--" in argv else len(argv)
    args, extra = parser.parse_args(argv[:cut]), argv[cut + 1 :]
    if args.examples < 1:
        parser.error("--examples must be at least 1")
    seed = args.seed if args.seed is not None else secrets.randbits(32)
    tests = args.tests or list(DEFAULT_TESTS)

    os.environ["MANIP_HYPOTHESIS_PROFILE"] = "long"
    os.environ["MANIP_HYPOTHESIS_EXAMPLES"] = str(args.examples)
    pytest_args = ["-q", "-p", "no:cacheprovider", f"--hypothesis-seed={seed}", f"--timeout={args.timeout:g}"]
    pytest_args += [*tests, *extra]
    again = (
        f"MANIP_HYPOTHESIS_PROFILE=long MANIP_HYPOTHESIS_EXAMPLES={args.examples} "
        f"python -m pytest {shlex.join(pytest_args)}"
    )
    print(
        f"long Hypothesis run: seed {seed}, at least {args.examples} examples per property test", flush=True
    )
    os.chdir(ROOT)
    collector = Collector()
    status = int(pytest.main(pytest_args, plugins=[collector]))

    print()
    for ce in collector.found:
        if ce.explicit:
            print(f"{ce.nodeid}: its pinned example fails again:\n{ce.decorator()}\n")
        else:
            print(
                f"{ce.nodeid}: new counterexample; after the fix, pin it on the test with\n{ce.decorator()}\n"
            )
    for nodeid in collector.failed_without_example:
        print(f"{nodeid}: failed without a Hypothesis example (see its report above)\n")
    if status == 0:
        print(f"no counterexample found (seed {seed})")
    else:
        print(f"repeat this run with:\n  {again}")
    return status


if __name__ == "__main__":
    sys.exit(main())
