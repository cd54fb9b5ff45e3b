"""The one rule for tests that need a real program (``tests/support/programs.py``): absent, the test is
skipped and the run ends with one line naming what was not checked and how to install it, in one process
and with xdist workers alike, with ``-q`` too; under ``MANIP_REQUIRE_PROGRAMS=1`` (``.ci/run``) the test
fails instead.  ``.ci/run`` installs every such program and sets that variable, and no test looks a
program up another way."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.support.paths import ROOT
from tests.support.programs import PROGRAMS, REQUIRE_VARIABLE, missing_from, need_program, summary_line

INNER_TESTS = """
from tests.support.programs import need_program


def test_in_the_dissector() -> None:
    need_program("tshark")


def test_in_a_browser() -> None:
    need_program("chromium")


def test_in_a_browser_again() -> None:
    need_program("chromium")


def test_needing_nothing() -> None:
    assert True
"""
INNER_CONFTEST = "from tests.conftest import pytest_terminal_summary  # noqa: F401  # the hook under test\n"


def _inner_run(tmp_path: Path, *args: str, require: bool = False) -> subprocess.CompletedProcess[str]:
    """pytest on :data:`INNER_TESTS` with a PATH holding only this Python's own directory, so that none
    of the programs is found on any machine."""
    (tmp_path / "test_inner.py").write_text(INNER_TESTS)
    (tmp_path / "conftest.py").write_text(INNER_CONFTEST)
    env = {k: v for k, v in os.environ.items() if k != REQUIRE_VARIABLE}
    env |= {"PATH": str(Path(sys.executable).parent), "PYTHONPATH": str(ROOT)}
    if require:
        env[REQUIRE_VARIABLE] = "1"
    command = [sys.executable, "-m", "pytest", "-p", "no:randomly", "-p", "no:cacheprovider"]
    command += [*args, str(tmp_path)]
    return subprocess.run(
        command, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120, check=False
    )  # fmt: skip


@pytest.mark.parametrize("workers", ["0", "2"])
def test_absent_programs_skip_and_the_run_ends_with_one_line(tmp_path: Path, workers: str) -> None:
    done = _inner_run(tmp_path, "-q", "-ra", "-n", workers)
    assert done.returncode == 0, done.stdout + done.stderr
    assert re.search(r"\b1 passed, 3 skipped\b", done.stdout), done.stdout
    lines = [line for line in done.stdout.splitlines() if line.startswith("not checked:")]
    assert len(lines) == 1, done.stdout
    (line,) = lines
    assert done.stdout.splitlines()[-2] == line, done.stdout  # after -ra's list, before the count
    assert "the HTML report in a browser (2 tests, no chromium)" in line, line
    assert "the Wireshark dissector in tshark (1 test, no tshark)" in line, line
    assert "apt-get install chromium tshark" in line and "lua" not in line, line


def test_required_programs_fail_when_absent(tmp_path: Path) -> None:
    done = _inner_run(tmp_path, "-q", "-n", "0", require=True)
    assert done.returncode == 1, done.stdout + done.stderr
    assert re.search(r"\b3 failed, 1 passed\b", done.stdout), done.stdout
    assert f"{REQUIRE_VARIABLE}=1 requires it" in done.stdout and "not checked:" not in done.stdout


def test_a_run_with_every_program_says_nothing() -> None:
    assert summary_line(missing_from(["no IPv6", "no /dev/full"])) is None


def test_a_program_not_listed_is_an_error_of_the_test() -> None:
    with pytest.raises(KeyError, match="PROGRAMS"):
        need_program("no-such-program")


def test_ci_installs_every_program_and_requires_them() -> None:
    ci = (ROOT / ".ci" / "run").read_text()
    assert f"export {REQUIRE_VARIABLE}=1" in ci
    for name, program in PROGRAMS.items():
        assert f"command -v {name} " in ci and f"missing+=({program.package})" in ci, name


def test_no_test_looks_a_program_up_its_own_way() -> None:
    """A real program is found only through need_program: no ``shutil.which`` of one of them, nor the
    variables the browser and dissector tests used to have each of their own."""
    own_ways = re.compile(
        r"which\(\s*\"(" + "|".join(map(re.escape, PROGRAMS)) + r")\"|MANIP_ALLOW_NO_BROWSER|\"CI\"\)"
    )
    found = [
        f"{path.relative_to(ROOT)}: {match.group(0)}"
        for path in sorted((ROOT / "tests").rglob("*.py"))
        if path.name != "programs.py" and path != Path(__file__)
        for match in own_ways.finditer(path.read_text())
    ]
    assert not found, found
