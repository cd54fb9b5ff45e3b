"""Reference server benchmark (run by hand): Here requests/s, latency, and servo-tick jitter.

The servers run in a child process (client and server are separate programs in real use, and the
server's own CPU time can then be measured): the reference server (``max_clients=8`` so that eight
clients can hammer it at once; one robot normally takes one client), and as the baseline a bare NCP
echo server on the same TCP link that answers every packet with a 50-byte packet (the size of a Here
reply) without looking at it.  Clients run in this process over manip's links.

For each scenario (1 and 8 clients, one request at a time or pipelined up to the Chaos window of 15)
it prints, for the server and the baseline: requests/s through the whole path, latency p50/p99 (send to
reply, so pipelined latencies include the queue), and the server process's CPU time per request, which
gives the rate one core could sustain (``req/s per server core`` = requests / server CPU seconds).
The clients share one core with everything else, so the wall-clock rate is usually bound by them.

Then servo jitter: the server's servo wakes at 62.5 Hz (time scale 1); it records how late each wake-up
was.  Measured idle (one client connected, silent) and while 8 pipelining clients hammer Here.

    .venv/bin/python bench/server.py [--requests 4000] [--rounds 3] [--jitter-seconds 5] [--profile]

Targets (issue 4): >= 10,000 Here requests/s on one core; servo tick jitter p99 <= 1 ms.  Figures only.
``--profile`` runs the server child under cProfile and prints where its time went.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import json
import pstats
import statistics
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from manip.links import ChaosConnection, ChaosServer, open_connection, start_server
from manip.reference_server import ServerConfig
from manip.reference_server.driver import ReferenceServer, serve
from manip.spec.constants import RequestOp, ServerOp

HERE = RequestOp.HERE
REPLY = bytes(50)
CLIENTS = 8
WINDOW = 15


# ---------------------------------------------------------------------------------- the child
async def _echo(conn: ChaosConnection) -> None:
    async for _packet in conn:
        await conn.send(REPLY, ServerOp.RESPONSE)


def _report(server: ReferenceServer, since: int) -> dict[str, Any]:
    lateness = list(server.tick_lateness)
    stats = server.stats
    return {
        "cpu": time.process_time(),
        "ticks": stats.ticks,
        "lateness": lateness[max(0, len(lateness) - (stats.ticks - since)) :],
        "requests": stats.requests,
        "late_ticks": stats.late_ticks,
        "driver_errors": stats.driver_errors,
    }


async def _child() -> None:
    """Serve until stdin closes; each line ``mark`` is answered with a JSON report."""
    loop = asyncio.get_running_loop()
    echo: ChaosServer = await start_server("tcp://127.0.0.1:0", "ECHO", _echo)
    async with serve("tcp://127.0.0.1:0", ServerConfig(powered_at_open=True), max_clients=CLIENTS) as server:
        print(server.address, echo.address, flush=True)
        since = 0
        while True:
            line = await loop.run_in_executor(None, sys.stdin.readline)
            if not line or line.strip() == "quit":
                break
            report = _report(server, since)
            since = server.stats.ticks
            print(json.dumps(report), flush=True)
    await echo.aclose()


def child_main(profile: bool) -> None:
    if not profile:
        asyncio.run(_child())
        return
    profiler = cProfile.Profile()
    profiler.enable()
    asyncio.run(_child())
    profiler.disable()
    out = pstats.Stats(profiler, stream=sys.stderr)
    out.sort_stats("tottime").print_stats(25)
    out.sort_stats("cumulative").print_stats(40)


# --------------------------------------------------------------------------------- the parent
class Child:
    def __init__(self, profile: bool) -> None:
        cmd = [sys.executable, __file__, "--child"] + (["--profile"] if profile else [])
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout is not None
        self.server_url, self.echo_url = self.proc.stdout.readline().split()
        self.echo_url += "?contact=ECHO"

    def mark(self) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write("mark\n")
        self.proc.stdin.flush()
        result: dict[str, Any] = json.loads(self.proc.stdout.readline())
        return result

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


_next_me = 0o401


async def _connect(url: str, greeting: bool) -> ChaosConnection:
    # Each client its own Chaos address: clients on one address share index space only by luck.
    global _next_me  # noqa: PLW0603 -- a counter for the whole run
    _next_me = _next_me + 1 if _next_me < 0o477 else 0o402
    sep = "&" if "?" in url else "?"
    conn = await open_connection(f"{url}{sep}me={_next_me:o}", timeout=10.0)
    if greeting:
        await conn.receive()  # the initial RESPONSE
    return conn


async def one_at_a_time(conn: ChaosConnection, n: int) -> list[float]:
    clock = time.perf_counter
    out = []
    for _ in range(n):
        t0 = clock()
        await conn.send(b"", HERE)
        await conn.receive()
        out.append(clock() - t0)
    return out


async def pipelined(conn: ChaosConnection, n: int) -> list[float]:
    clock = time.perf_counter
    sent: list[float] = []

    async def sender() -> None:
        for _ in range(n):
            sent.append(clock())
            await conn.send(b"", HERE)  # waits while the window (15) is full

    task = asyncio.create_task(sender())
    out = []
    for i in range(n):
        await conn.receive()
        out.append(clock() - sent[i])
    await task
    return out


Pattern = Callable[[ChaosConnection, int], Awaitable[list[float]]]


@dataclass
class Result:
    rate: float
    p50: float
    p99: float
    cpu_per_request: float

    @property
    def per_core(self) -> float:
        return 1.0 / self.cpu_per_request if self.cpu_per_request > 0 else float("inf")


def _pct(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


async def scenario(child: Child, url: str, greeting: bool, clients: int, n: int, pattern: Pattern) -> Result:
    conns = [await _connect(url, greeting) for _ in range(clients)]
    for conn in conns:  # warm up
        await pattern(conn, 50)
    before = child.mark()
    t0 = time.perf_counter()
    samples = await asyncio.gather(*(pattern(conn, n) for conn in conns))
    elapsed = time.perf_counter() - t0
    after = child.mark()
    for conn in conns:
        await conn.close()
    total = clients * n
    latencies = [x for s in samples for x in s]
    cpu = (after["cpu"] - before["cpu"]) / total
    return Result(total / elapsed, _pct(latencies, 0.5), _pct(latencies, 0.99), cpu)


def _jitter_line(name: str, lateness: list[float]) -> str:
    if not lateness:
        return f"    {name:34} no servo wake-ups recorded"
    us = [x * 1e6 for x in lateness]
    return (
        f"    {name:34} {len(us):5d} ticks  p50 {_pct(us, 0.5):7.0f} us  p99 {_pct(us, 0.99):7.0f} us"
        f"  max {max(us):7.0f} us  mean {statistics.fmean(us):6.0f} us"
    )


def _thread_timer(seconds: float, period: float = 0.016, spin: float = 0.0011) -> list[float]:
    """Lateness of a plain thread keeping a 62.5 Hz schedule (sleep, then spin): the OS's share."""
    clock = time.perf_counter
    t0 = clock()
    out = []
    k = 1
    while k * period <= seconds:
        due = t0 + k * period
        remaining = due - clock()
        if remaining > spin:
            time.sleep(remaining - spin)
        while clock() < due:
            pass
        out.append(clock() - due)
        k += 1
    return out


