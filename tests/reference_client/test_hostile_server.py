"""A hostile Chaos server against manip-client and the client library: every run ends, with a result or
one clear error, never a traceback, and in bounded memory.  The scenarios are those of
``tools/hostile_campaign.py`` (the long form, run by hand), played by the client judge's scripted server
on a loopback port."""

from __future__ import annotations

import asyncio
import random
import time
from types import ModuleType

import pytest
from click.testing import CliRunner

from manip.conformance.client.server import serve_scenario
from manip.reference_client import ClientOptions, ConnectionLostError, ReplyTooLargeError, aconnect
from manip.reference_client.cli import main as client_main
from tests.support.tools import load_tool

pytestmark = pytest.mark.waits  # real sockets and the client's real close: mostly waiting


def _tool() -> ModuleType:
    return load_tool("hostile_campaign")


HOSTILE = _tool()
SCENARIOS = HOSTILE.scenarios(1)


async def _describe(scenario: str, options: ClientOptions) -> object:
    listener = await serve_scenario("tcp", SCENARIOS[scenario], rng=random.Random(1))
    try:
        async with asyncio.timeout(30), aconnect(listener.address, options) as arm:
            return await arm.describe()
    finally:
        await listener.aclose()


def test_an_endless_describe_self_ends_at_the_reply_limit_even_without_a_timeout() -> None:
    options = ClientOptions(timeout=None, max_reply_bytes=64 * 1024)
    with pytest.raises(ReplyTooLargeError, match="goes past 65536 data bytes") as caught:
        asyncio.run(_describe("endless-describe", options))
    request = caught.value.request
    assert request.responses == [] and 64 * 1024 < request.reply_bytes < 64 * 1024 + 500


def test_a_describe_self_under_the_limit_is_read_whole() -> None:
    options = ClientOptions(timeout=20, max_reply_bytes=5 << 20)  # over the 1 MiB default
    alist = asyncio.run(_describe("huge-describe", options))
    assert isinstance(alist, dict) and alist["name"] == ["y" * (4 << 20)]


@pytest.mark.parametrize("scenario", ["illegal-chaos", "illegal-deaf"])
def test_a_connection_given_up_with_los_is_lost_at_once_not_timed_out(scenario: str) -> None:
    """The server sends illegal packets after the first request (and, deaf, ignores the client's LOS):
    the client answers LOS and reports the connection lost at once, although it was told to wait for
    ever (it used to wait: 'no reply within N s' with a timeout, for ever without)."""
    started = time.monotonic()
    with pytest.raises(ConnectionLostError, match="illegal packet"):
        asyncio.run(_describe(scenario, ClientOptions(timeout=None)))
    assert time.monotonic() - started < 20


def _cli(scenario: str, *args: str) -> tuple[int, str]:
    with HOSTILE.hostile_server(SCENARIOS[scenario]) as server:
        result = CliRunner().invoke(client_main, [server.address, *args, "--timeout", "10"])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output and "background process failed" not in result.output
    return result.exit_code, result.output


@pytest.mark.parametrize("form", [[], ["--json"]])
def test_a_description_nested_500_deep_is_an_error_not_a_recursion(form: list[str]) -> None:
    code, output = _cli("deep-500", "describe", *form)
    assert code == 1 and "nested deeper than 64" in output


def test_the_cli_reply_limit_is_an_option() -> None:
    code, output = _cli("endless-describe", "describe", "--max-reply", "10000")
    assert code == 1 and "goes past 10000 data bytes" in output
    code, output = _cli("endless-describe", "describe", "--json", "--max-reply", "10000")
    assert code == 1 and '"error": "reply-too-large"' in output


def test_raw_data_no_packet_can_hold_is_a_usage_error_before_connecting() -> None:
    result = CliRunner().invoke(client_main, ["tcp://127.0.0.1:9", "raw", "0216", "00" * 600, "--no-check"])
    assert result.exit_code == 2
    assert "600 bytes; a Chaos packet holds at most 488" in result.output
    assert ("background process failed" not in result.output and result.exception is None) or isinstance(
        result.exception, SystemExit
    )


def test_a_short_hostile_campaign_finds_nothing_bad() -> None:
    """Every scenario but the stalls against the library (with and without a timeout) and the CLI's
    describe: no traceback, no hang, and the error each scenario calls for."""
    outcomes = []
    for name, script in SCENARIOS.items():
        if name in ("stall", "huge-packets", "huge-describe"):  # a timeout's length each, or 4 MB
            continue
        for client in ("lib-describe", "lib-describe-no-timeout", "describe"):
            outcomes.append(
                HOSTILE.run_one(name, script, client, 1, processes=False, timeout=20.0, rss_mb=200)
            )
    bad = [o for o in outcomes if o.outcome in HOSTILE.BAD]
    assert not bad, "\n".join(f"{o.outcome} {o.scenario} {o.client}: {o.detail}" for o in bad)
    assert {o.outcome for o in outcomes} >= {"ok", "error"}
