"""NCP driver benchmark (run by hand): request/response over manip's TCP link against a raw TCP echo.

A round trip is the manip client's common case: send one 66-byte data packet and wait for the server's
66-byte answer.  The baseline is a bare asyncio TCP echo of the same framed bytes (2 + 16 + 66 + 6 = 90),
measured in the same run with rounds alternating between the two (and which of the two goes first), so
that machine load hits both alike; the rounds are split into trials and the median of the per-trial
ratios is printed too, with their spread, because a shared machine's load comes and goes.
Then sustained one-way throughput: 66-byte packets/s from a client to a server that reads them as fast as
it can, through the Chaos window (the client ends with a marker packet the server answers, so the time
covers delivery of everything).

Two placements, both by default: ``same`` runs servers and client on one event loop (every microsecond
of both sides is on the path), ``split`` runs the servers in a child process (client and server are
separate programs in real use, so this is the realistic one).

    .venv/bin/python bench/ncp.py [--mode same|split|both] [--rounds 5000] [--trials 5] [--packets 20000]
                                  [--window 15]

Target: NCP p50 round trip at most 2x the raw echo's.  Figures only; nothing is asserted.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import statistics
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from manip.codecs.framing import encode_tcp
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, ChaosServer, NcpConfig, open_connection, start_server
from manip.links.stream import StreamLink

PAYLOAD = bytes(range(66))
FRAME = encode_tcp(Packet(0o200, 0o440, 0x101, 0o401, 0x201, 2, 1, PAYLOAD))
MARKER = 0o201
"""Opcode of the packet that ends a throughput run; the sink answers it with its count."""


class _Echo(asyncio.Protocol):
    """Raw baseline server: send every complete frame straight back."""

    def __init__(self) -> None:
        self.transport: asyncio.Transport | None = None
        self.buf = bytearray()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        buf = self.buf
        buf += data
        size = len(FRAME)
        while len(buf) >= size:
            assert self.transport is not None
            self.transport.write(bytes(buf[:size]))
            del buf[:size]


class _HopEcho(_Echo):
    """The raw echo, but each frame is answered by a task woken for it, as a server handler is: the
    asyncio hop that any connection object with an ``await receive()`` puts on the server's path."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        super().connection_made(transport)
        self.frames: asyncio.Queue[bytes] = asyncio.Queue()
        self.task = asyncio.get_running_loop().create_task(self._answer())

    async def _answer(self) -> None:
        while True:
            frame = await self.frames.get()
            assert self.transport is not None
            self.transport.write(frame)

    def data_received(self, data: bytes) -> None:
        buf = self.buf
        buf += data
        size = len(FRAME)
        while len(buf) >= size:
            self.frames.put_nowait(bytes(buf[:size]))
            del buf[:size]

    def connection_lost(self, exc: Exception | None) -> None:
        self.task.cancel()


class _EchoClient(asyncio.Protocol):
    """Raw baseline client: one frame out, wait for one frame back."""

    def __init__(self) -> None:
        self.transport: asyncio.Transport | None = None
        self.buf = bytearray()
        self.waiter: asyncio.Future[None] | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        self.buf += data
        if len(self.buf) >= len(FRAME) and self.waiter is not None and not self.waiter.done():
            del self.buf[: len(FRAME)]
            self.waiter.set_result(None)

    async def round_trip(self) -> None:
        assert self.transport is not None
        self.waiter = asyncio.get_running_loop().create_future()
        self.transport.write(FRAME)
        await self.waiter


async def _echo_handler(conn: ChaosConnection) -> None:
    async for _packet in conn:
        await conn.send(PAYLOAD)


async def _sink_handler(conn: ChaosConnection) -> None:
    count = 0
    async for packet in conn:
        if packet.opcode == MARKER:
            await conn.send(count.to_bytes(4, "big"))
            count = 0
        else:
            count += 1


@dataclass
class Servers:
    raw_port: int
    echo_port: int
    sink_port: int
    hop_port: int


@dataclass
class Running:
    """The servers of one placement: the raw and hop echoes, the NCP echo and the sink."""

    ports: Servers
    raw: list[asyncio.Server]
    chaos: list[ChaosServer]

    async def aclose(self) -> None:
        for server in self.chaos:
            await server.aclose()
        for raw in self.raw:
            raw.close()


