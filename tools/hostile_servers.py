"""Hostile Chaos servers against the conformance suite (``manip-conform run``, ``fuzz``, ``replay
--against``): every run must end within its stated bound, in bounded memory, with a verdict (exit 1) or a
clear "target unreachable" (exit 3), and never a traceback.

``tools/hostile_campaign.py`` attacks the client with bad servers; this campaign points the suite itself
at them, since the target under test is by definition possibly broken.  Each scenario is a scripted bad
Puma (the client judge's scripted server, :mod:`manip.conformance.client.server`, with manip's own NCP,
on a fresh loopback port in a thread of this process) that every connection of the run meets:

* ``endless-describe``: describe-self never sends its empty terminator, and every other request is
  answered by replies that never stop (the run that once grew to 3.3 GB);
* ``huge-describe``: a 10 MB describe-self, then the terminator; ``deep-describe``: one nested 100,000
  deep;
* ``async-flood``: asynchronous packets without end; ``unknown-numbers``: replies carrying request
  numbers never sent, without end;
* ``silent-opn``: OPN, then nothing (no initial RESPONSE); ``silent-initial``: the initial RESPONSE, then
  nothing; ``silent-after-one``: one request answered per connection, then nothing;
* ``window-0``: a window of 0 offered for ever; ``absurd-acks``: STS packets acknowledging packets never
  sent; ``far-ahead``: data packets numbered far ahead; ``garbage``: packets of illegal opcodes and
  random data;
* ``fatal-no-cls``: every request answered with a fatal error, the connection left open;
* ``wrong-lengths``: every reply of a random length;
* ``cls-mid-reply``, ``los-mid-reply``, ``eof-mid-reply``: half a reply, then CLS, LOS or EOF;
  ``close-at-first``: the initial RESPONSE, then CLS at the first request; ``close-mid-case``: three
  requests answered, then CLS;
* ``liveness-only``: the first connection is served plainly (the liveness probe passes), every later one
  gets nothing.

Each run is a real process; the campaign prints, per scenario and command, the exit status, the seconds,
the peak resident memory (from ``/proc``) and the JSON report's size, and fails (exit 1) when a run
shows a traceback, exits with a status other than 1 or 3, takes longer than ``--timeout`` or grows past
``--rss-mb``.  One scenario at a time (the machine may be shared).

    .venv/bin/python tools/hostile_servers.py                        # every scenario against run
    .venv/bin/python tools/hostile_servers.py --only endless-describe --command fuzz
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import random
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from campaign_tally import peak_rss_mb
from manip.codecs.error_string import ErrorMessage
from manip.codecs.packet import Packet
from manip.conformance.client.server import Listener, ServerSide, plain_answer, scenario_in_thread
from manip.spec.constants import ChaosOp, RequestOp, ServerOp

MAX_DATA: Final = 488
DESCRIBE: Final = RequestOp.DESCRIBE_SELF
KEPT_RECORDS: Final = 64
"""The scripted server's wire keeps every packet; a flood trims it to its first records (the OPN)."""
Script = Callable[[ServerSide], Awaitable[None]]


@dataclass(frozen=True)
class Scenario:
    script: Script
    initial: bool = True
    """Whether the server sends the initial RESPONSE itself before the script."""


# ---------------------------------------------------------------------------------------- helpers


def _trim(side: ServerSide) -> None:
    records = side.wire.records
    if len(records) > 4 * KEPT_RECORDS:
        del records[KEPT_RECORDS:]


async def _each_request(side: ServerSide, answer: Callable[[Packet], Awaitable[None]]) -> None:
    while (request := await side.next_request(60.0)) is not None:
        await answer(request)


def _number(request: Packet) -> bytes:
    return request.packet_no.to_bytes(2, "little")


async def _forever(side: ServerSide, opcode: int, data: Callable[[int], bytes]) -> None:
    i = 0
    while True:
        await side.send(opcode, data(i))
        i += 1
        if i % 256 == 0:
            _trim(side)


