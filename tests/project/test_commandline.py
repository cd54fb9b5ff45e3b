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
from manip.commandline import LogFormatter, configure_logging
from tests.support.paths import ROOT

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


# ------------------------------------------------------------------------------------ octal notation

PYTHON_OCTAL = re.compile(r"0o[0-7]")
HEX_INDEX = re.compile(r"index 0x", re.IGNORECASE)


def _decoder_output() -> str:
    from manip.codecs import Packet, encode_chudp, encode_tcp
    from manip.decode.cli import main as decode

    rfc = Packet(0o1, 0o440, 0, 0o401, 0x0A01, 1, 0, b"PUMA")
    unknown = Packet(0o277, 0o440, 0x5E02, 0o401, 0x0A01, 7, 3, b"")
    out = []
    for args in (
        [encode_chudp(rfc).hex()],
        ["--direction", "request", encode_chudp(unknown).hex()],
        ["--link", "tcp", "--format", "hexdump", encode_tcp(unknown).hex()],
        ["--link", "tcp", "--format", "json", encode_tcp(rfc).hex()],
    ):
        result = CliRunner().invoke(decode, args)
        out.append(result.output)
    return "\n".join(out)


def _client_and_server_output(caplog: pytest.LogCaptureFixture) -> str:
    from manip.reference_client.cli import main as client
    from manip.reference_server import ServerConfig
    from tests.support.servers import in_thread, reference_server

    caplog.set_level(logging.INFO, logger="manip")
    out = []
    with in_thread(reference_server(ServerConfig())) as url:
        for args in (["describe"], ["joints"], ["speed", "5"], ["describe", "--json"]):
            out.append(CliRunner().invoke(client, [url, *args]).output)
    formatter = LogFormatter()
    out += [formatter.format(record) for record in caplog.records]
    return "\n".join(out)


def _conformance_output(tmp_path: Path) -> str:
    from manip.conformance.cli import main as conform

    report = tmp_path / "report.json"
    result = CliRunner().invoke(
        conform,
        ["run", "--seed", "2", "--server-fault", "unknown-opcode-answered",
         "--server-fault", "describe-extra-operation", "--select", "server.negative.unknown-opcodes",
         "--select", "server.describe.operations-served", "--select", "server.ncp.los-unknown-connection",
         "--json", str(report)],
    )  # fmt: skip
    assert result.exit_code == 1, result.output  # failures, so their messages are read too
    return result.output + report.read_text()


def test_what_people_read_writes_octal_one_way(caplog: pytest.LogCaptureFixture, tmp_path: Path) -> None:
    """Decoder, client, server log and a failing conformance run: octal as 0277, never 0o277, and Chaos
    indexes in octal like the addresses beside them."""
    texts = {
        "manip-decode": _decoder_output(),
        "manip-client and the server's log": _client_and_server_output(caplog),
        "manip-conform run": _conformance_output(tmp_path),
    }
    for where, text in texts.items():
        assert "0277" in text or "0201" in text or "0200" in text, f"{where} shows no opcode: {text[:400]}"
        assert not PYTHON_OCTAL.search(text), f"{where}: {text[max(0, text.find('0o') - 80) :][:200]}"
        assert not HEX_INDEX.search(text), where