async def _start_servers(options: NcpConfig) -> Running:
    loop = asyncio.get_running_loop()
    raw = await loop.create_server(_Echo, "127.0.0.1", 0)
    hop = await loop.create_server(_HopEcho, "127.0.0.1", 0)
    echo = await start_server("tcp://127.0.0.1:0", "ECHO", _echo_handler, options=options)
    sink = await start_server("tcp://127.0.0.1:0", "SINK", _sink_handler, options=options)
    raw_port, hop_port = (server.sockets[0].getsockname()[1] for server in (raw, hop))
    return Running(Servers(raw_port, echo.port, sink.port, hop_port), [raw, hop], [echo, sink])


@contextlib.contextmanager
def timed_server_work(server_ports: set[int]) -> Iterator[dict[str, list[float]]]:
    """Time the servers' own work per packet in this process, in seconds: ``raw``, the raw echo's
    ``data_received`` (read to written); ``ncp``, an NCP server link's ``data_received`` to the return of
    the ``send`` that answers it (decode, NCP, the task hop to the handler, encode, write), on links whose
    local port is in ``server_ports`` (filled in by the caller once the servers listen).  The same code
    timed in one event loop and across processes tells what a process's wake-up does to it."""
    work: dict[str, list[float]] = {"raw": [], "ncp": []}
    clock = time.perf_counter
    received, sent, raw_received = StreamLink.data_received, StreamLink.send, _Echo.data_received
    started: dict[int, float] = {}

    def data_received(link: StreamLink, data: bytes) -> None:
        transport = link.transport
        if transport is not None and transport.get_extra_info("sockname")[1] in server_ports:
            started[id(link)] = clock()
        received(link, data)

    def send(link: StreamLink, packet: Packet, next_hop: int | None = None) -> bool:
        ok = sent(link, packet, next_hop)
        t0 = started.pop(id(link), None)
        if t0 is not None and len(packet.data) == len(PAYLOAD):
            work["ncp"].append(clock() - t0)
        return ok

    def echo_received(echo: _Echo, data: bytes) -> None:
        t0 = clock()
        raw_received(echo, data)
        work["raw"].append(clock() - t0)

    wrappers: dict[tuple[type, str], Callable[..., Any]] = {
        (StreamLink, "data_received"): data_received,
        (StreamLink, "send"): send,
        (_Echo, "data_received"): echo_received,
    }
    originals = {(cls, name): getattr(cls, name) for cls, name in wrappers}
    for (cls, name), wrapper in wrappers.items():
        setattr(cls, name, wrapper)
    try:
        yield work
    finally:
        for (cls, name), original in originals.items():
            setattr(cls, name, original)


def _timing(timed: bool, listening: set[int]) -> contextlib.AbstractContextManager[dict[str, list[float]]]:
    return timed_server_work(listening) if timed else contextlib.nullcontext({})


