"""What every manip command shares: ``--version`` and the log format (:mod:`manip.commandline`)."""

from __future__ import annotations

import importlib
import importlib.metadata
import logging
import re
import tomllib
from datetime import datetime
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

import manip
from manip.commandline import configure_logging

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS: dict[str, str] = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
ISO_MS = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d"


def _command(target: str) -> click.Command:
    module, _, name = target.partition(":")
    command = getattr(importlib.import_module(module), name)
    assert isinstance(command, click.Command)
    return command


def test_there_are_commands_to_check() -> None:
    assert {"manip-client", "manip-server", "manip-cougar", "manip-conform"} <= set(SCRIPTS)


@pytest.mark.parametrize("prog", sorted(SCRIPTS))
def test_every_command_says_its_version_the_same_way(prog: str) -> None:
    result = CliRunner().invoke(_command(SCRIPTS[prog]), ["--version"])
    assert result.exit_code == 0, result.output
    assert result.output == f"{prog}, version {importlib.metadata.version('manip')}\n"


def test_the_package_version_is_the_installed_one() -> None:
    assert manip.__version__ == importlib.metadata.version("manip")


def test_log_lines_have_a_local_iso_time_to_the_millisecond(capsys: pytest.CaptureFixture[str]) -> None:
    root = logging.getLogger()
    level = root.level
    try:
        configure_logging("info")
        configure_logging("INFO")  # again: still one line a record
        logging.getLogger("manip.test").info("request %s", "0201")
        logging.getLogger("manip.test").debug("not shown")
    finally:
        configure_logging(logging.WARNING)
        root.setLevel(level)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    match = re.fullmatch(rf"({ISO_MS}) INFO manip\.test: request 0201", lines[0])
    assert match, lines[0]
    when = datetime.fromisoformat(match[1])
    assert abs((when - datetime.now().astimezone()).total_seconds()) < 60
