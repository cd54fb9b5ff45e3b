"""A hostile Chaos server against ``manip-client`` (the command and the library): every run must end, in
bounded memory, with a result or a clear error (never a traceback), and a connection the client gave up
must be reported as lost.

Each scenario is a scripted bad Puma on a fresh loopback port (the client judge's scripted server,
:mod:`manip.conformance.client.server`, run in a thread of its own):

* ``endless-describe``: describe-self answered with text that never ends (no terminator);
* ``deep-500`` / ``deep-20000``: describe-self text nested 500 (1 KB) or 20,000 deep;
* ``huge-describe``: describe-self answered with 4 MB of text, then the terminator;
* ``garbage-replies``: every request answered with random bytes as a RESPONSE;
* ``random-opcodes``: packets of random server opcodes (0200-0377) with random data;
* ``bad-errors``: error packets (0201, 0202, 0204, 0205) with random or truncated error strings;
* ``illegal-chaos``: Chaos packets of illegal opcodes (the client answers with LOS and gives up);
* ``illegal-deaf``: the same from a server deaf to the client's LOS (nothing but the client's own LOS
  can tell it the connection is gone);
* ``async-flood``: 3,000 asynchronous responses, then the reply;
* ``stall``: the request is never answered;
* ``close-mid``: half a describe-self, then a CLS; ``drop-mid``: the link dropped instead;
* ``huge-packets``: replies of the largest data a packet may hold (488 bytes) to single-packet requests.

Each scenario is run against ``describe`` (text and ``--json``), ``here`` and ``raw 0216`` of the
command, as real processes (``--processes``, peak resident memory measured from ``/proc``) or in this
process by click's test runner, and against the library's ``describe_self()`` and ``here()`` with and
without a timeout (``timeout=None`` too).  Outcomes:

* ``ok``: exit 0 (or a result);
* ``waits``: the library, asked for no timeout, still waits for an answer that never ends (``stall``);
* ``error``: a documented exit status with one clear line (the library: a ``ManipError``);
* ``wrong``: an error, but not the one the scenario calls for (a connection the client gave up with LOS
  reported as a timeout);
* ``traceback``, ``hang`` (no end within ``--timeout`` seconds, however long the client's own timeout),
  ``memory`` (peak resident set over ``--rss-mb``).

The campaign fails (exit 1) on any ``wrong``, ``traceback``, ``hang`` or ``memory``.

    .venv/bin/python tools/hostile_campaign.py --seed 1 --rounds 3
    .venv/bin/python tools/hostile_campaign.py --processes
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from click.testing import CliRunner

from campaign_tally import peak_rss_mb, tally
from manip.codecs.error_string import ErrorMessage
from manip.codecs.packet import Packet
from manip.conformance.client.server import Listener, ServerSide, plain_answer, scenario_in_thread
from manip.reference_client import ClientOptions, ManipError, aconnect
from manip.reference_client.cli import main as client_main
from manip.spec.constants import ChaosOp, RequestOp, ServerOp

BAD: Final = frozenset({"wrong", "traceback", "hang", "memory"})
OUTCOMES: Final = ("ok", "error", "waits", "wrong", "traceback", "hang", "memory")
MAX_DATA: Final = 488
DESCRIBE: Final = RequestOp.DESCRIBE_SELF
Script = Callable[[ServerSide], Awaitable[None]]


# ---------------------------------------------------------------------------------------- the server


async def _each_request(side: ServerSide, answer: Callable[[Packet], Awaitable[None]]) -> None:
    while (request := await side.next_request(30.0)) is not None:
        await answer(request)


def _text_forever(chunk: bytes) -> Script:
    async def script(side: ServerSide) -> None:
        async def answer(request: Packet) -> None:
            if request.opcode != DESCRIBE:
                await plain_answer(side, request)
                return
            number = request.packet_no.to_bytes(2, "little")
            while True:
                await side.send(ServerOp.RESPONSE, number + chunk)

        await _each_request(side, answer)

    return script


def _describe_text(text: bytes) -> Script:
    async def script(side: ServerSide) -> None:
        async def answer(request: Packet) -> None:
            if request.opcode != DESCRIBE:
                await plain_answer(side, request)
                return
            size = MAX_DATA - 2
            await side.text_reply(request, [text[i : i + size] for i in range(0, len(text), size)])

        await _each_request(side, answer)

    return script


def _random_replies(seed: int, opcodes: Sequence[int]) -> Script:
    rng = random.Random(seed)

    async def script(side: ServerSide) -> None:
        async def answer(request: Packet) -> None:
            for _ in range(rng.randint(1, 4)):
                opcode = rng.choice(opcodes)
                number = request.packet_no if rng.random() < 0.8 else rng.randrange(1 << 16)
                body = rng.randbytes(rng.choice((0, 1, 3, 7, 30, MAX_DATA - 2)))
                await side.send(opcode, number.to_bytes(2, "little") + body)
            await plain_answer(side, request)

        await _each_request(side, answer)

    return script


def _bad_errors(seed: int) -> Script:
    rng = random.Random(seed)

    async def script(side: ServerSide) -> None:
        async def answer(request: Packet) -> None:
            opcode = rng.choice((ServerOp.FATAL_ERROR, ServerOp.NON_FATAL_ERROR, 0o204, 0o205))
            good = ErrorMessage("PUMA", "C", "BDL", "Bad ~ and ~ $", (1, 1 << 31, 7)).encode()
            body = rng.choice(
                (rng.randbytes(rng.randrange(60)), good[: rng.randrange(len(good))], b"~" * 400)
            )
            await side.send(opcode, request.packet_no.to_bytes(2, "little") + body)
            await plain_answer(side, request)

        await _each_request(side, answer)

    return script


async def _illegal_chaos(side: ServerSide) -> None:
    if await side.next_request(30.0) is None:
        return
    for opcode in (0o17, 0o77, 0o150):
        side.send_raw(opcode, b"hostile")
    await side.next_request(30.0)


async def _illegal_deaf(side: ServerSide) -> None:
    """Illegal packets, then deaf to the client's LOS (as a server without a real NCP would be): the
    client learns nothing more from the server, so only its own LOS can tell it the connection is gone."""
    if await side.next_request(30.0) is None:
        return
    link = side.wire.links[0]
    hear = link._receiver  # the tap's hook into the server's node (a scenario may reach into it)

    def deaf(on: Any, packet: Packet) -> None:
        if packet.opcode != ChaosOp.LOS and hear is not None:
            hear(on, packet)

    link._receiver = deaf
    for opcode in (0o17, 0o77, 0o150):
        side.send_raw(opcode, b"hostile")
    await side.next_request(30.0)


async def _async_flood(side: ServerSide) -> None:
    async def answer(request: Packet) -> None:
        for i in range(3000):
            await side.async_response(1, i & 0xFFFF, 0, request.packet_no)
        await plain_answer(side, request)

    await _each_request(side, answer)


async def _stall(side: ServerSide) -> None:
    while await side.next_request(60.0) is not None:
        pass


def _mid(action: str) -> Script:
    async def script(side: ServerSide) -> None:
        request = await side.next_request(30.0)
        if request is None:
            return
        await side.send(ServerOp.RESPONSE, request.packet_no.to_bytes(2, "little") + b"((:brand")
        await asyncio.sleep(0.05)
        if action == "close":
            side.close_now("hostile server closes mid-reply")
        else:
            side.drop_link()

    return script


async def _huge_packets(side: ServerSide) -> None:
    async def answer(request: Packet) -> None:
        await side.reply_payload(request, bytes(MAX_DATA - 2))

    await _each_request(side, answer)


def _deep(depth: int) -> bytes:
    """A well-formed description whose one value is nested ``depth`` lists deep."""
    return b"((:deep " + b"(" * depth + b")" * depth + b"))"


def scenarios(seed: int) -> dict[str, Script]:
    """The scenarios of a seed (the seed draws the random replies)."""
    return {
        "endless-describe": _text_forever(b"(:chunk " + b"x" * 400 + b") "),
        "deep-500": _describe_text(_deep(500)),
        "deep-20000": _describe_text(_deep(20_000)),
        "huge-describe": _describe_text(b'((:name "' + b"y" * (4 << 20) + b'"))'),
        "garbage-replies": _random_replies(seed, (ServerOp.RESPONSE,)),
        "random-opcodes": _random_replies(seed + 1, tuple(range(0o200, 0o400))),
        "bad-errors": _bad_errors(seed + 2),
        "illegal-chaos": _illegal_chaos,
        "illegal-deaf": _illegal_deaf,
        "async-flood": _async_flood,
        "stall": _stall,
        "close-mid": _mid("close"),
        "drop-mid": _mid("drop"),
        "huge-packets": _huge_packets,
    }


WAITS: Final = frozenset({"stall", "huge-packets"})
"""Scenarios whose server never finishes its answer: without a timeout the library waits, as asked."""
EXPECTED: Final = {"illegal-chaos": "illegal packet", "illegal-deaf": "illegal packet"}
"""What a scenario's error must say (any error will do for the others)."""