async def _serve_until_stdin_closes(options: NcpConfig, timed: bool) -> None:
    """The child process of ``split`` mode: print the ports, serve until the parent closes stdin; with
    ``timed``, then print the median server work per packet (:func:`timed_server_work`) as JSON."""
    listening: set[int] = set()
    with _timing(timed, listening) as work:
        running = await _start_servers(options)
        ports = running.ports
        listening.add(ports.echo_port)
        print(ports.raw_port, ports.echo_port, ports.sink_port, ports.hop_port, flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
        await running.aclose()
    if timed:
        print(json.dumps(_medians(work)), flush=True)


def _medians(work: dict[str, list[float]]) -> dict[str, float]:
    return {k: statistics.median(v) for k, v in work.items() if v}


def _percentile(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


@dataclass
class RoundTrips:
    """Round-trip samples in seconds, NCP and raw echo alternating, and the p50 ratio of each trial."""

    ncp: list[float]
    raw: list[float]
    trial_ratios: list[float]

    @property
    def p50_ratio(self) -> float:
        return _percentile(self.ncp, 0.5) / _percentile(self.raw, 0.5)


async def _round_trips(ports: Servers, rounds: int, trials: int, options: NcpConfig) -> None:
    result = await measure_round_trips(ports, rounds, trials, options)
    ncp, base, trial_ratios = result.ncp, result.raw, result.trial_ratios
    print(f"  round trip, 66-byte data packet each way, {len(ncp)} rounds in {trials} trials (microseconds)")
    print(f"    {'':10} {'p50':>8} {'p99':>8} {'mean':>8}")
    for name, samples in (("NCP/TCP", ncp), ("raw echo", base)):
        p50, p99 = _percentile(samples, 0.5), _percentile(samples, 0.99)
        print(f"    {name:10} {p50 * 1e6:8.1f} {p99 * 1e6:8.1f} {statistics.fmean(samples) * 1e6:8.1f}")
    ratio99 = _percentile(ncp, 0.99) / _percentile(base, 0.99)
    print(f"    ratio NCP/raw: p50 {result.p50_ratio:.2f}x, p99 {ratio99:.2f}x (target p50 <= 2x)")
    spread = ", ".join(f"{r:.2f}" for r in sorted(trial_ratios))
    print(f"    p50 ratio per trial: median {statistics.median(trial_ratios):.2f}x ({spread})")


async def measure_round_trips(ports: Servers, rounds: int, trials: int, options: NcpConfig) -> RoundTrips:
    """``rounds`` round trips of each kind against the servers at ``ports``, after a warm-up."""
    loop = asyncio.get_running_loop()
    transport, raw = await loop.create_connection(_EchoClient, "127.0.0.1", ports.raw_port)
    conn = await open_connection(f"tcp://127.0.0.1:{ports.echo_port}?contact=ECHO", options=options)

    async def ncp_round_trip() -> None:
        await conn.send(PAYLOAD)
        await conn.receive()

    async with conn:
        ncp: list[float] = []
        base: list[float] = []
        trial_ratios: list[float] = []
        for _ in range(max(100, rounds // 10)):  # warm up both paths
            await ncp_round_trip()
            await raw.round_trip()
        clock = time.perf_counter
        per_trial = max(1, rounds // trials)
        for _ in range(trials):
            ncp_t: list[float] = []
            base_t: list[float] = []
            for i in range(per_trial):
                # Alternate which goes first, so neither always runs right after the other's work.
                first, second = (
                    (ncp_round_trip, raw.round_trip) if i & 1 else (raw.round_trip, ncp_round_trip)
                )
                t0 = clock()
                await first()
                t1 = clock()
                await second()
                t2 = clock()
                a, b = (ncp_t, base_t) if i & 1 else (base_t, ncp_t)
                a.append(t1 - t0)
                b.append(t2 - t1)
            trial_ratios.append(statistics.median(ncp_t) / statistics.median(base_t))
            ncp += ncp_t
            base += base_t
    transport.close()
    return RoundTrips(ncp, base, trial_ratios)


async def _throughput(ports: Servers, packets: int, options: NcpConfig) -> None:
    conn = await open_connection(f"tcp://127.0.0.1:{ports.sink_port}?contact=SINK", options=options)
    async with conn:
        t0 = time.perf_counter()
        for _ in range(packets):
            await conn.send(PAYLOAD)
        await conn.send(b"", MARKER)
        count = int.from_bytes((await conn.receive()).data, "big")
        elapsed = time.perf_counter() - t0
        waits = conn.stats.send_waits
    assert count == packets, (count, packets)
    rate = packets / elapsed
    print(f"  one-way, {packets} packets of 66 bytes, window {options.window}:")
    mb = rate * len(PAYLOAD) / 1e6
    print(f"    {rate:,.0f} packets/s ({mb:.2f} MB/s of data); the sender waited {waits} times")


async def hop_bound(rounds: int, ports: Servers | None = None) -> tuple[float, float]:
    """p50 round trips (s) of the raw echo and of the same echo answering from a task, alternating: what
    one task hop per packet costs, before any protocol work.  Servers on this loop, or at ``ports``."""
    loop = asyncio.get_running_loop()
    running = await _start_servers(NcpConfig()) if ports is None else None
    where = running.ports if running is not None else ports
    assert where is not None
    clients = [
        await loop.create_connection(_EchoClient, "127.0.0.1", p) for p in (where.raw_port, where.hop_port)
    ]
    samples: list[list[float]] = [[], []]
    clock = time.perf_counter
    for i in range(rounds + rounds // 10):
        for k in (0, 1) if i & 1 else (1, 0):
            t0 = clock()
            await clients[k][1].round_trip()
            if i >= rounds // 10:  # after a warm-up
                samples[k].append(clock() - t0)
    for transport, _ in clients:
        transport.close()
    if running is not None:
        await running.aclose()
    return statistics.median(samples[0]), statistics.median(samples[1])


@dataclass
class Placement:
    """One placement's round trips, the task-hop bound, and (when timed) the servers' work per packet."""

    trips: RoundTrips
    raw_p50: float
    hop_p50: float
    work: dict[str, float]


async def same_loop_round_trips(
    rounds: int, trials: int, options: NcpConfig, timed: bool = False
) -> Placement:
    """Round trips with client and servers on this event loop (for bench/all.py)."""
    listening: set[int] = set()
    with _timing(timed, listening) as work:
        running = await _start_servers(options)
        listening.add(running.ports.echo_port)
        try:
            trips = await measure_round_trips(running.ports, rounds, trials, options)
        finally:
            await running.aclose()
    raw_p50, hop_p50 = await hop_bound(rounds)
    return Placement(trips, raw_p50, hop_p50, _medians(work))


async def split_round_trips(rounds: int, trials: int, options: NcpConfig, timed: bool = False) -> Placement:
    """Round trips against servers in a child process (for bench/all.py)."""
    child = _serve_in_child(options, timed)
    assert child.stdin is not None and child.stdout is not None
    loop = asyncio.get_running_loop()
    try:
        line = await loop.run_in_executor(None, child.stdout.readline)
        ports = Servers(*map(int, line.split()))
        trips = await measure_round_trips(ports, rounds, trials, options)
        raw_p50, hop_p50 = await hop_bound(rounds, ports)
    finally:
        child.stdin.close()
    work = json.loads(await loop.run_in_executor(None, child.stdout.readline) or "{}") if timed else {}
    child.wait(timeout=10)
    return Placement(trips, raw_p50, hop_p50, work)


def _serve_in_child(options: NcpConfig, timed: bool = False) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, __file__, "--serve", "--window", str(options.window)]
        + (["--timed"] if timed else []),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )


async def _same(ns: argparse.Namespace, options: NcpConfig) -> None:
    running = await _start_servers(options)
    try:
        await _round_trips(running.ports, ns.rounds, ns.trials, options)
        await _throughput(running.ports, ns.packets, options)
    finally:
        await running.aclose()


async def _split(ns: argparse.Namespace, options: NcpConfig) -> None:
    child = _serve_in_child(options)
    assert child.stdin is not None and child.stdout is not None
    try:
        line = await asyncio.get_running_loop().run_in_executor(None, child.stdout.readline)
        ports = Servers(*map(int, line.split()))
        await _round_trips(ports, ns.rounds, ns.trials, options)
        await _throughput(ports, ns.packets, options)
    finally:
        child.stdin.close()
        child.wait(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--mode", choices=("same", "split", "both"), default="both")
    parser.add_argument("--rounds", type=int, default=5000)
    parser.add_argument("--trials", type=int, default=5, help="the rounds are split into this many trials")
    parser.add_argument("--packets", type=int, default=20000)
    parser.add_argument("--window", type=int, default=15)
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--timed", action="store_true", help=argparse.SUPPRESS)
    ns = parser.parse_args()
    options = NcpConfig(window=ns.window)
    if ns.serve:
        asyncio.run(_serve_until_stdin_closes(options, ns.timed))
        return
    print(f"Python {sys.version.split()[0]}, {sys.platform}")
    if ns.mode in ("same", "both"):
        print("same process (client and servers on one event loop):")
        asyncio.run(_same(ns, options))
    if ns.mode in ("split", "both"):
        print("split (servers in a child process):")
        asyncio.run(_split(ns, options))


if __name__ == "__main__":
    main()
