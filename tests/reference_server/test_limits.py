"""`manip-server` under a descriptor flood, its access warning and its stats line.

The soak scenario: the server process runs with the common soft limit of 1,024 descriptors (set in its
``preexec_fn``) and the test opens 1,100 TCP connections to it that never send a byte.  A well-behaved
client must still be served within 2 s, and the server's stderr must hold no traceback and only a few
lines.  The test raises its own soft descriptor limit to its hard limit for the 1,100 sockets, and uses
fewer (but still more than the server's limit allows it to keep) if the hard limit is too low.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import resource
import signal
import socket
import subprocess
import time
from typing import Any

import pytest
from click.testing import CliRunner

from manip.links import AccessList, parse_address
from manip.reference_client import aconnect
from manip.reference_server import cli
from tests.support.servers import StartServer

SERVER_FDS = 1024
FLOOD = 1100
# A process of its own on purpose: the server runs under its own descriptor limit, and the stats line
# answers SIGUSR1 and comes at the exit on SIGTERM.
STATS = re.compile(
    r"^manip-server: stats: links accepted (\d+), refused (.*), idle-closed (.*), over-limit (.*), "
    r"accept errors (\d+), bad frames (.*)$",
    re.M,
)


def _limit_descriptors() -> None:
    resource.setrlimit(resource.RLIMIT_NOFILE, (SERVER_FDS, resource.getrlimit(resource.RLIMIT_NOFILE)[1]))


def _flood_size() -> int:
    """Raise our own soft limit as far as allowed; return how many sockets the flood may open."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = hard if hard == resource.RLIM_INFINITY else min(hard, 65536)
    if soft != target:
        resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
    room = (target if target != resource.RLIM_INFINITY else 65536) - 100  # pytest's own files
    if room < FLOOD:
        if room <= SERVER_FDS:
            pytest.skip(f"this process may open {room} sockets, not more than the server's {SERVER_FDS}")
        return room  # still enough to exhaust the server's descriptors
    return FLOOD


def flood(proc: subprocess.Popen[str], port: int, count: int) -> list[socket.socket]:
    """``count`` TCP connections that never send a byte, opened one by one; returns once the server
    has accepted (or turned away) every one, as its SIGUSR1 stats line says."""
    socks = []
    for _ in range(count):
        with contextlib.suppress(OSError):  # reset at once (turned away): that is fine
            socks.append(socket.create_connection(("127.0.0.1", port), timeout=10.0))
    deadline = time.monotonic() + 30.0
    while True:
        stats = live_stats(proc)
        seen = total(stats["accepted"]) + total(stats["over-limit"]) - over_limit(stats, "displaced")
        if seen >= count or time.monotonic() > deadline:
            return socks
        time.sleep(0.2)


def live_stats(proc: subprocess.Popen[str]) -> dict[str, str]:
    assert proc.stdout is not None
    proc.send_signal(signal.SIGUSR1)
    return parse_stats(proc.stdout.readline())


def over_limit(stats: dict[str, str], kind: str) -> int:
    match = re.search(rf"{kind} (\d+)", stats["over-limit"])
    return int(match.group(1)) if match else 0


async def served_here(url: str) -> float:
    """Connect with the reference client, ask HERE, return the seconds it took."""
    started = time.monotonic()
    async with aconnect(url) as arm:
        transform = await arm.here()
    assert transform is not None
    return time.monotonic() - started


def parse_stats(out: str) -> dict[str, str]:
    match = STATS.search(out)
    assert match is not None, out
    keys = ("accepted", "refused", "idle-closed", "over-limit", "accept errors", "bad frames")
    return dict(zip(keys, match.groups(), strict=True))


def total(field: str) -> int:
    return int(field.split(maxsplit=1)[0])


# ------------------------------------------------------------------------------ the soak scenario


def served_through_a_flood(manip_server: StartServer, *args: str) -> tuple[str, str, int]:
    """Start the server under the descriptor limit, flood it, and a client must still be served within
    2 s; returns what the server wrote to stdout and stderr when stopped, and the flood's size."""
    count = _flood_size()
    server = manip_server(*args, limit=_limit_descriptors)
    socks = flood(server.proc, int(server.url.rsplit(":", 1)[1]), count)
    try:
        took = asyncio.run(asyncio.wait_for(served_here(server.url), 10.0))
        assert took < 2.0, f"served after {took:.2f} s"
    finally:
        for sock in socks:
            sock.close()
    out, err = server.stop()
    return out, err, count


@pytest.mark.waits
@pytest.mark.timeout(90)
def test_idle_sockets_beyond_the_descriptor_limit_do_not_lock_a_client_out(manip_server: StartServer) -> None:
    out, err, count = served_through_a_flood(manip_server, "--stats")
    assert "Traceback" not in err and "Errno 24" not in err
    assert len(err.splitlines()) < 40, err  # rate limited: no line per socket
    stats = parse_stats(out)
    assert total(stats["accepted"]) >= count + 1  # every one was let in, the oldest idle made room
    assert over_limit(stats, "displaced") >= count - 256 and not over_limit(stats, "refused")
    assert "more idle TCP links displaced over the link limit" in err


@pytest.mark.waits
@pytest.mark.timeout(90)
def test_out_of_descriptors_the_server_backs_off_without_tracebacks(manip_server: StartServer) -> None:
    args = ("--stats", "--max-links", "0", "--accept-backoff", "0.2")  # no limit but the descriptors
    out, err, _ = served_through_a_flood(manip_server, *args)
    assert "Traceback" not in err
    failures = [line for line in err.splitlines() if "accepting a TCP connection failed" in line]
    assert 1 <= len(failures) <= 2, err  # at most once per 10 s interval (the test takes a few)
    assert "Too many open files" in failures[0]
    assert re.search(r"out of file descriptors with \d+ links open: at most \d+ from now on", err)
    assert len(err.splitlines()) < 40, err
    stats = parse_stats(out)
    assert int(stats["accept errors"]) >= 1
    assert total(stats["over-limit"]) >= 1  # room was made by displacing idle links


