"""``manip-client`` by opcode: ``raw``, the wrist commands made from the spec, ``--no-check``, errors as
JSON, and what ``watch`` says it waits for; against the reference server with a simulated Cougar."""

from __future__ import annotations

import functools
import json
from collections.abc import AsyncIterator, Iterator
from contextlib import asynccontextmanager
from typing import Any

import pytest
from click.testing import CliRunner, Result

from manip.codecs.pdp11float import pack_f
from manip.reference_client.cli import EXIT_SERVER_ERROR, EXIT_USAGE, main
from manip.reference_client.cli_requests import WRIST_OPCODES
from manip.reference_server import ServerConfig
from manip.reference_server.cougar_wrist import make_cougar_wrist
from manip.reference_server.driver import serve
from manip.spec import SPEC
from manip.spec.notation import octal
from tests.support.servers import in_thread


@asynccontextmanager
async def _wrist_server() -> AsyncIterator[str]:
    wrist = functools.partial(make_cougar_wrist, "sim", seed=7)
    async with serve("tcp://127.0.0.1:0", ServerConfig(powered_at_open=True), wrist_factory=wrist) as server:
        yield server.address


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    with in_thread(_wrist_server()) as address:
        yield address


def invoke(*args: str) -> Result:
    return CliRunner().invoke(main, list(args), catch_exceptions=False)


def ok_json(*args: str) -> dict[str, Any]:
    result = invoke(*args, "--json")
    assert result.exit_code == 0, result.output
    value = json.loads(result.stdout)
    assert isinstance(value, dict)
    return value


def json_failure(code: int, *args: str) -> dict[str, Any]:
    """The one JSON object a failure writes on stdout with --json (nothing on stderr)."""
    result = invoke(*args, "--json")
    assert result.exit_code == code, result.output
    assert result.stderr == ""
    [line] = result.stdout.splitlines()
    value = json.loads(line)
    assert isinstance(value, dict)
    assert {"where", "severity", "code", "message", "args"} <= set(value) and value["exit"] == code
    return value


# ------------------------------------------------------------------ raw


def test_raw_sends_any_opcode_and_shows_the_reply_decoded(url: str) -> None:
    here = ok_json(url, "raw", "0201")
    assert here["opcode"] == "0201" and here["name"] == "here" and len(here["values"]["transform"]) == 12
    assert len(bytes.fromhex(here["data"])) == 48
    text = invoke(url, "raw", "201").stdout  # the leading 0 is optional
    assert text.startswith("0201 here: reply to request") and "transform:" in text and "data: " in text
    speed = ok_json(url, "raw", "0216", pack_f(0.5).hex(" "))  # data in wire order, spaces allowed
    assert speed["name"] == "set-speed" and speed["data"] == "" and speed["problem"] is None


def test_raw_an_unknown_opcode_gets_the_servers_refusal(url: str) -> None:
    error = json_failure(EXIT_SERVER_ERROR, url, "raw", "0277")
    assert (error["severity"], error["code"], error["where"]) == ("C", "UOP", "dispatch")
    assert error["args"] == [0o277] and error["error"] == "non-fatal-error"


def test_raw_refuses_malformed_data_unless_no_check(url: str) -> None:
    refused = invoke(url, "raw", "0216", "00")
    assert refused.exit_code == EXIT_USAGE
    assert "set-speed" in refused.stderr and "--no-check" in refused.stderr
    assert json_failure(EXIT_USAGE, url, "raw", "0216", "00")["error"] == "usage"
    sent = json_failure(EXIT_SERVER_ERROR, url, "raw", "0216", "00", "--no-check")  # reaches the server
    assert (sent["code"], sent["args"]) == ("BDL", [4, 1])
    assert invoke(url, "raw", "0300").exit_code == EXIT_USAGE  # not a request opcode
    assert "0o" not in invoke(url, "raw", "0300").stderr
    assert json_failure(EXIT_SERVER_ERROR, url, "raw", "0300", "--no-check")["code"] == "UOP"
    assert invoke(url, "raw", "0201", "zz").exit_code == EXIT_USAGE


# ------------------------------------------------------------------ wrist commands


def test_every_wrist_opcode_is_a_command_with_help_from_the_spec() -> None:
    assert [op.opcode for op in WRIST_OPCODES] == list(range(0o240, 0o254))
    for op in WRIST_OPCODES:
        result = invoke("tcp://127.0.0.1:1", op.name, "--help")
        assert result.exit_code == 0, result.output
        text = " ".join(result.output.split())
        assert f"{op.title} ({octal(op.opcode)})" in text and op.section in text
        for field in op.request.fields:
            assert field.name.upper() in text


def test_wrist_commands_against_the_simulated_cougar(url: str) -> None:
    forces = ok_json(url, "read-forces")
    assert forces["name"] == "read-forces" and len(forces["values"]["forces"]) == 6
    gauges = ok_json(url, "read-raw-gauges")["values"]["gauges"]
    assert len(gauges) == 8 and all(isinstance(g, int) for g in gauges)
    assert ok_json(url, "set-spring", "1", "2", "3", "4", "5", "6")["problem"] is None
    assert ok_json(url, "set-weight", "2.5", "0", "0", "10")["name"] == "set-weight"
    assert ok_json(url, "set-guard", "0100003", "0", "0", "1", "0", "0", "0", "8")["data"] == ""
    assert ok_json(url, "clear-guard", "3")["name"] == "clear-guard"
    moved = ok_json(url, "compliant-move", "0", "-90", "90", "0", "0", "0", "0")
    assert isinstance(moved["values"]["segment"], int)


def test_wrist_arguments_are_checked_unless_no_check(url: str) -> None:
    short = invoke(url, "set-spring", "1", "2", "3")
    assert short.exit_code == EXIT_USAGE and "takes 6 value(s)" in short.stderr
    sent = json_failure(EXIT_SERVER_ERROR, url, "set-spring", "1", "2", "3", "--no-check")
    assert (sent["code"], sent["args"]) == ("BDL", [24, 12])
    assert invoke(url, "clear-guard", "70000").exit_code == EXIT_USAGE  # not a word
    wrapped = json_failure(EXIT_SERVER_ERROR, url, "clear-guard", "99", "--no-check")
    assert (wrapped["where"], wrapped["code"]) == ("clear-guard", "BVA")
    assert invoke(url, "set-weight", "heavy", "0", "0", "0").exit_code == EXIT_USAGE


def test_a_server_error_is_one_json_object_with_its_parts(url: str) -> None:
    spec = SPEC.error_codes["BVA"]
    error = json_failure(EXIT_SERVER_ERROR, url, "clear-guard", "16", "--no-check")
    assert error["meaning"] == spec.meaning and error["severity"] == "C" and "16" in error["message"]
    text = invoke(url, "clear-guard", "16", "--no-check")
    assert text.stdout == "" and text.stderr.startswith("manip-client: BVA: ")


# ------------------------------------------------------------------ watch


def test_watch_says_what_it_waits_for(url: str) -> None:
    result = invoke(url, "watch", "--seconds", "0.2", "--count", "3")
    assert result.exit_code == 0, result.output
    said = result.stderr.strip()
    assert said.startswith("manip-client: waiting for segment completions and guard hits")
    assert url in said and "3 responses" in said and "0.2 s" in said
    quiet = invoke(url, "watch", "--seconds", "0.1", "--no-guards")
    assert "guard hits" not in quiet.stderr and "Ctrl-C or 0.1 s" in quiet.stderr
