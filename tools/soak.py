"""Soak the reference server: eight clients connecting, vanishing, resetting and flooding for a while,
the server's memory and descriptors sampled all along; both must stay flat.

The server is ``manip-server`` on a free loopback port (extra options after ``--``).  Eight client
tasks loop until the time is up, each pass one of (drawn from the seed):

* ``session``: a Chaos connection, a few requests read one by one, a clean close (CLS);
* ``flood``: a connection and 500 Here requests pipelined, every reply read, a clean close;
* ``vanish``: a connection, a request, then the socket closed without a CLS;
* ``reset``: a connection, requests, then the socket reset (no FIN, no CLS);
* ``idle``: a socket that sends nothing, or half a frame, and is dropped after up to 2 s;
* ``garbage``: a socket carrying bytes of another protocol;
* ``rfcs``: twenty RFCs on one socket, most refused as busy (one robot), then dropped;

then a pause of up to ``--pause`` seconds.  One robot takes one client, so most connections are
refused as busy: that is part of the load.  Every ``--interval`` seconds the server's resident memory
(VmRSS) and open descriptors (``/proc/PID/fd``) are sampled, with its stats line (SIGUSR1).  At the
end the clients stop, the server is given its link timeouts to close what is left, and sampled again.

Flat means: the memory at the end is within ``--rss-growth`` (default 10 %) of the memory after the
warm-up (the first tenth of the run), the trend over the second half is under 5 MB per hour, and the
descriptors are back to what the idle server held (give or take two).  The server's log must hold no
traceback.  Exit status 0 when all of that holds, 1 when not.

    .venv/bin/python tools/soak.py --minutes 60 > soak.txt
    .venv/bin/python tools/soak.py --minutes 2 --interval 2 -- --cougar sim
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import random
import re
import signal
import socket
import statistics
import struct
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Final

from manip.codecs.framing import encode_tcp
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, ChaosError, open_connection, parse_address
from manip.spec.constants import ChaosOp, RequestOp

CLIENTS: Final = 8
FLOOD: Final = 500
RFCS: Final = 20
KINDS: Final = ("session", "flood", "vanish", "reset", "idle", "garbage", "rfcs")
WEIGHTS: Final = (4, 2, 3, 3, 2, 1, 1)
SETTLE: Final = 35.0
"""Seconds the server gets after the clients stop (its idle-link timeout is 30 s) before the last sample."""
TREND_LIMIT_MB_PER_HOUR: Final = 5.0
_RESET: Final = struct.pack("ii", 1, 0)
_TRACEBACK: Final = "Traceback (most recent call last):"


@dataclass
class Sample:
    t: float
    rss_kb: int
    fds: int
    stats: str = ""


@dataclass
class Tally:
    done: Counter[str] = field(default_factory=Counter)
    refused: int = 0
    failed: Counter[str] = field(default_factory=Counter)
    replies: int = 0


def rss_kb(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return 0


def fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def rfc_frame(index: int, number: int, address: str) -> bytes:
    a = parse_address(address)
    return encode_tcp(Packet(ChaosOp.RFC, a.peer_addr, 0, a.my_addr, index, number, 0, a.contact.encode()))


async def _requests(conn: ChaosConnection, count: int, tally: Tally) -> None:
    for _ in range(count):
        await conn.send(b"", RequestOp.HERE)
        await asyncio.wait_for(conn.receive(), 5.0)
        tally.replies += 1


async def _flood(conn: ChaosConnection, tally: Tally) -> None:
    async def read() -> None:
        for _ in range(FLOOD):
            await asyncio.wait_for(conn.receive(), 10.0)
            tally.replies += 1

    reader = asyncio.ensure_future(read())
    try:
        for _ in range(FLOOD):
            await conn.send(b"", RequestOp.HERE)
        await reader
    finally:
        reader.cancel()


def _abort(conn: ChaosConnection, *, reset: bool) -> None:
    """Drop the connection's link without a CLS: closed (FIN) or reset."""
    for link in conn.node.links:
        transport = getattr(link, "_transport", None)
        if transport is None:
            continue
        sock = transport.get_extra_info("socket")
        if reset and sock is not None:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
        transport.abort()


