"""Every benchmark figure of issue 17, briefly, in one table (run by hand): where the project stands.

Each figure is measured against a baseline in the same run (rounds alternate between manip and the
baseline, so machine load hits both alike) and printed as one row: figure, manip, baseline, ratio, goal,
met.  A few figures have an absolute goal (frames/s, MB, seconds) and no baseline.  The table is also
written as JSON (``--json``).  The long runs stay in each benchmark's own script (bench/codec_speed.py,
floats.py, ncp.py, server.py, capture.py); this one takes a second or a few per figure.

    .venv/bin/python bench/all.py [--seconds 1.0] [--only NAME ...] [--tests] [--json PATH]

``--tests`` also times the README's test command (minutes); without it that row says "not run".
Nothing here asserts a timing.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import re
import shlex
import statistics
import struct
import subprocess
import sys
import tempfile
import time
import timeit
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

import capture as capture_bench
import codec_speed
import ncp as ncp_bench
import server as server_bench
from manip.captures.view import Annotation, Annotator, view_bytes
from manip.codecs.framing import decode_tcp
from manip.codecs.packet import Direction
from manip.codecs.pdp11float import pack_f, pack_f_array, unpack_f
from manip.decode.describe import describe_packet, packet_json
from manip.links import NcpConfig
from manip.reference_server import ServerConfig
from manip.reference_server.session import ServerSession
from manip.spec.constants import RequestOp

ROOT = Path(__file__).resolve().parent.parent
BIN = Path(sys.executable).parent


@dataclass
class Row:
    """One figure.  ``ratio`` is manip against the baseline in the goal's sense (None: absolute goal)."""

    name: str
    figure: str
    manip: float
    baseline: float | None
    unit: str
    ratio: float | None
    goal: float
    at_least: bool
    """True: the goal is a floor (>=); False: a ceiling (<=)."""
    note: str = ""

    @property
    def value(self) -> float:
        return self.ratio if self.ratio is not None else self.manip

    @property
    def met(self) -> bool:
        return self.value >= self.goal if self.at_least else self.value <= self.goal


# ----------------------------------------------------------------------------------- the figures


def codec_rows(seconds: float) -> list[Row]:
    wire = codec_speed.manip_encode(7, codec_speed.TRANSFORM)
    assert wire == codec_speed.baseline_encode(7, codec_speed.TRANSFORM)
    enc, enc_base = codec_speed.rates(
        lambda: codec_speed.manip_encode(7, codec_speed.TRANSFORM),
        lambda: codec_speed.baseline_encode(7, codec_speed.TRANSFORM),
        seconds,
    )
    dec, dec_base = codec_speed.rates(
        lambda: codec_speed.manip_decode(wire), lambda: codec_speed.baseline_decode(wire), seconds
    )
    return [
        Row(
            "encode",
            "encode Here response (66 bytes) vs struct",
            enc,
            enc_base,
            "/s",
            enc / enc_base,
            0.6,
            True,
        ),
        Row("decode", "decode Here response vs struct", dec, dec_base, "/s", dec / dec_base, 0.8, True),
    ]


def scalar_float_rows(seconds: float) -> list[Row]:
    rng = np.random.default_rng(1985)
    values = rng.uniform(-1000.0, 1000.0, 1000)
    values[::7] = 0.0  # transforms are full of zeros
    xs = [float(v) for v in values]
    raw, ieee = pack_f_array(values), values.astype("<f4").tobytes()
    offsets = range(0, 4 * len(xs), 4)
    f32 = struct.Struct("<f")  # the calls are spelt as in bench/floats.py, which the figures are from
    pack, base_pack = codec_speed.rates(
        lambda: b"".join([pack_f(x) for x in xs]), lambda: b"".join([f32.pack(x) for x in xs]), seconds
    )
    unpack, base_unpack = codec_speed.rates(
        lambda: [unpack_f(raw, o) for o in offsets],
        lambda: [f32.unpack_from(ieee, o)[0] for o in offsets],
        seconds,
    )
    # The bound: pack_f's fast path with none of its checks (type, policy, range), one '<ff' pack and a
    # slice in a Python function; it gives wrong bytes outside the range, so it is only a yardstick.
    twice = struct.Struct("<ff").pack

    def bare(x: float) -> bytes:
        y = x * 4.0
        return twice(y, y)[2:6]

    bare_rate, base_bare = codec_speed.rates(
        lambda: b"".join([bare(x) for x in xs]), lambda: b"".join([f32.pack(x) for x in xs]), seconds
    )
    n = len(xs)
    return [
        Row(
            "pack_f",
            "scalar pack_f vs struct '<f' pack",
            pack * n,
            base_pack * n,
            "floats/s",
            pack / base_pack,
            0.3,
            True,
            f"bound: the fast path alone, unchecked: {bare_rate / base_bare:.2f}x",
        ),
        Row(
            "unpack_f",
            "scalar unpack_f vs struct '<f' unpack_from",
            unpack * n,
            base_unpack * n,
            "floats/s",
            unpack / base_unpack,
            0.3,
            True,
        ),
    ]