# ---------------------------------------------------------------------------------------- scripts


async def _endless(side: ServerSide) -> None:
    chunk = b"(:chunk " + b"x" * 400 + b") "

    async def answer(request: Packet) -> None:
        if request.opcode == DESCRIBE:
            await _forever(side, ServerOp.RESPONSE, lambda _: _number(request) + chunk)
        else:
            await _forever(side, ServerOp.RESPONSE, lambda _: _number(request) + bytes(4))

    await _each_request(side, answer)


def _describe_text(text: bytes) -> Script:
    async def script(side: ServerSide) -> None:
        async def answer(request: Packet) -> None:
            if request.opcode != DESCRIBE:
                await plain_answer(side, request)
                return
            size = MAX_DATA - 2
            number = _number(request)
            for i in range(0, len(text), size):
                await side.send(ServerOp.RESPONSE, number + text[i : i + size])
                if i % (256 * size) == 0:
                    _trim(side)
            await side.send(ServerOp.RESPONSE, number)

        await _each_request(side, answer)

    return script


async def _async_flood(side: ServerSide) -> None:
    request = await side.next_request(60.0)
    if request is None:
        return
    await _forever(
        side,
        ServerOp.ASYNCHRONOUS_RESPONSE,
        lambda i: _number(request) + (1).to_bytes(2, "little") + bytes(4),
    )


async def _unknown_numbers(side: ServerSide) -> None:
    request = await side.next_request(60.0)
    if request is None:
        return
    await _forever(
        side, ServerOp.RESPONSE, lambda i: ((request.packet_no + 1000 + i) & 0xFFFF).to_bytes(2, "little")
    )


async def _silent(side: ServerSide) -> None:
    while await side.next_request(60.0) is not None:
        pass


async def _after_one(side: ServerSide) -> None:
    request = await side.next_request(60.0)
    if request is None:
        return
    await plain_answer(side, request)
    await _silent(side)


async def _window_0(side: ServerSide) -> None:
    side.offer_window(0)
    await _silent(side)


async def _absurd_acks(side: ServerSide) -> None:
    async def answer(request: Packet) -> None:
        for k in range(8):
            side.send_raw(ChaosOp.STS, bytes(4), ack_no=request.packet_no + 20_000 + k)
        await plain_answer(side, request)

    await _each_request(side, answer)


async def _far_ahead(side: ServerSide) -> None:
    async def answer(request: Packet) -> None:
        for k in range(8):
            side.send_raw(ServerOp.RESPONSE, _number(request), packet_no=30_000 + k, ack_no=request.packet_no)
        await plain_answer(side, request)

    await _each_request(side, answer)


async def _garbage(side: ServerSide) -> None:
    rng = random.Random(7)

    async def answer(request: Packet) -> None:
        for _ in range(6):
            side.send_raw(
                rng.choice((0o17, 0o77, 0o150, 0o200, 0o377)), rng.randbytes(rng.randrange(MAX_DATA))
            )
        if rng.random() < 0.5:
            await plain_answer(side, request)

    await _each_request(side, answer)


async def _fatal_no_cls(side: ServerSide) -> None:
    error = ErrorMessage("PUMA", "F", "HST", "Hostile fatal error", ()).encode()

    async def answer(request: Packet) -> None:
        await side.send(ServerOp.FATAL_ERROR, _number(request) + error)

    await _each_request(side, answer)


async def _wrong_lengths(side: ServerSide) -> None:
    rng = random.Random(11)

    async def answer(request: Packet) -> None:
        await side.send(
            ServerOp.RESPONSE, _number(request) + rng.randbytes(rng.choice((0, 1, 3, 5, 17, 486)))
        )

    await _each_request(side, answer)


def _mid_reply(how: str) -> Script:
    async def script(side: ServerSide) -> None:
        request = await side.next_request(60.0)
        if request is None:
            return
        await side.send(
            ServerOp.RESPONSE, _number(request) + (b"((:brand" if request.opcode == DESCRIBE else b"")
        )
        await asyncio.sleep(0.05)
        await _end(side, how)

    return script