async def client(number: int, address: str, until: float, seed: int, pause: float, tally: Tally) -> None:
    rng = random.Random(seed * 100 + number)
    host, port = parse_address(address).host, parse_address(address).port
    while time.monotonic() < until:
        kind = rng.choices(KINDS, WEIGHTS)[0]
        try:
            await asyncio.wait_for(_pass(kind, address, host, port, rng, tally), 60.0)
            tally.done[kind] += 1
        except ChaosError as exc:
            if "busy" in str(exc).lower():
                tally.refused += 1
            else:
                tally.failed[f"{kind}: {type(exc).__name__}"] += 1
        except (OSError, TimeoutError) as exc:
            tally.failed[f"{kind}: {type(exc).__name__}"] += 1
        await asyncio.sleep(rng.uniform(0.0, pause))


async def _pass(kind: str, address: str, host: str, port: int, rng: random.Random, tally: Tally) -> None:
    if kind in ("session", "flood", "vanish", "reset"):
        conn = await open_connection(address, timeout=5.0)
        try:
            if kind == "session":
                await _requests(conn, rng.randint(1, 10), tally)
            elif kind == "flood":
                await _flood(conn, tally)
            else:
                await _requests(conn, rng.randint(0, 3), tally)
                _abort(conn, reset=kind == "reset")
        finally:
            await conn.close(timeout=2.0)
        return
    reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), 5.0)
    try:
        if kind == "idle":
            if rng.random() < 0.5:
                writer.write(rfc_frame(0x0100, 1, address)[: rng.randint(1, 20)])
            await asyncio.sleep(rng.uniform(0.0, 2.0))
        elif kind == "garbage":
            writer.write(
                rng.choice((b"GET / HTTP/1.0\r\n\r\n", b"SSH-2.0-x\r\n", bytes([2]) + rng.randbytes(50)))
            )
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(reader.read(100), 2.0)
        else:
            for i in range(RFCS):
                writer.write(rfc_frame(0x0100 + i, rng.randrange(0x10000), address))
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(reader.read(4096), 1.0)
    finally:
        writer.close()
        with contextlib.suppress(OSError):
            await writer.wait_closed()


async def sampler(
    pid: int, started: float, until: float, interval: float, samples: list[Sample], stats: asyncio.Queue[str]
) -> None:
    while time.monotonic() < until:
        samples.append(await _sample(pid, started, stats))
        s = samples[-1]
        print(f"{s.t:8.1f} s  rss {s.rss_kb / 1024:7.1f} MB  fds {s.fds:4d}  {s.stats}", flush=True)
        await asyncio.sleep(interval)


async def _sample(pid: int, started: float, stats: asyncio.Queue[str]) -> Sample:
    while not stats.empty():
        stats.get_nowait()
    os.kill(pid, signal.SIGUSR1)
    line = ""
    with contextlib.suppress(TimeoutError):
        line = await asyncio.wait_for(stats.get(), 2.0)
    return Sample(
        time.monotonic() - started, rss_kb(pid), fds(pid), line.removeprefix("manip-server: stats: ").strip()
    )


def trend_mb_per_hour(samples: list[Sample]) -> float:
    """Least-squares slope of the resident memory over the samples, MB per hour."""
    if len(samples) < 3:
        return 0.0
    slope = statistics.linear_regression([s.t for s in samples], [s.rss_kb / 1024 for s in samples]).slope
    return slope * 3600