# ------------------------------------------------------------------------------ stats and signals


def _rfc_frame(me: int) -> bytes:
    from manip.codecs.framing import encode_tcp
    from manip.codecs.packet import Packet
    from manip.spec.constants import ChaosOp

    return encode_tcp(Packet(ChaosOp.RFC, 0o440, 0, me, 0x1234, 1, 0, b"PUMA"), hw_dest=0o440, hw_src=me)


@pytest.mark.timeout(60)
def test_stats_line_on_sigusr1_and_at_exit_counts_every_refusal_and_close(manip_server: StartServer) -> None:
    server = manip_server(
        "--stats", "--frame-timeout", "0.3", "--allow", "127.0.0.0/8", "--allow", "chaos:0401"
    )
    proc, url = server.proc, server.url
    port = int(url.rsplit(":", 1)[1])
    silent = socket.create_connection(("127.0.0.1", port))
    stranger = socket.create_connection(("127.0.0.1", port))
    stranger.sendall(_rfc_frame(0o402))  # refused by its Chaos address
    garbage = socket.create_connection(("127.0.0.1", port))
    garbage.sendall(b"\x00\x03garbage")  # framing lost
    assert asyncio.run(asyncio.wait_for(served_here(url), 10.0)) < 5.0
    time.sleep(0.8)
    assert proc.stdout is not None
    proc.send_signal(signal.SIGUSR1)
    live = parse_stats(proc.stdout.readline())
    assert proc.poll() is None  # SIGUSR1 prints, it does not stop the server
    for sock in (silent, stranger, garbage):
        sock.close()
    out, err = server.stop()
    assert live["refused"] == "1 (chaos-host 1)"
    assert live["idle-closed"].startswith("1 (no frame 1)")
    assert live["bad frames"] == "1 (framing 1)"
    assert total(live["accepted"]) == 4
    final = parse_stats(out)
    assert final["refused"] == live["refused"] and total(final["accepted"]) == 4
    assert "Access refused: Chaos host 0402 not allowed" in err
    assert "Traceback" not in err


def test_without_stats_the_exit_prints_no_stats_line(manip_server: StartServer) -> None:
    out, _err = manip_server().stop()
    assert "stats:" not in out


# ------------------------------------------------------------------------------ exposure and options


@pytest.mark.parametrize(
    ("url", "rules", "warned"),
    [
        ("tcp://127.0.0.1:42085", [], False),
        ("tcp://[::1]:42085", [], False),
        ("tcp://localhost:42085", [], False),
        ("chaosd:///var/tmp/chaosd_server", [], False),
        ("tcp://0.0.0.0:42085", [], True),
        ("tcp://[::]:42085", [], True),
        ("tcp://robot.example:42085", [], True),
        ("chudp://10.1.2.3:42042?addr=0440", [], True),
        ("tcp://0.0.0.0:42085", ["10.0.0.0/8"], False),
        ("tcp://0.0.0.0:42085", ["chaos:0401"], True),
    ],
)
def test_listening_beyond_loopback_without_allow_warns(url: str, rules: list[str], warned: bool) -> None:
    warning = cli.exposure_warning(parse_address(url), AccessList.parse(rules))
    assert (warning is not None) == warned
    if warning is not None:
        assert "anyone who can reach this port can move the arm" in warning
        assert "no authentication" in warning and "--allow" in warning
        assert ("a peer writes its own Chaos address" in warning) == bool(rules)


def test_the_command_warns_before_serving(monkeypatch: pytest.MonkeyPatch) -> None:
    ran: list[dict[str, Any]] = []

    async def fake_run(*args: Any, **kwargs: Any) -> None:
        ran.append(kwargs)

    monkeypatch.setattr(cli, "_run", fake_run)
    result = CliRunner().invoke(cli.main, ["--listen", "tcp://0.0.0.0:0", "--stats"])
    assert result.exit_code == 0, result.output
    assert "warning: tcp://0.0.0.0:0 is not loopback" in result.output
    assert ran == [{"show_stats": True}]
    quiet = CliRunner().invoke(cli.main, ["--listen", "tcp://0.0.0.0:0", "--allow", "192.0.2.0/24"])
    assert quiet.exit_code == 0 and "warning" not in quiet.output


@pytest.mark.parametrize(
    "args",
    [
        ["--allow", "robot.example"],
        ["--allow", "chaos:9"],
        ["--frame-timeout", "-1"],
        ["--max-links", "-1"],
        ["--accept-backoff", "0"],
    ],
)
def test_bad_limit_or_rule_is_a_usage_error(args: list[str]) -> None:
    result = CliRunner().invoke(cli.main, args)
    assert result.exit_code == 2, result.output


def test_help_documents_the_limits_and_the_rules() -> None:
    out = " ".join(CliRunner().invoke(cli.main, ["--help"]).output.split())  # unwrapped
    for option in ("--allow", "--frame-timeout", "--link-idle-timeout", "--max-links", "--accept-backoff"):
        assert option in out
    assert "10.0.0.0/8" in out and "chaos:0401" in out and "SIGUSR1" in out
    assert "[default: 256;" in out and "[default: 10.0;" in out and "[default: 30.0;" in out