def hostile_server(script: Script, seed: int = 0) -> contextlib.AbstractContextManager[Listener]:
    """A scenario's server on a loop of its own thread (the client under test runs in the main one)."""
    return scenario_in_thread("tcp", script, rng=random.Random(seed))


# ---------------------------------------------------------------------------------------- clients


@dataclass(frozen=True, slots=True)
class Outcome:
    scenario: str
    client: str
    outcome: str
    detail: str
    rss_mb: float = 0.0


COMMANDS: Final = {
    "describe": ["describe"],
    "describe-json": ["describe", "--json"],
    "here": ["here"],
    "raw-0200": ["raw", "0200"],
    "raw-0216-600": ["raw", "0216", "00" * 600, "--no-check"],
}


USAGE: Final = frozenset({"raw-0216-600"})
"""Commands whose arguments are wrong whatever the server: exit 2, a usage error, before connecting."""


def judge(scenario: str, command: str, code: int, out: str, err: str) -> tuple[str, str]:
    """The outcome of one command's run from its exit status and output."""
    text = out + err
    if "Traceback" in text or "background process failed" in text:
        return "traceback", _last(text)
    if code == 0:
        return "ok", ""
    if code not in ((2,) if command in USAGE else (1, 3, 4)) or not text.strip():
        return "traceback", f"exit {code}: {_last(text)}"
    if command in USAGE:
        return "error", _last(text)
    expected = EXPECTED.get(scenario)
    if expected is not None and expected not in text.lower():
        return "wrong", f"expected {expected!r}, got exit {code}: {_last(text)}"
    return "error", _last(text)


