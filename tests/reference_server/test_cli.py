"""`manip-server`: the fault listing, usage errors, and a real process serving one request."""

from __future__ import annotations

import asyncio
import functools
import re

import pytest
from click.testing import CliRunner

from manip.codecs.messages import Reply, decode_server_packet
from manip.links import NcpConfig, open_connection
from manip.reference_server import cli
from manip.reference_server.cli import main
from manip.reference_server.conditions import WorldCondition
from manip.reference_server.faults import Fault
from manip.reference_server.session import ServerConfig
from manip.spec.constants import RequestOp
from tests.support.servers import StartServer

LOG_LINE = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}[+-]\d\d:\d\d (DEBUG|INFO|WARNING|ERROR) manip[.\w]*: "

PORT_LINE = "manip-server: listening on "


def test_list_faults_shows_every_switch_with_kind_and_clauses() -> None:
    result = CliRunner().invoke(main, ["--list-faults"])
    assert result.exit_code == 0, result.output
    out = result.output
    for name, kind, what, clauses in [
        *((c.value, "environment", c.description, c.clauses) for c in WorldCondition),
        *((f.value, f.kind, f.breaks, f.clauses) for f in Fault),
    ]:
        assert f"{name}  [{kind}]" in out
        assert what in out
        assert f"clauses: {', '.join(clauses)}" in out
    assert "obstacle=JOINT:LOWER:UPPER" in out


def test_unknown_fault_is_a_usage_error_listing_the_names() -> None:
    result = CliRunner().invoke(main, ["--fault", "no-such-fault"])
    assert result.exit_code == 2
    assert "no-such-fault" in result.output
    assert all(f.value in result.output for f in Fault)


@pytest.mark.parametrize(
    "args",
    [
        ["--fault", "obstacle=nonsense"],
        ["--fault", "no-jor=3"],
        ["--listen", "ftp://127.0.0.1:1"],
        ["--chudp", "tcp://127.0.0.1:0"],
        ["--time-scale", "0"],
        ["--max-clients", "0"],
    ],
)
def test_bad_arguments_exit_2(args: list[str]) -> None:
    assert CliRunner().invoke(main, args).exit_code == 2


def test_help_documents_the_default_port() -> None:
    result = CliRunner().invoke(main, ["--help"])
    assert result.exit_code == 0
    assert "42085" in result.output


@pytest.mark.parametrize(("args", "extensions"), [([], True), (["--no-extensions"], False)])
def test_no_extensions_configures_a_guide_only_server(
    monkeypatch: pytest.MonkeyPatch, args: list[str], extensions: bool
) -> None:
    configs: list[ServerConfig] = []

    async def run(server: functools.partial[object], *rest: object, **options: object) -> None:
        configs.append(server.args[1])

    monkeypatch.setattr(cli, "_run", run)
    result = CliRunner().invoke(main, ["--listen", "tcp://127.0.0.1:0", *args])
    assert result.exit_code == 0, result.output
    assert [config.extensions for config in configs] == [extensions]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        ([], ServerConfig()),
        (["--profile", "guide"], ServerConfig.guide_profile()),
        (["--profile", "guide", "--length-unit", "mm"], ServerConfig.guide_profile(length_unit="mm")),
        (
            ["--async-layout", "guide", "--length-unit", "cm", "--configuration-bits", "done"],
            ServerConfig(async_layout="guide", length_unit="cm", configuration_bits="done"),
        ),
        (["--profile", "guide", "--error-args", "packed"], ServerConfig.guide_profile(error_args="packed")),
    ],
)
def test_profile_and_single_choices(
    monkeypatch: pytest.MonkeyPatch, args: list[str], expected: ServerConfig
) -> None:
    configs: list[ServerConfig] = []

    async def run(server: functools.partial[object], *rest: object, **options: object) -> None:
        configs.append(server.args[1])

    monkeypatch.setattr(cli, "_run", run)
    result = CliRunner().invoke(main, ["--listen", "tcp://127.0.0.1:0", *args])
    assert result.exit_code == 0, result.output
    assert configs == [expected]


def _tuple(value: object) -> tuple[object, ...]:
    assert isinstance(value, tuple)
    return value


async def _here(url: str) -> tuple[Reply, Reply, int]:
    conn = await open_connection(url, timeout=5.0, options=NcpConfig(first_packet_no=0o500))
    async with conn:
        first = await asyncio.wait_for(conn.receive(), 5.0)
        number = await conn.send(b"", RequestOp.HERE)
        reply = await asyncio.wait_for(conn.receive(), 5.0)
    initial = decode_server_packet(first.opcode, first.data)
    here = decode_server_packet(reply.opcode, reply.data, RequestOp.HERE)
    assert isinstance(initial, Reply) and isinstance(here, Reply)
    return initial, here, number


@pytest.mark.timeout(30)
def test_a_server_process_serves_and_stops_on_sigterm(manip_server: StartServer) -> None:
    # A process on purpose: the command's own start-up lines, log and exit on SIGTERM are under test.
    server = manip_server("--chudp", "chudp://127.0.0.1:0?addr=440")
    line, url = server.line, server.url
    assert line.startswith(PORT_LINE) and line.removeprefix(PORT_LINE).split()[0] == url
    assert url.startswith("tcp://127.0.0.1:") and not url.endswith(":0")
    assert line.rstrip().endswith("(contact PUMA)")
    assert server.proc.stdout is not None
    second = server.proc.stdout.readline()  # one line per address
    assert second.startswith(f"{PORT_LINE}chudp://127.0.0.1:") and ":0?" not in second
    initial, here, number = asyncio.run(asyncio.wait_for(_here(url), 10.0))
    assert initial.request_number == 0o500 and initial.is_empty
    assert here.request_number == number and len(_tuple(here.values["transform"])) == 12
    _, err = server.stop(timeout=10.0)  # exit status 0
    assert "here (0201)" in err  # the request's log line
    for log_line in err.splitlines():  # the common log format: local ISO 8601 time, level, logger
        assert re.match(LOG_LINE, log_line), log_line