async def _end(side: ServerSide, how: str) -> None:
    if how == "cls":
        side.close_now("hostile server closes")
    elif how == "los":
        side.send_los("hostile server loses the connection")
        side.conn.abort("lost")
    else:
        await side.conn.close(timeout=1.0)


async def _close_at_first(side: ServerSide) -> None:
    if await side.next_request(60.0) is not None:
        side.close_now("hostile server closes at the first request")


async def _close_mid_case(side: ServerSide) -> None:
    for _ in range(3):
        request = await side.next_request(60.0)
        if request is None:
            return
        await plain_answer(side, request)
    side.close_now("hostile server closes mid-case")


def _liveness_only() -> Scenario:
    served = [0]

    async def script(side: ServerSide) -> None:
        served[0] += 1
        if served[0] == 1:
            await side.serve_plainly()
        else:
            await _silent(side)

    return Scenario(script, initial=False)


def scenarios() -> dict[str, Scenario]:
    return {
        "endless-describe": Scenario(_endless),
        "huge-describe": Scenario(_describe_text(b'((:name "' + b"y" * (10 << 20) + b'"))')),
        "deep-describe": Scenario(_describe_text(b"((:deep " + b"(" * 100_000 + b")" * 100_000 + b"))")),
        "async-flood": Scenario(_async_flood),
        "unknown-numbers": Scenario(_unknown_numbers),
        "silent-opn": Scenario(_silent, initial=False),
        "silent-initial": Scenario(_silent),
        "silent-after-one": Scenario(_after_one),
        "window-0": Scenario(_window_0),
        "absurd-acks": Scenario(_absurd_acks),
        "far-ahead": Scenario(_far_ahead),
        "garbage": Scenario(_garbage),
        "fatal-no-cls": Scenario(_fatal_no_cls),
        "wrong-lengths": Scenario(_wrong_lengths),
        "cls-mid-reply": Scenario(_mid_reply("cls")),
        "los-mid-reply": Scenario(_mid_reply("los")),
        "eof-mid-reply": Scenario(_mid_reply("eof")),
        "close-at-first": Scenario(_close_at_first),
        "close-mid-case": Scenario(_close_mid_case),
        "liveness-only": _liveness_only(),
    }


# ---------------------------------------------------------------------------------------- the server


def hostile_server(scenario: Scenario, link: str = "tcp") -> contextlib.AbstractContextManager[Listener]:
    """A scenario's server on a loop of its own thread (the suite under test is another process)."""
    return scenario_in_thread(link, scenario.script, rng=random.Random(1), initial=scenario.initial)


# ---------------------------------------------------------------------------------------- the runs


@dataclass(frozen=True, slots=True)
class Figures:
    scenario: str
    command: str
    exit: int | None
    """None: killed after the campaign's timeout."""
    seconds: float
    rss_mb: float
    report_bytes: int
    verdict: str
    traceback: bool
    failed_clauses: frozenset[str] = frozenset()
    """The clauses the report's violations name."""
    counts: tuple[tuple[str, int], ...] = ()
    """The report's outcome counts."""

    @property
    def bad(self) -> bool:
        return self.traceback or self.exit not in (1, 3)


def command_line(command: str, target: str, report: Path, extra: Sequence[str]) -> list[str]:
    bindir = Path(sys.executable).parent
    if command == "run":
        return [str(bindir / "manip-conform"), "run", target, "--json", str(report), *extra]
    if command == "fuzz":
        cheap = ["--inputs", "500", "--shrink-seconds", "5"]  # the campaign's point is the end, not the finds
        return [str(bindir / "manip-conform"), "fuzz", target, "--json", str(report), *cheap, *extra]
    if command == "replay":
        capture = Path(__file__).resolve().parents[1] / "captures" / "describe-self.mcap"
        return [
            str(bindir / "manip-conform"),
            "replay",
            str(capture),
            "--against",
            target,
            "--json",
            str(report),
            *extra,
        ]
    raise ValueError(command)