def _last(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1][:200] if lines else ""


def run_command_in_process(scenario: str, script: Script, command: str, seed: int, timeout: float) -> Outcome:
    """One command of ``manip-client``, in this process (click's test runner)."""

    with hostile_server(script, seed) as server:
        args = [server.address, *COMMANDS[command], "--timeout", str(min(timeout / 2, 5.0))]
        started = time.monotonic()
        result = CliRunner().invoke(client_main, args)
        took = time.monotonic() - started
    name = f"cli {command}"
    exc = result.exception
    if isinstance(exc, MemoryError):
        return Outcome(scenario, name, "memory", "MemoryError")
    if exc is not None and not isinstance(exc, SystemExit):
        return Outcome(scenario, name, "traceback", f"{type(exc).__name__}: {exc}"[:200])
    if took > timeout:
        return Outcome(scenario, name, "hang", f"took {took:.1f} s")
    outcome, detail = judge(scenario, command, result.exit_code, result.stdout, result.stderr)
    return Outcome(scenario, name, outcome, detail)


def run_command_process(
    scenario: str, script: Script, command: str, seed: int, timeout: float, rss_mb: float
) -> Outcome:
    """One command of ``manip-client`` as a real process; its peak resident memory is sampled."""
    exe = Path(sys.executable).parent / "manip-client"
    name = f"process {command}"
    # Output goes to files, not pipes: a pipe nobody reads while the process runs would fill and stall it.
    with (
        hostile_server(script, seed) as server,
        tempfile.TemporaryFile() as out,
        tempfile.TemporaryFile() as err,
    ):
        args = [str(exe), server.address, *COMMANDS[command], "--timeout", str(min(timeout / 2, 5.0))]
        proc = subprocess.Popen(args, stdout=out, stderr=err)
        peak, deadline = 0.0, time.monotonic() + timeout
        while proc.poll() is None and time.monotonic() < deadline:
            peak = max(peak, peak_rss_mb(proc.pid))
            time.sleep(0.05)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
            return Outcome(scenario, name, "hang", f"killed after {timeout} s", peak)
        out.seek(0)
        err.seek(0)
        text_out, text_err = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if peak > rss_mb:
        return Outcome(scenario, name, "memory", f"peak RSS {peak:.0f} MB", peak)
    outcome, detail = judge(scenario, command, proc.returncode, text_out, text_err)
    return Outcome(scenario, name, outcome, detail, peak)


