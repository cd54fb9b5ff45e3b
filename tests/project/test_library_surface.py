"""What a library user reaches from ``manip`` itself: the exceptions to catch (loaded lazily, so
``import manip`` stays light), and clause ids checked with close matches wherever a user gives one."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

import manip
from manip.conformance.cli import main as conform
from manip.spec import SPEC, UnknownClauseError

ERRORS = sorted(name for name in manip.__all__ if name[0].isupper() and not name.isupper())  # not the masks


def test_the_exceptions_a_user_catches_are_importable_from_manip() -> None:
    caught = {"ManipError", "NonFatalError", "ConnectionLostError", "RequestTimeout", "DecodeError"}
    assert caught <= set(ERRORS)
    for name in ERRORS:
        value = getattr(manip, name)
        assert isinstance(value, type) and issubclass(value, Exception), name
        assert name in dir(manip)
    from manip import NonFatalError, ServerError
    from manip.reference_client.errors import NonFatalError as Defined

    assert NonFatalError is Defined and issubclass(NonFatalError, ServerError)
    with pytest.raises(AttributeError, match="no attribute 'NoSuchError'"):
        manip.NoSuchError  # noqa: B018


def test_the_notification_masks_are_the_clients() -> None:
    from manip.reference_client import NOTIFY_GUARD_HITS, NOTIFY_SEGMENTS

    assert (manip.NOTIFY_SEGMENTS, manip.NOTIFY_GUARD_HITS) == (NOTIFY_SEGMENTS, NOTIFY_GUARD_HITS) == (2, 1)


def test_import_manip_stays_light() -> None:
    script = (
        "import sys, manip\n"
        "heavy = [m for m in sys.modules if m.startswith('manip.') or m in ('numpy', 'mcap', 'click')]\n"
        "assert not heavy, heavy\n"
        "manip.SpecError\n"
        "assert 'numpy' not in sys.modules and 'manip.reference_client' not in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", script], check=False, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_an_unknown_clause_id_names_close_matches() -> None:
    assert SPEC.clause("here.transform").id == "here.transform"
    with pytest.raises(UnknownClauseError) as caught:
        SPEC.clause("here.transfrom")
    assert caught.value.close[0] == "here.transform"
    message = str(caught.value)
    assert message.startswith("no clause 'here.transfrom' in the spec; close matches: here.transform")
    assert isinstance(caught.value, KeyError)  # code that caught the KeyError of before still does
    with pytest.raises(UnknownClauseError, match=r"docs/spec\.md lists them"):
        SPEC.check_clause_ids(["here.transform", "nothing-like-it-at-all"])


def test_run_clause_selects_the_cases_that_check_it_and_names_close_matches(tmp_path: Path) -> None:
    typo = CliRunner().invoke(conform, ["run", "--clause", "here.transfrom"])
    assert typo.exit_code == 2 and "close matches: here.transform" in typo.output
    report = tmp_path / "r.json"
    result = CliRunner().invoke(
        conform, ["run", "-q", "--seed", "3", "--clause", "here.transform", "--json", str(report)]
    )
    assert result.exit_code == 0, result.output
    ran = json.loads(report.read_text())["cases"]
    assert ran and all("here.transform" in case["clauses"] for case in ran)
