"""A seeded campaign of damaged files against every reader of files manip has: each run must end, in
bounded memory, with either a result or a clear error (never a traceback), and damage inside a capture's
chunks must never be reported as a clean file.

The inputs are made from the golden captures (zstd chunks), the same captures written again with lz4
and uncompressed chunks, their pcapng and pcap exports, and the TCP-link frames they hold, damaged by a
seeded draw of one kind:

* ``flip``: one to eight bits flipped anywhere;
* ``chunk-flip``: bits flipped inside the records of one chunk (its compressed bytes);
* ``invert16``: sixteen bytes inverted inside one chunk's records;
* ``crc``: only a chunk's CRC changed (the data intact);
* ``truncate``: the file cut at a random byte;
* ``huge-length``: a record's (or a pcap packet's) length field made enormous;
* ``garbage``: random bytes, with or without the file's magic in front;
* ``endless``: ``/dev/zero``, a file that never ends.

Each input goes to each reader that takes its kind of file (``manip-capture info``, ``info --json``,
``export``, ``recover``, ``manip-decode --mcap``, ``manip-conform verify`` and ``replay`` (against the
embedded server); ``manip-capture import`` and
``manip-decode --pcap``; ``manip-decode`` with each link framing and as hex text), in this process by
click's test runner (a wall-clock alarm catches a hang; the address space is limited, so a runaway
allocation becomes a MemoryError rather than a swapping machine), or with ``--processes`` as real
processes whose peak resident memory is measured.  Outcomes:

* ``ok``: exit 0 on a file the reader could read (or damage it cannot see, such as a flipped byte of a
  message's payload in a pcap);
* ``rejected``: a documented non-zero exit status with a message on stderr;
* ``silent``: exit 0 although the damage was inside a chunk's records or CRC (a damaged file passed as
  fine; ``recover`` saying "the file was complete" counts too);
* ``traceback``: an exception escaped (a traceback, or "internal error");
* ``hang``: no end within ``--timeout`` seconds;
* ``memory``: a MemoryError, or (real processes) a peak resident set over ``--rss-mb``.

The campaign fails (exit 1) on any ``silent``, ``traceback``, ``hang`` or ``memory`` outcome.

    .venv/bin/python tools/damaged_files.py --seed 1 --inputs 400
    .venv/bin/python tools/damaged_files.py --seed 1 --inputs 40 --processes
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import random
import resource
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import dpkt
from click.testing import CliRunner
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

import manip.captures.cli
import manip.conformance.cli
import manip.decode.cli
from campaign_tally import tally
from manip.captures.pcap import export_pcapng
from manip.captures.reader import iter_packets

ROOT: Final = Path(__file__).resolve().parent.parent
GOLDEN: Final = ("describe-self.mcap", "errors.mcap", "motion.mcap")
OUTCOMES: Final = ("ok", "rejected", "streaming", "skipped", "silent", "traceback", "hang", "memory")
BAD: Final = frozenset({"silent", "traceback", "hang", "memory"})
KINDS: Final = ("flip", "chunk-flip", "invert16", "crc", "truncate", "huge-length", "garbage", "endless")
_MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
_CHUNK: Final = 0x06
ENDLESS: Final = "/dev/zero"
_STREAMS: Final = frozenset({"stream", "hex"})
"""Families decoded as a stream: an endless input is decoded endlessly (in flat memory), not an error."""


@dataclass(frozen=True, slots=True)
class Input:
    """One damaged file: what it was made from, how, and whether the damage is inside chunk records."""

    name: str
    family: str
    """mcap, pcap or stream (a stream of TCP-link frames) or hex (the same as hex text)."""
    kind: str
    data: bytes | None
    """None for the endless input (read from ``/dev/zero``)."""
    in_chunk: bool = False


@dataclass(frozen=True, slots=True)
class Reader:
    """A command that reads one family of file: its program and argument list for a path and a scratch
    directory, and whether exit 0 on damage inside a chunk is a silent acceptance."""

    name: str
    family: str
    program: str
    args: Callable[[str, str], list[str]]
    judges_chunks: bool = True


READERS: Final = (
    Reader("capture-info", "mcap", "manip-capture", lambda f, d: ["info", f]),
    Reader("capture-info-json", "mcap", "manip-capture", lambda f, d: ["info", "--json", f]),
    Reader("capture-export", "mcap", "manip-capture", lambda f, d: ["export", f, "-o", f"{d}/out.pcapng"]),
    Reader(
        "capture-recover", "mcap", "manip-capture", lambda f, d: ["recover", f, "-o", f"{d}/out.mcap"], False
    ),
    Reader("decode-mcap", "mcap", "manip-decode", lambda f, d: ["--mcap", f]),
    Reader("verify", "mcap", "manip-conform", lambda f, d: ["verify", f, "-q"]),
    Reader("replay", "mcap", "manip-conform", lambda f, d: ["replay", f, "-q"]),
    Reader(
        "capture-import", "pcap", "manip-capture", lambda f, d: ["import", f, "-o", f"{d}/in.mcap"], False
    ),
    Reader("decode-pcap", "pcap", "manip-decode", lambda f, d: ["--pcap", f], False),
    Reader("decode-tcp", "stream", "manip-decode", lambda f, d: ["--link", "tcp", "--binary", f], False),
    Reader(
        "decode-chaosd", "stream", "manip-decode", lambda f, d: ["--link", "chaosd", "--binary", f], False
    ),
    Reader("decode-raw", "stream", "manip-decode", lambda f, d: ["--link", "raw", "--binary", f], False),
    Reader("decode-chudp", "stream", "manip-decode", lambda f, d: ["--link", "chudp", "--binary", f], False),
    Reader("decode-hex", "hex", "manip-decode", lambda f, d: ["--link", "tcp", "--hex", f], False),
    Reader("decode-cougar", "hex", "manip-decode", lambda f, d: ["--cougar", "command", f], False),
)


# ---------------------------------------------------------------------------------------- base files


def _rewrite(source: Path, compression: str) -> bytes:
    """A golden capture written again with another chunk compression (same records)."""

    kinds = {"lz4": CompressionType.LZ4, "none": CompressionType.NONE}
    out = io.BytesIO()
    with source.open("rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        assert summary is not None
        writer = Writer(out, compression=kinds[compression], chunk_size=4096)
        writer.start(profile=header.profile, library=header.library)
        schemas = {
            sid: writer.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()
        }
        channels = {
            cid: writer.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0), c.metadata)
            for cid, c in summary.channels.items()
        }
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            writer.add_message(
                channels[channel.id], message.log_time, message.data, message.publish_time, message.sequence
            )
        for metadata in reader.iter_metadata():
            writer.add_metadata(metadata.name, metadata.metadata)
        writer.finish()  # type: ignore[no-untyped-call]
    return out.getvalue()


def _pcaps(mcap: Path, scratch: Path) -> list[tuple[str, bytes]]:
    """The capture as pcapng (manip-capture export) and as classic pcap (the same datagrams)."""

    out = scratch / f"{mcap.stem}.pcapng"
    export_pcapng(mcap, out)
    classic = io.BytesIO()
    writer = dpkt.pcap.Writer(classic, linktype=101)
    with out.open("rb") as f:
        for ts, frame in dpkt.pcapng.Reader(f):
            writer.writepkt(frame, ts)
    return [(f"{mcap.stem}.pcapng", out.read_bytes()), (f"{mcap.stem}.pcap", classic.getvalue())]


def _frames(mcap: Path) -> bytes:
    """The TCP-link frames of a capture, one after another (what manip-decode --link tcp reads)."""

    return b"".join(p.frame for p in iter_packets(mcap))


def base_files(scratch: Path) -> list[tuple[str, str, bytes]]:
    """(name, family, bytes) of every undamaged input."""
    files: list[tuple[str, str, bytes]] = []
    for name in GOLDEN:
        path = ROOT / "captures" / name
        files.append((name, "mcap", path.read_bytes()))
        files.append((f"{path.stem}.lz4.mcap", "mcap", _rewrite(path, "lz4")))
        files.append((f"{path.stem}.none.mcap", "mcap", _rewrite(path, "none")))
        files.extend((n, "pcap", b) for n, b in _pcaps(path, scratch))
        frames = _frames(path)
        files.append((f"{path.stem}.frames", "stream", frames))
        files.append((f"{path.stem}.hex", "hex", frames.hex(" ").encode()))
    return files


# ---------------------------------------------------------------------------------------- damage


def chunk_spans(data: bytes) -> list[tuple[int, int, int]]:
    """(crc offset, records start, records end) of every whole chunk record of an MCAP file."""
    spans = []
    pos = len(_MCAP_MAGIC)
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        body = pos + 9
        if body + length > len(data):
            break
        if opcode == _CHUNK:
            crc_at = body + 24
            (name_len,) = struct.unpack_from("<I", data, crc_at + 4)
            records = crc_at + 8 + name_len + 8
            spans.append((crc_at, records, body + length))
        pos = body + length
    return spans


def _record_starts(data: bytes) -> list[int]:
    starts, pos = [], len(_MCAP_MAGIC)
    while pos + 9 <= len(data):
        starts.append(pos)
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        pos += 9 + length
    return starts


def _flip(data: bytearray, rng: random.Random, lo: int, hi: int, bits: int) -> None:
    for _ in range(bits):
        at = rng.randrange(lo, hi)
        data[at] ^= 1 << rng.randrange(8)


def damage(name: str, family: str, data: bytes, kind: str, rng: random.Random) -> Input:
    """``data`` damaged by one ``kind`` (drawn from ``rng``)."""
    out = bytearray(data)
    spans = chunk_spans(data) if family == "mcap" else []
    if kind == "endless":
        return Input(f"{family}:{ENDLESS}", family, kind, None)
    if kind in ("chunk-flip", "invert16", "crc") and not spans:
        kind = "flip"
    if kind == "flip":
        _flip(out, rng, 0, len(out), rng.randint(1, 8))
        in_chunk = False
    elif kind == "chunk-flip":
        _crc, lo, hi = rng.choice(spans)
        _flip(out, rng, lo, hi, rng.randint(1, 8))
        in_chunk = out != bytearray(data)
    elif kind == "invert16":
        _crc, lo, hi = rng.choice(spans)
        at = rng.randrange(lo, max(lo + 1, hi - 16))
        out[at : at + 16] = bytes(b ^ 0xFF for b in out[at : at + 16])
        in_chunk = True
    elif kind == "crc":
        crc, _lo, _hi = rng.choice(spans)
        out[crc + rng.randrange(4)] ^= 1 << rng.randrange(8)
        in_chunk = True
    elif kind == "truncate":
        del out[rng.randrange(len(out)) :]
        in_chunk = False
    elif kind == "huge-length":
        out = _huge(out, family, rng)
        in_chunk = False
    else:  # garbage
        junk = rng.randbytes(rng.choice((1, 7, 64, 4096, 70_000)))
        out = bytearray((data[:8] if rng.random() < 0.5 else b"") + junk)
        in_chunk = False
    return Input(f"{name}:{kind}@{rng.getrandbits(32):08x}", family, kind, bytes(out), in_chunk)


def _huge(out: bytearray, family: str, rng: random.Random) -> bytearray:
    """A length field set to something enormous: an MCAP record's, a pcap packet's, a TCP frame's."""
    value = rng.choice((1 << 31, 1 << 40, (1 << 63) - 1, (1 << 64) - 1))
    if family == "mcap":
        starts = _record_starts(bytes(out))
        at = rng.choice(starts) + 1 if starts else 9
        out[at : at + 8] = struct.pack("<Q", value)
    elif family == "pcap":
        # pcapng: a block's total length; pcap: the first packet's captured length
        at = rng.choice((4, 28 + 4, len(out) // 2)) if out[:4] == b"\x0a\x0d\x0d\x0a" else 24 + 8
        out[at : at + 4] = struct.pack("<I", value & 0xFFFFFFFF)
    else:
        at = rng.randrange(0, max(1, len(out) - 2))
        out[at : at + 2] = b"\xff\xff"
    return out


def inputs(seed: int, count: int, scratch: Path) -> Iterator[Input]:
    """``count`` damaged inputs of a seed: input N depends on the seed and N alone."""
    bases = base_files(scratch)
    for n in range(count):
        rng = random.Random(f"{seed}:{n}")
        name, family, data = rng.choice(bases)
        yield damage(name, family, data, KINDS[n % len(KINDS)], rng)


# ---------------------------------------------------------------------------------------- running


@dataclass(frozen=True, slots=True)
class Outcome:
    reader: str
    input: str
    kind: str
    outcome: str
    detail: str
    rss_mb: float = 0.0


class _Alarm(BaseException):
    """The wall-clock limit of one in-process run (a BaseException: nothing under test catches it)."""


def _program(name: str) -> Any:

    return {
        "manip-capture": manip.captures.cli.main,
        "manip-decode": manip.decode.cli.main,
        "manip-conform": manip.conformance.cli.main,
    }[name]


def judge(reader: Reader, item: Input, code: int, out: str, err: str) -> tuple[str, str]:
    """The outcome of one finished run from its exit status and output."""
    text = out + err
    if "Traceback" in text or "internal error" in text or code == 4:
        return "traceback", _last_line(text)
    if code == 0:
        if item.in_chunk and reader.judges_chunks:
            return "silent", _last_line(out)
        said = any(word in out.lower() for word in ("crc", "skipped", "damaged", "problem"))
        if item.in_chunk and reader.name == "capture-recover" and not said:
            return "silent", _last_line(out)
        return "ok", ""
    # manip-conform writes its verdict, and why there is none, to standard output.
    message = text if reader.program == "manip-conform" else err
    if not message.strip():
        return "traceback", f"exit {code} with no message on stderr"
    return "rejected", _last_line(message)


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1][:200] if lines else ""


def run_in_process(reader: Reader, item: Input, path: str, scratch: str, timeout: float) -> Outcome:
    """One reader on one input, in this process (click's test runner)."""

    if item.data is None and reader.family in _STREAMS:
        return Outcome(reader.name, item.name, item.kind, "skipped", "an endless stream is decoded endlessly")

    def _alarm(signum: int, frame: Any) -> None:
        raise _Alarm

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        result = CliRunner().invoke(_program(reader.program), reader.args(path, scratch))
    except _Alarm:
        return Outcome(reader.name, item.name, item.kind, "hang", f"no end within {timeout} s")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    exc = result.exception
    if isinstance(exc, _Alarm):
        return Outcome(reader.name, item.name, item.kind, "hang", f"no end within {timeout} s")
    if isinstance(exc, MemoryError):
        return Outcome(reader.name, item.name, item.kind, "memory", "MemoryError")
    if exc is not None and not isinstance(exc, SystemExit):
        return Outcome(reader.name, item.name, item.kind, "traceback", f"{type(exc).__name__}: {exc}"[:200])
    outcome, detail = judge(reader, item, result.exit_code, result.stdout, result.stderr)
    return Outcome(reader.name, item.name, item.kind, outcome, detail)


def run_process(
    reader: Reader, item: Input, path: str, scratch: str, timeout: float, rss_mb: float
) -> Outcome:
    """One reader on one input as a real process; its peak resident set is measured."""
    exe = Path(sys.executable).parent / reader.program
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        proc = subprocess.Popen([str(exe), *reader.args(path, scratch)], stdout=out, stderr=err)
        deadline = time.monotonic() + timeout
        status, usage = 0, None
        while time.monotonic() < deadline:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            time.sleep(0.02)
        else:
            proc.kill()
            _pid, status, usage = os.wait4(proc.pid, 0)
            peak = usage.ru_maxrss / 1024
            if item.data is None and reader.family in _STREAMS and peak <= rss_mb:
                return Outcome(
                    reader.name, item.name, item.kind, "streaming", f"{peak:.0f} MB after {timeout} s", peak
                )
            return Outcome(reader.name, item.name, item.kind, "hang", f"killed after {timeout} s", peak)
        proc.returncode = os.waitstatus_to_exitcode(status)
        peak = usage.ru_maxrss / 1024 if usage is not None else 0.0
        out.seek(0)
        err.seek(0)
        text_out, text_err = out.read().decode(errors="replace"), err.read().decode(errors="replace")
    if peak > rss_mb:
        return Outcome(reader.name, item.name, item.kind, "memory", f"peak RSS {peak:.0f} MB", peak)
    outcome, detail = judge(reader, item, proc.returncode, text_out, text_err)
    return Outcome(reader.name, item.name, item.kind, outcome, detail, peak)


def campaign(
    seed: int,
    count: int,
    *,
    processes: bool = False,
    timeout: float = 20.0,
    rss_mb: float = 200.0,
    readers: Sequence[Reader] = READERS,
    report: Callable[[Outcome], None] | None = None,
) -> list[Outcome]:
    """Every reader of a family on each of ``count`` damaged inputs of ``seed``."""
    outcomes = []
    with tempfile.TemporaryDirectory(prefix="manip-damaged-") as scratch:
        base = Path(scratch)
        for item in inputs(seed, count, base):
            path = ENDLESS
            if item.data is not None:
                path = str(base / "input.bin")
                Path(path).write_bytes(item.data)
            for reader in readers:
                if reader.family != item.family:
                    continue
                if processes:
                    outcome = run_process(reader, item, path, scratch, timeout, rss_mb)
                else:
                    outcome = run_in_process(reader, item, path, scratch, timeout)
                outcomes.append(outcome)
                if report is not None:
                    report(outcome)
    return outcomes


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--inputs", type=int, default=400, help="Damaged inputs (each to every reader of its kind)."
    )
    parser.add_argument("--processes", action="store_true", help="Real processes, peak RSS measured.")
    parser.add_argument("--timeout", type=float, default=20.0, help="Seconds one run may take.")
    parser.add_argument(
        "--rss-mb", type=float, default=200.0, help="Peak resident memory allowed (processes)."
    )
    parser.add_argument("--address-space-gb", type=float, default=3.0, help="In-process address-space limit.")
    parser.add_argument(
        "-v", "--verbose", action="store_true", help="Print every outcome, not only bad ones."
    )
    args = parser.parse_args(argv)
    if not args.processes:
        limit = int(args.address_space_gb * (1 << 30))
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_AS, (limit, limit))

    def show(o: Outcome) -> None:
        if args.verbose or o.outcome in BAD:
            rss = f" ({o.rss_mb:.0f} MB)" if o.rss_mb else ""
            print(f"{o.outcome:9} {o.reader:18} {o.input}: {o.detail}{rss}", flush=True)

    started = time.monotonic()
    outcomes = campaign(
        args.seed,
        args.inputs,
        processes=args.processes,
        timeout=args.timeout,
        rss_mb=args.rss_mb,
        report=show,
    )
    return tally(
        outcomes,
        f"on {args.inputs} inputs (seed {args.seed})",
        started=started,
        kinds=OUTCOMES,
        bad=BAD,
        peak=args.processes,
    )


if __name__ == "__main__":
    sys.exit(main())