LIBRARY: Final = ("lib-describe", "lib-describe-no-timeout", "lib-here", "lib-here-no-timeout")


async def _library_call(target: str, call: str, timeout: float) -> Any:

    client_timeout = None if call.endswith("no-timeout") else min(timeout / 2, 5.0)
    options = ClientOptions(timeout=client_timeout, connect_timeout=5.0)
    async with aconnect(target, options) as arm:
        if call.startswith("lib-describe"):
            return await arm.describe()
        return await arm.here()


def run_library(scenario: str, script: Script, call: str, seed: int, timeout: float) -> Outcome:
    """One library call (``describe_self()`` or ``here()``) in this process."""

    name = call
    with hostile_server(script, seed) as server:
        try:
            asyncio.run(asyncio.wait_for(_library_call(server.address, call, timeout), timeout))
        except ManipError as exc:  # before TimeoutError: a RequestTimeout is one too
            expected = EXPECTED.get(scenario)
            if expected is not None and expected not in str(exc).lower():
                return Outcome(scenario, name, "wrong", f"expected {expected!r}: {type(exc).__name__}: {exc}")
            return Outcome(scenario, name, "error", f"{type(exc).__name__}: {exc}"[:200])
        except TimeoutError:
            if call.endswith("no-timeout") and scenario in WAITS:
                return Outcome(scenario, name, "waits", "no reply comes, and no timeout was asked for")
            return Outcome(scenario, name, "hang", f"no end within {timeout} s")
        except MemoryError:
            return Outcome(scenario, name, "memory", "MemoryError")
        except Exception as exc:
            return Outcome(scenario, name, "traceback", f"{type(exc).__name__}: {exc}"[:200])
    return Outcome(scenario, name, "ok", "")


def run_one(
    scenario: str, script: Script, client: str, seed: int, *, processes: bool, timeout: float, rss_mb: float
) -> Outcome:
    """One scenario against one client: a command (``COMMANDS``) or a library call (``LIBRARY``)."""
    if client in LIBRARY:
        return run_library(scenario, script, client, seed, timeout)
    if processes:
        return run_command_process(scenario, script, client, seed, timeout, rss_mb)
    return run_command_in_process(scenario, script, client, seed, timeout)


def campaign(
    seed: int,
    rounds: int = 1,
    *,
    processes: bool = False,
    timeout: float = 20.0,
    rss_mb: float = 200.0,
    only: Sequence[str] = (),
    report: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Every scenario against every command and library call, ``rounds`` times (each with its own seed)."""
    outcomes = []
    for r in range(rounds):
        for scenario, script in scenarios(seed + 1000 * r).items():
            if only and scenario not in only:
                continue
            for client in (*COMMANDS, *LIBRARY):
                outcome = run_one(
                    scenario, script, client, seed, processes=processes, timeout=timeout, rss_mb=rss_mb
                )
                outcomes.append(outcome)
                if report is not None:
                    report(outcome)
    return outcomes


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rounds", type=int, default=1, help="Times through every scenario (new seeds).")
    parser.add_argument(
        "--processes", action="store_true", help="The command as real processes, RSS sampled."
    )
    parser.add_argument("--timeout", type=float, default=20.0, help="Seconds one run may take.")
    parser.add_argument(
        "--rss-mb", type=float, default=200.0, help="Peak resident memory allowed (processes)."
    )
    parser.add_argument("--only", action="append", default=[], help="Only this scenario (repeatable).")
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="Print every outcome, not only bad ones."
    )
    args = parser.parse_args(argv)

    def show(o: Outcome) -> None:
        if args.verbose or o.outcome in BAD:
            rss = f" ({o.rss_mb:.0f} MB)" if o.rss_mb else ""
            print(f"{o.outcome:9} {o.scenario:17} {o.client:26} {o.detail}{rss}", flush=True)

    started = time.monotonic()
    outcomes = campaign(
        args.seed,
        args.rounds,
        processes=args.processes,
        timeout=args.timeout,
        rss_mb=args.rss_mb,
        only=args.only,
        report=show,
    )
    return tally(
        outcomes,
        f"(seed {args.seed}, {args.rounds} round(s))",
        started=started,
        kinds=OUTCOMES,
        bad=BAD,
        peak=args.processes,
    )


if __name__ == "__main__":
    os.environ.setdefault("PYTHONFAULTHANDLER", "1")
    sys.exit(main())