def ncp_rows(rounds: int) -> list[Row]:
    options = NcpConfig()
    split = asyncio.run(ncp_bench.split_round_trips(rounds, 5, options))
    same = asyncio.run(ncp_bench.same_loop_round_trips(rounds, 5, options))
    # The bound: the servers' own work per packet, the same code timed in one loop and across processes
    # (separate runs: the timing itself costs a little).
    timed_split = asyncio.run(ncp_bench.split_round_trips(rounds // 2, 1, options, timed=True))
    timed_same = asyncio.run(ncp_bench.same_loop_round_trips(rounds // 2, 1, options, timed=True))
    rows = []
    for name, figure, placement, goal in (
        ("ncp-split", "NCP round trip p50, separate processes, vs raw echo", split, 1.3),
        ("ncp-same", "NCP round trip p50, one event loop, vs raw echo", same, 2.5),
    ):
        result = placement.trips
        ncp_p50, raw_p50 = statistics.median(result.ncp) * 1e6, statistics.median(result.raw) * 1e6
        trials = ", ".join(f"{r:.2f}" for r in sorted(result.trial_ratios))
        hop = placement.hop_p50 / placement.raw_p50
        note = (
            f"trials {trials}; bound: the raw echo answering from a task (one asyncio hop) is {hop:.2f}x raw"
        )
        if name == "ncp-split":
            note += "; " + _wake_bound(timed_same, timed_split, raw_p50, goal)
        rows.append(Row(name, figure, ncp_p50, raw_p50, "us", result.p50_ratio, goal, False, note))
    return rows


def _wake_bound(same: ncp_bench.Placement, split: ncp_bench.Placement, raw_p50: float, goal: float) -> str:
    """Why the split figure misses: a process woken for each packet runs the same code k times slower."""
    ncp_same, ncp_split = same.work["ncp"] * 1e6, split.work["ncp"] * 1e6
    raw_same, raw_split = same.work["raw"] * 1e6, split.work["raw"] * 1e6
    k = ncp_split / ncp_same
    extra_same = (statistics.median(same.trips.ncp) - statistics.median(same.trips.raw)) * 1e6
    allowed = (goal - 1) * raw_p50
    return (
        f"the server's own work per packet, the same code, is {ncp_same:.1f} us (NCP) and {raw_same:.1f} us"
        f" (raw) in one loop but {ncp_split:.1f} and {raw_split:.1f} us across processes ({k:.1f}x, the"
        f" wake-up); {goal}x allows {allowed:.0f} us over raw for both processes, {allowed / k:.1f} us of"
        f" one-loop work at that factor, and the NCP adds {extra_same:.1f} us in one loop"
    )


def session_here_seconds(count: int = 20000) -> float:
    """CPU seconds per Here of the reference server's sans-I/O session alone (best of three)."""
    session = ServerSession(ServerConfig(powered_at_open=True))
    now = 1000.0
    session.on_open(now, 1)
    best = math.inf
    for _ in range(3):
        start = time.process_time()
        for number in range(2, count + 2):
            now += 1e-4
            session.on_request(now, RequestOp.HERE, number & 0xFFFF, b"", number - 1)
        best = min(best, (time.process_time() - start) / count)
    return best


def server_rows(requests: int, rounds: int) -> list[Row]:
    async def measure() -> tuple[list[server_bench.Result], list[server_bench.Result], float]:
        child = server_bench.Child(False)
        ours: list[server_bench.Result] = []
        base: list[server_bench.Result] = []
        try:
            for _ in range(rounds):
                clients = server_bench.CLIENTS
                n = requests // clients
                pattern = server_bench.one_at_a_time
                base.append(await server_bench.scenario(child, child.echo_url, False, clients, n, pattern))
                ours.append(await server_bench.scenario(child, child.server_url, True, clients, n, pattern))
            # The servo's CPU with one silent client: its spin before each tick, paid per second.
            idle = await server_bench._connect(child.server_url, True)
            before = child.mark()
            started = time.perf_counter()
            await asyncio.sleep(1.0)
            servo = (child.mark()["cpu"] - before["cpu"]) / (time.perf_counter() - started)
            await idle.close()
        finally:
            child.close()
        return ours, base, servo

    ours, base, servo = asyncio.run(measure())
    rate = statistics.median(r.rate for r in ours)
    cpu = statistics.median(r.cpu_per_request for r in ours) * 1e6
    cpu_base = statistics.median(r.cpu_per_request for r in base) * 1e6
    session = session_here_seconds() * 1e6
    bound = f"bound: the session alone costs {session:.1f} us CPU per Here ({session / cpu_base:.2f}x echo)"
    return [
        Row(
            "server-cpu",
            "manip-server Here, server CPU per request vs NCP echo server, 8 clients one at a time",
            cpu,
            cpu_base,
            "us CPU",
            cpu / cpu_base,
            1.3,
            False,
            f"{rate:,.0f} Here/s through the whole path; {bound}; the servo alone (its spin and ticks,"
            f" one silent client) {servo * 1e3:.0f} ms CPU/s, {servo / rate * 1e6:.1f} us per Here here;"
            f" the echo's CPU plus these two alone, timed warm, is already"
            f" {(cpu_base + session + servo / rate * 1e6) / cpu_base:.2f}x the echo",
        )
    ]


def capture_rows(packets: int, trials: int) -> list[Row]:
    frames = capture_bench.workload(packets)
    sample = capture_bench.manip_record(frames, True)
    views, arms = capture_bench.views_of(sample), capture_bench.arm_of(sample)
    times = capture_bench.best(
        trials,
        {
            "manip": lambda: capture_bench.manip_record(frames, True),
            "raw": lambda: capture_bench.raw_record(frames, views, True, arms=arms),
            "appender": lambda: capture_bench.raw_record(frames, views, True, lean=True, arms=arms),
        },
    )
    n = len(frames)
    own, written, raw = (times["manip"] - times["appender"]) / n, times["appender"] / n, times["raw"] / n
    decode, annotate, view = _capture_parts(frames)
    note = (
        f"bound: manip's own work (decode, annotate, JSON view) {own * 1e6:.1f} us/frame + writing both"
        f" messages {written * 1e6:.1f} us vs the raw writer's {raw * 1e6:.1f} us: 1x leaves"
        f" {(raw - written) * 1e6:.1f} us for the own work, against {decode * 1e6:.1f} us to decode the"
        f" frame, {annotate * 1e6:.1f} us to pair and annotate it and {view * 1e6:.1f} us to write its"
        " view's JSON (each timed alone)"
    )
    return [
        Row(
            "capture",
            "capture: record with the decoded view vs raw mcap writer writing the JSON view",
            n / times["manip"],
            n / times["raw"],
            "frames/s",
            times["raw"] / times["manip"],
            1.0,
            True,
            note,
        )
    ]


def _capture_parts(frames: list[tuple[str, bytes]]) -> tuple[float, float, float]:
    """CPU seconds per frame of the recorder's three steps, each alone: decode, annotate, view JSON."""
    directions = [cast(Direction, direction) for direction, _ in frames]
    wires = [frame for _, frame in frames]
    packets = [decode_tcp(w) for w in wires]

    def per_frame(work: Callable[[], object]) -> float:
        return min(timeit.Timer(work, timer=time.process_time).repeat(3, 1)) / len(frames)

    def annotate_all() -> list[Annotation]:
        annotate = Annotator().annotate
        return [annotate(1, d, p) for d, p in zip(directions, packets, strict=True)]

    notes = annotate_all()
    rows = list(zip(notes, directions, packets, strict=True))
    return (
        per_frame(lambda: [decode_tcp(w) for w in wires]),
        per_frame(annotate_all),
        per_frame(lambda: [view_bytes(a, 1, d, i, p, len(p.data)) for i, (a, d, p) in enumerate(rows)]),
    )


# The child's peak RSS is read by a small launcher process, not here: Linux carries ru_maxrss across
# execve, and subprocess starts children with vfork, so a child's own ru_maxrss starts at this process's
# high-water mark (the workloads above, numpy, mcap: ~90 MB), whatever the child does.  The launcher is a
# bare Python (~10 MB) that forks the command and reports the command's ru_maxrss on its stdout.
_LAUNCHER = """
import os, sys
pid = os.fork()
if pid == 0:
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    os.dup2(os.open(os.devnull, os.O_WRONLY), 2)
    try:
        os.execv(sys.argv[1], sys.argv[1:])
    finally:
        os._exit(127)
_, status, usage = os.wait4(pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss * 1024)
"""


def _run_measured(
    cmd: list[str], *, stdin: Path | None = None, cwd: Path | None = None
) -> tuple[float, int, int]:
    """Wall seconds, exit status and peak RSS (bytes) of a child process (its output is discarded)."""
    with open(stdin or os.devnull, "rb") as source:
        start = time.perf_counter()
        report = subprocess.run(
            [sys.executable, "-S", "-c", _LAUNCHER, *cmd],
            stdin=source,
            stdout=subprocess.PIPE,
            cwd=cwd,
            check=True,
        ).stdout
        elapsed = time.perf_counter() - start
    code, rss = (int(x) for x in report.split())
    return elapsed, code, rss


def decode_rows(frames: int) -> list[Row]:
    """manip-decode streaming TCP-link frames to JSON, at two input sizes (RSS must not grow with them)."""
    results = []
    with tempfile.TemporaryDirectory(prefix="manip-bench-") as tmp:
        for count in (frames, 4 * frames):
            path = Path(tmp) / f"stream-{count}.bin"
            path.write_bytes(b"".join(frame for _, frame in capture_bench.workload(count)))
            cmd = [str(BIN / "manip-decode"), "--link", "tcp", "--format", "json", "-"]
            elapsed, code, rss = _run_measured(cmd, stdin=path)
            results.append((count, path.stat().st_size, elapsed, code, rss))
    small_rss = results[0][4]
    count, size, elapsed, code, rss = results[1]
    # The bounds: starting Python and importing the decoder, and writing each frame's JSON alone.
    startup = min(_run_measured([sys.executable, "-c", "import manip.decode.cli"])[0] for _ in range(3))
    packets = [decode_tcp(frame) for _, frame in capture_bench.workload(frames)]
    nodes = [describe_packet(p, header=False) for p in packets]
    pairs = list(zip(nodes, packets, strict=True))

    def cpu_per_frame(work: Callable[[], object]) -> float:
        return min(timeit.Timer(work, timer=time.process_time).repeat(3, 1)) / len(pairs)

    write = cpu_per_frame(lambda: [packet_json(n, p) for n, p in pairs])
    describe = cpu_per_frame(lambda: [describe_packet(p, header=False) for p in packets])
    size_json = statistics.fmean(len(packet_json(n, p)) for n, p in pairs)
    note = (
        f"{size / 1e6:.1f} MB in {elapsed:.1f} s, exit {code}; peak RSS {small_rss / 1e6:.0f} MB at 1/4;"
        f" bound: starting Python and importing the decoder takes {startup:.2f} s"
        f" ({count / max(elapsed - startup, 1e-9):,.0f} frames/s without it); each frame's tree is"
        f" {size_json:,.0f} bytes of JSON: describing it takes {describe * 1e6:.1f} us CPU and writing it"
        f" (the header by hand, the rest by the C encoder) {write * 1e6:.1f} us"
        f" ({1 / (describe + write):,.0f} frames/s if reading and decoding were free)"
        + _faster_json_bound(nodes, packets)
    )
    return [
        Row(
            "decode-rate",
            "manip-decode, TCP-link frames to JSON",
            count / elapsed,
            None,
            "frames/s",
            None,
            100_000,
            True,
            note,
        ),
        Row(
            "decode-rss",
            "manip-decode peak RSS (flat: < 100 MB for any input)",
            rss / 1e6,
            None,
            "MB",
            None,
            100,
            False,
        ),
    ]


def _faster_json_bound(nodes: list[Any], packets: list[Any]) -> str:
    """What a C JSON encoder of the whole tree would take instead, if orjson happens to be installed (it
    is not a dependency: it would not reach the goal, see the note)."""
    try:
        import orjson  # type: ignore[import-not-found]  # noqa: PLC0415  # optional yardstick
    except ImportError:
        return ""
    trees = [describe_packet(p).to_json() for p in packets]
    dump = min(
        timeit.Timer(lambda: [orjson.dumps(t) for t in trees], timer=time.process_time).repeat(3, 1)
    ) / len(trees)
    build = min(
        timeit.Timer(lambda: [n.to_json() for n in nodes], timer=time.process_time).repeat(3, 1)
    ) / len(nodes)
    return f"; with orjson the writing would take {(dump + build) * 1e6:.1f} us (tree to dicts, then encode)"


def conform_rows() -> list[Row]:
    elapsed, code, _ = _run_measured([str(BIN / "manip-conform"), "run", "-q", "--seed", "1985"])
    return [
        Row(
            "conform",
            "embedded manip-conform run (virtual time)",
            elapsed,
            None,
            "s",
            None,
            10.0,
            False,
            f"exit {code}",
        )
    ]


def readme_test_command() -> list[str]:
    """The pytest part of the README's test command (what .ci/run runs), as arguments."""
    for line in (ROOT / "README.md").read_text().splitlines():
        match = re.search(r"\.venv/bin/python -m pytest(.*)$", line)
        if match:
            return [sys.executable, "-m", "pytest", *shlex.split(match.group(1).strip().rstrip("`"))]
    raise SystemExit("bench/all.py: no pytest command found in README.md")


def test_rows(run: bool) -> list[Row]:
    if not run:
        return [
            Row(
                "tests",
                "the README test command (pytest)",
                float("nan"),
                None,
                "s",
                None,
                150,
                False,
                "not run (--tests)",
            )
        ]
    elapsed, code, _ = _run_measured(readme_test_command(), cwd=ROOT)
    return [
        Row("tests", "the README test command (pytest)", elapsed, None, "s", None, 150, False, f"exit {code}")
    ]


# ----------------------------------------------------------------------------------- the table


def _amount(value: float | None, unit: str) -> str:
    if value is None:
        return "-"
    if math.isnan(value):  # NaN: not measured
        return "-"
    if abs(value) >= 10_000:
        return f"{value:,.0f} {unit}"
    return f"{value:.3g} {unit}" if abs(value) < 100 else f"{value:.0f} {unit}"


def print_table(rows: list[Row]) -> None:
    header = ("figure", "manip", "baseline", "ratio", "goal", "met")
    cells = [
        (
            r.figure,
            _amount(r.manip, r.unit),
            _amount(r.baseline, r.unit),
            "-" if r.ratio is None else f"{r.ratio:.2f}x",
            f"{'>=' if r.at_least else '<='} {r.goal:g}{'x' if r.ratio is not None else ' ' + r.unit}",
            "-" if math.isnan(r.value) else ("yes" if r.met else "NO"),
        )
        for r in rows
    ]
    widths = [max(len(str(c[i])) for c in [header, *cells]) for i in range(len(header))]
    for line in [header, *cells]:
        print(
            "  ".join(
                str(c).ljust(w) if i == 0 else str(c).rjust(w)
                for i, (c, w) in enumerate(zip(line, widths, strict=True))
            )
        )
    for r in rows:
        if r.note:
            print(f"  {r.name}: {r.note}")


FIGURES: dict[str, Callable[[argparse.Namespace], list[Row]]] = {
    "codec": lambda ns: codec_rows(ns.seconds),
    "floats": lambda ns: scalar_float_rows(ns.seconds),
    "ncp": lambda ns: ncp_rows(ns.rounds),
    "server": lambda ns: server_rows(ns.requests, 3),
    "capture": lambda ns: capture_rows(ns.packets, 3),
    "decode": lambda ns: decode_rows(ns.frames),
    "conform": lambda ns: conform_rows(),
    "tests": lambda ns: test_rows(ns.tests),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=1.0, help="per codec and float figure")
    ap.add_argument("--rounds", type=int, default=3000, help="NCP round trips of each kind, per placement")
    ap.add_argument("--requests", type=int, default=4000, help="Here requests per server round")
    ap.add_argument("--packets", type=int, default=10000, help="frames per capture recording")
    ap.add_argument("--frames", type=int, default=10000, help="frames of the smaller manip-decode input")
    ap.add_argument("--only", nargs="+", choices=sorted(FIGURES), help="run only these groups")
    ap.add_argument("--tests", action="store_true", help="also time the README test command (minutes)")
    ap.add_argument(
        "--json", type=Path, default=ROOT / "reports" / "bench-all.json", help="where to write the table"
    )
    ns = ap.parse_args()
    rows: list[Row] = []
    for name in ns.only or list(FIGURES):
        started = time.perf_counter()
        rows += FIGURES[name](ns)
        print(f"[{name}: {time.perf_counter() - started:.1f} s]", file=sys.stderr, flush=True)
    print(f"Python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    print_table(rows)
    ns.json.parent.mkdir(parents=True, exist_ok=True)
    ns.json.write_text(
        json.dumps(
            {
                "python": sys.version.split()[0],
                "load_average": os.getloadavg()[0],
                "figures": [{**asdict(r), "met": None if math.isnan(r.value) else r.met} for r in rows],
            },
            indent=2,
        )
        + "\n"
    )
    print(f"written to {ns.json}")


if __name__ == "__main__":
    main()