async def soak(args: argparse.Namespace, server_args: list[str]) -> int:
    cmd = [
        sys.executable,
        "-m",
        "manip.reference_server.cli",
        "--listen",
        "tcp://127.0.0.1:0",
        "--log-level",
        "WARNING",
        *server_args,
    ]
    proc = await asyncio.create_subprocess_exec(
        *cmd,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    assert proc.stdout is not None and proc.stderr is not None
    first = (await asyncio.wait_for(proc.stdout.readline(), 30.0)).decode()
    match = re.match(r"manip-server: listening on (\S+)", first)
    if match is None:
        print(f"the server did not start: {first!r}", file=sys.stderr)
        return 1
    address = match.group(1)
    stats: asyncio.Queue[str] = asyncio.Queue()
    errors: list[str] = []

    async def read_out() -> None:
        assert proc.stdout is not None
        async for raw in proc.stdout:
            stats.put_nowait(raw.decode())

    async def read_err() -> None:
        assert proc.stderr is not None
        async for raw in proc.stderr:
            errors.append(raw.decode())

    readers = [asyncio.ensure_future(read_out()), asyncio.ensure_future(read_err())]
    await asyncio.sleep(1.0)
    started = time.monotonic()
    idle = await _sample(proc.pid, started, stats)
    print(f"soak: {address}, pid {proc.pid}, {CLIENTS} clients for {args.minutes:g} min, seed {args.seed}")
    print(f"idle server: rss {idle.rss_kb / 1024:.1f} MB, fds {idle.fds}", flush=True)
    until = started + args.minutes * 60
    tally = Tally()
    samples: list[Sample] = []
    tasks = [
        asyncio.ensure_future(client(i, address, until, args.seed, args.pause, tally)) for i in range(CLIENTS)
    ]
    await sampler(proc.pid, started, until, args.interval, samples, stats)
    await asyncio.gather(*tasks, return_exceptions=True)
    print(f"clients stopped; {SETTLE:g} s for the server to close what is left", flush=True)
    await asyncio.sleep(SETTLE)
    final = await _sample(proc.pid, started, stats)
    alive = proc.returncode is None
    proc.send_signal(signal.SIGTERM)
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(proc.wait(), 10.0)
    for reader in readers:
        with contextlib.suppress(TimeoutError, asyncio.CancelledError):
            await asyncio.wait_for(reader, 5.0)
    tracebacks = sum(line.startswith(_TRACEBACK) for line in errors)
    warm = samples[max(1, len(samples) // 10)] if samples else idle
    half = samples[len(samples) // 2 :]
    growth = (final.rss_kb - warm.rss_kb) / warm.rss_kb * 100
    trend = trend_mb_per_hour(half)
    rss = [s.rss_kb / 1024 for s in samples]
    open_fds = [s.fds for s in samples]
    passes = ", ".join(f"{k} {tally.done[k]}" for k in KINDS)
    total = sum(tally.done.values())
    print(f"passes: {total} ({passes}); refused busy {tally.refused}; replies {tally.replies}")
    if tally.failed:
        print(f"client passes that failed: {dict(tally.failed)}")
    print(f"samples: {len(samples)} every {args.interval:g} s")
    print(
        f"rss MB: idle {idle.rss_kb / 1024:.1f}, after warm-up {warm.rss_kb / 1024:.1f}, "
        f"min {min(rss):.1f}, max {max(rss):.1f}, end {final.rss_kb / 1024:.1f} "
        f"({growth:+.1f} % from warm-up); trend over the second half {trend:+.2f} MB/h"
    )
    print(f"fds: idle {idle.fds}, min {min(open_fds)}, max {max(open_fds)}, end {final.fds}")
    print(f"server stats at the end: {final.stats}")
    print(f"server log: {len(errors)} line(s), {tracebacks} traceback(s); the most frequent:")
    kinds = Counter(re.sub(r"^\S+ \S+ |\d+|0x[0-9a-f]+", "#", line.strip())[:100] for line in errors)
    for line, count in kinds.most_common(5):
        print(f"  {count:6d}  {line}")
    flat = growth <= args.rss_growth and trend <= TREND_LIMIT_MB_PER_HOUR and abs(final.fds - idle.fds) <= 2
    verdict = alive and flat and tracebacks == 0
    state = "flat" if flat else "NOT flat"
    print(f"{state}; server {'alive' if alive else 'DEAD'}; {'PASS' if verdict else 'FAIL'}")
    return 0 if verdict else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--interval", type=float, default=5.0, help="seconds between samples (default 5)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--pause", type=float, default=0.5, help="most seconds a client rests between passes")
    parser.add_argument(
        "--rss-growth", type=float, default=10.0, help="percent the memory may grow (default 10)"
    )
    argv = sys.argv[1:]
    server_args: list[str] = []
    if "--" in argv:
        cut = argv.index("--")
        argv, server_args = argv[:cut], argv[cut + 1 :]
    args = parser.parse_args(argv)
    return asyncio.run(soak(args, server_args))


if __name__ == "__main__":
    sys.exit(main())