async def jitter(child: Child, seconds: float) -> None:
    print(f"\n  servo-tick jitter at 62.5 Hz, time scale 1 ({seconds:g} s each; lateness of each wake-up)")
    idle = await _connect(child.server_url, True)
    start = child.mark()
    # Meanwhile the machine's own timer noise: a thread here sleeping and spinning to the same schedule.
    machine = await asyncio.get_running_loop().run_in_executor(None, _thread_timer, seconds)
    quiet = child.mark()
    print(_jitter_line("baseline: bare timer thread", machine))
    print(_jitter_line("1 client connected, idle", quiet["lateness"]))
    busy_cpu = (quiet["cpu"] - start["cpu"]) / seconds
    print(
        f"    (server CPU while a client is connected and idle: {busy_cpu:.1%} of a core, the servo's spin)"
    )
    await idle.close()

    conns = [await _connect(child.server_url, True) for _ in range(CLIENTS)]
    stop = time.perf_counter() + seconds
    count = 0

    async def hammer(conn: ChaosConnection) -> None:
        nonlocal count
        while time.perf_counter() < stop:
            await pipelined(conn, 200)
            count += 200

    child.mark()
    t0 = time.perf_counter()
    await asyncio.gather(*(hammer(c) for c in conns))
    elapsed = time.perf_counter() - t0
    busy = child.mark()
    print(_jitter_line(f"{CLIENTS} clients pipelining Here", busy["lateness"]))
    print(f"    (meanwhile {count / elapsed:,.0f} Here/s; late by more than a period: {busy['late_ticks']})")
    for conn in conns:
        await conn.close()


