"""Every command holds to the one exit-status table (``manip.exit_status``): the README shows it, each
command's ``--help`` ends with its row, and each command exits with the statuses it says for the
situations the table names (run in-process, so a wrong status fails here before a user sees it)."""

from __future__ import annotations

import re
import socket
from collections.abc import Iterator
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from manip.captures.cli import main as capture_main
from manip.conformance.cli import main as conform_main
from manip.cougar.cli import main as cougar_main
from manip.decode.cli import main as decode_main
from manip.exit_status import EXIT_STATUSES, epilog, markdown_table
from manip.reference_client.cli import main as client_main
from manip.reference_server.cli import main as server_main
from tests.support.paths import ROOT

GOLDEN = ROOT / "captures" / "motion.mcap"
ERRORS = ROOT / "captures" / "errors.mcap"
"""A golden capture with a deliberately malformed request in it (manip-decode reads it as one)."""

COMMANDS: dict[str, tuple[click.Command, list[str]]] = {
    "manip-conform run": (conform_main, ["run"]),
    "manip-conform verify, replay": (conform_main, ["verify"]),
    "manip-conform client": (conform_main, ["client"]),
    "manip-conform fuzz": (conform_main, ["fuzz"]),
    "manip-conform diff": (conform_main, ["diff"]),
    "manip-conform coverage": (conform_main, ["coverage"]),
    "manip-conform cases, report": (conform_main, ["report"]),
    "manip-client": (client_main, []),
    "manip-server": (server_main, []),
    "manip-cougar": (cougar_main, []),
    "manip-capture": (capture_main, []),
    "manip-decode": (decode_main, []),
}
"""Each row of the table: the command object and the words before ``--help``."""


def _invoke(command: click.Command, args: list[str]) -> tuple[int, str]:
    result = CliRunner().invoke(command, args, catch_exceptions=False)
    return result.exit_code, result.output


def test_the_readme_shows_the_table() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = r"<!-- exit-status table[^\n]*-->\n(.*?)\n<!-- end of the exit-status table -->"
    found = re.search(table, readme, re.S)
    assert found, "the README has no exit-status table"
    assert found.group(1) == markdown_table(), "the README's table differs from manip.exit_status"


def test_the_table_covers_every_command() -> None:
    assert set(COMMANDS) == set(EXIT_STATUSES)
    scripts = re.findall(r"^(manip-[a-z]+) = ", (ROOT / "pyproject.toml").read_text(), re.M)
    assert {row.split()[0] for row in EXIT_STATUSES} == set(scripts)


@pytest.mark.parametrize("row", sorted(COMMANDS))
def test_each_help_ends_with_its_row(row: str) -> None:
    command, words = COMMANDS[row]
    code, output = _invoke(command, [*words, "--help"])
    assert code == 0
    for number, meaning in EXIT_STATUSES[row]:
        line = next((x for x in output.splitlines() if x.strip().startswith(f"{number} ")), None)
        assert line is not None and meaning in " ".join(line.split()), (row, number, output[-800:])
    assert "Exit status:" in output and epilog(row).startswith("\b\nExit status:")


@pytest.mark.parametrize("row", sorted(COMMANDS))
def test_a_bad_option_is_a_usage_error(row: str) -> None:
    command, words = COMMANDS[row]
    code, output = _invoke(command, [*words, "--no-such-option"])
    assert code == 2 and 2 in dict(EXIT_STATUSES[row]), output


@pytest.mark.parametrize(
    ("row", "command", "args"),
    [
        ("manip-decode", decode_main, ["--mcap", "MISSING"]),
        ("manip-capture", capture_main, ["export", "MISSING", "-o", "out.pcapng"]),
        ("manip-capture", capture_main, ["import", "MISSING", "-o", "out.mcap"]),
        ("manip-capture", capture_main, ["info", "MISSING"]),
        ("manip-capture", capture_main, ["recover", "MISSING"]),
        ("manip-conform verify, replay", conform_main, ["verify", "MISSING"]),
        ("manip-conform verify, replay", conform_main, ["replay", "MISSING"]),
        ("manip-conform cases, report", conform_main, ["report", "MISSING", "--html", "out.html"]),
    ],
)
def test_a_missing_input_file_is_a_usage_error(
    row: str, command: click.Command, args: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The same mistake gets the same status from every command (manip-capture export once said 1)."""
    monkeypatch.chdir(tmp_path)
    code, output = _invoke(command, args)
    assert code == 2, output
    assert "MISSING" in output and ("does not exist" in output or "no such file" in output), output
    assert not (tmp_path / "out.pcapng").exists() and not (tmp_path / "out.mcap").exists()


@pytest.fixture
def taken_port() -> Iterator[int]:
    """A loopback port something already listens on."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen()
        yield sock.getsockname()[1]


@pytest.fixture
def closed_port() -> int:
    """A loopback port nothing listens on (bound, then closed)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def test_a_server_that_cannot_listen_exits_1(taken_port: int) -> None:
    for row, command in (("manip-server", server_main), ("manip-cougar", cougar_main)):
        code, output = _invoke(command, ["--listen", f"tcp://127.0.0.1:{taken_port}"])
        assert code == 1 and "cannot listen" in dict(EXIT_STATUSES[row])[1], (row, output)
        assert "Traceback" not in output and "cannot listen" in output, (row, output)


def test_found_something_wrong_is_1(tmp_path: Path) -> None:
    not_a_capture = tmp_path / "text.mcap"
    not_a_capture.write_text("not a capture\n")
    code, output = _invoke(capture_main, ["export", str(not_a_capture), "-o", str(tmp_path / "x.pcapng")])
    assert code == 1 and "Traceback" not in output, output
    code, output = _invoke(decode_main, ["--body", "request", "here", "01 02 03"])
    assert code == 1, output
    code, output = _invoke(decode_main, ["--mcap", str(ERRORS)])
    assert code == 1 and "is not a request opcode of the spec" in output, output[-500:]
    code, output = _invoke(decode_main, ["--mcap", str(GOLDEN), "--filter", "opcode=kill-power"])
    assert code == 1 and "no packet matches --filter" in output, output[-500:]


def test_nothing_wrong_is_0(tmp_path: Path) -> None:
    assert _invoke(capture_main, ["export", str(GOLDEN), "-o", str(tmp_path / "g.pcapng")])[0] == 0
    assert _invoke(decode_main, ["--mcap", str(GOLDEN)])[0] == 0
    assert _invoke(conform_main, ["verify", str(GOLDEN)])[0] == 0
    assert _invoke(conform_main, ["cases"])[0] == 0


def test_an_unreachable_peer_is_3(closed_port: int) -> None:
    code, output = _invoke(client_main, [f"tcp://127.0.0.1:{closed_port}", "here"])
    assert code == 3, output
    code, output = _invoke(
        conform_main, ["run", f"tcp://127.0.0.1:{closed_port}", "--select", "server.reply.here", "-q"]
    )
    assert code == 3, output