def run_scenario(
    name: str,
    scenario: Scenario,
    command: str,
    *,
    timeout: float,
    link: str = "tcp",
    extra: Sequence[str] = (),
) -> Figures:
    """One command against one scenario's server, as a real process."""
    with (
        hostile_server(scenario, link) as server,
        tempfile.TemporaryDirectory() as tmp,
        tempfile.TemporaryFile() as out,
    ):
        report = Path(tmp) / "report.json"
        args = command_line(command, server.address, report, extra)
        started = time.monotonic()
        proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        peak = 0.0
        while proc.poll() is None and time.monotonic() - started < timeout:
            peak = max(peak, peak_rss_mb(proc.pid))
            time.sleep(0.05)
        code: int | None = proc.poll()
        if code is None:
            proc.kill()
            proc.wait()
        took = time.monotonic() - started
        out.seek(0)
        text = out.read().decode(errors="replace")
        size = report.stat().st_size if report.exists() else 0
        verdict, clauses, counts = _verdict(report, text)
    return Figures(name, command, code, took, peak, size, verdict, "Traceback" in text, clauses, counts)


def _verdict(report: Path, text: str) -> tuple[str, frozenset[str], tuple[tuple[str, int], ...]]:
    """The report's verdict (else the output's last line), the clauses its violations name, its counts."""
    with contextlib.suppress(OSError, ValueError, AttributeError, TypeError):
        data = json.loads(report.read_text())
        clauses = frozenset(
            str(v["clause"])
            for case in data.get("cases", [])
            for v in case.get("violations", [])
            if v.get("clause")
        )
        counts = tuple((str(k), int(n)) for k, n in dict(data.get("counts", {})).items())
        if data.get("verdict"):
            return str(data["verdict"]), clauses, counts
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return (lines[-1][:80] if lines else ""), frozenset(), ()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--only", action="append", default=[], help="Only this scenario (repeatable).")
    parser.add_argument(
        "--command", action="append", default=[], choices=("run", "fuzz", "replay"), help="Default: run."
    )
    parser.add_argument("--link", default="tcp", choices=("tcp", "chudp"))
    parser.add_argument("--timeout", type=float, default=300.0, help="Seconds one run may take.")
    parser.add_argument("--rss-mb", type=float, default=300.0, help="Peak resident memory allowed.")
    parser.add_argument("extra", nargs="*", help="More options for the command (after --).")
    args = parser.parse_args(argv)
    all_scenarios = scenarios()
    unknown = [n for n in args.only if n not in all_scenarios]
    if unknown:
        parser.error(f"unknown scenario(s): {', '.join(unknown)}; known: {', '.join(all_scenarios)}")
    chosen = {n: s for n, s in all_scenarios.items() if not args.only or n in args.only}
    print(f"{'scenario':18} {'command':7} {'exit':>4} {'seconds':>8} {'peak RSS':>9} {'report':>9}  verdict")
    bad = 0
    for name, scenario in chosen.items():
        for command in args.command or ["run"]:
            f = run_scenario(name, scenario, command, timeout=args.timeout, link=args.link, extra=args.extra)
            over = f.bad or f.rss_mb > args.rss_mb
            bad += over
            code = "kill" if f.exit is None else str(f.exit)
            figures = f"{f.seconds:8.1f} {f.rss_mb:6.0f} MB {f.report_bytes / 1024:6.0f} KB"
            print(
                f"{name:18} {command:7} {code:>4} {figures}  {f.verdict}"
                + ("  TRACEBACK" if f.traceback else "")
                + ("  <-- BAD" if over else ""),
                flush=True,
            )
    return 1 if bad else 0


if __name__ == "__main__":
    os.environ.setdefault("PYTHONFAULTHANDLER", "1")
    sys.exit(main())