def _median(results: list[Result]) -> Result:
    return Result(
        statistics.median(r.rate for r in results),
        statistics.median(r.p50 for r in results),
        statistics.median(r.p99 for r in results),
        statistics.median(r.cpu_per_request for r in results),
    )


async def parent(ns: argparse.Namespace) -> None:
    child = Child(ns.profile)
    try:
        print(f"reference server {child.server_url}, baseline NCP echo {child.echo_url}")
        print(
            f"  Here requests: {ns.requests} per scenario (split over the clients), {ns.rounds} rounds"
            " alternating baseline and server; medians of the rounds; server CPU from the server process\n"
        )
        header = f"    {'':26} {'req/s':>9} {'p50 us':>8} {'p99 us':>8} {'CPU us/req':>10} {'req/s/core':>10}"
        patterns: list[tuple[str, Pattern]] = [("one at a time", one_at_a_time), ("pipelined", pipelined)]
        targets = (
            ("NCP echo (baseline)", child.echo_url, False),
            ("manip-server Here", child.server_url, True),
        )
        for clients in (1, CLIENTS):
            for label, pattern in patterns:
                print(f"  {clients} client(s), {label}")
                print(header)
                rounds: dict[str, list[Result]] = {name: [] for name, _, _ in targets}
                for _ in range(ns.rounds):
                    for name, url, greeting in targets:
                        n = ns.requests // clients
                        rounds[name].append(await scenario(child, url, greeting, clients, n, pattern))
                results = {name: _median(rs) for name, rs in rounds.items()}
                for name, r in results.items():
                    print(
                        f"    {name:26} {r.rate:9,.0f} {r.p50 * 1e6:8.0f} {r.p99 * 1e6:8.0f}"
                        f" {r.cpu_per_request * 1e6:10.1f} {r.per_core:10,.0f}"
                    )
                base, ours = results["NCP echo (baseline)"], results["manip-server Here"]
                print(
                    f"    server/baseline: req/s {ours.rate / base.rate:.2f}x, "
                    f"CPU per request {ours.cpu_per_request / base.cpu_per_request:.2f}x\n"
                )
        await jitter(child, ns.jitter_seconds)
        final = child.mark()
        print(f"\n  server driver errors: {final['driver_errors']}")
        print("  targets: >= 10,000 Here/s on one core (req/s/core column); tick jitter p99 <= 1000 us")
    finally:
        child.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--requests", type=int, default=4000, help="requests per scenario (split over clients)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds per scenario (medians are printed)")
    ap.add_argument("--jitter-seconds", type=float, default=5.0)
    ap.add_argument("--profile", action="store_true", help="profile the server process (printed on stderr)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ns = ap.parse_args()
    if ns.child:
        child_main(ns.profile)
    else:
        asyncio.run(parent(ns))


if __name__ == "__main__":
    main()
