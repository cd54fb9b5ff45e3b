"""manip-decode benchmark (run by hand): a large stream decoded as a user runs it, in a subprocess.

Workload: ``--mb`` megabytes (default 100) of manip TCP-link frames, a session's mix repeated (a
joint-angles request and its reply, here and its transform reply, set-joint-angles with six floats,
an error reply with arguments, a describe-self text chunk), written to a temporary file once.

Measured, each in its own ``manip-decode --link tcp FILE`` process, its output read from a pipe:

* ``first line``: seconds from starting the process to reading its first line of output (the
  process is then killed), beside the seconds it takes only to start Python and import the decoder
  (``python -c 'import manip.decode.cli'``): on a loaded machine both grow together;
* ``whole``: seconds to decode the whole file (``--format tree``, output read and thrown away),
  frames per second, MB per second, and the process's peak RSS (its own ``ru_maxrss``);
* ``json``: the same with ``--format json`` (one JSON array, written element by element).

Targets (issue 14): peak RSS under 100 MB and the first line within 0.5 s for a 100 MB input.  The
figures are printed with a verdict; nothing is asserted (the machine is shared: run it twice).

    .venv/bin/python bench/decode.py [--mb 100] [--formats tree,json]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from manip.codecs import ErrorMessage, Packet, encode_reply, encode_request, encode_tcp
from manip.codecs.messages import encode_error, encode_multi_text
from manip.spec.constants import RequestOp, ServerOp

DECODE = Path(sys.executable).with_name("manip-decode")
RSS_TARGET_MB = 100.0
FIRST_LINE_TARGET_S = 0.5


def session_frames() -> list[bytes]:
    """One round of the workload's frames (client and server packets alternating)."""

    def c2s(opcode: int, number: int, data: bytes = b"") -> Packet:
        return Packet(opcode, 0o440, 0x5678, 0o401, 0x1234, number, number - 1, data)

    def s2c(opcode: int, number: int, data: bytes) -> Packet:
        return Packet(opcode, 0o401, 0x1234, 0o440, 0x5678, number, number, data)

    joints = (1.5, -90.0, 90.0, 0.25, 10.0, -3.0)
    transform = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 500.0, 150.0, 400.0)
    error = ErrorMessage("move", "C", "BDL", "Bad data length: ~ expected, ~ received", (48, 44))
    text = encode_multi_text(5, '((:BRAND-NAME . "Unimation Puma 600") (:DEGREES-OF-FREEDOM . 6))')[0]
    packets = [
        c2s(RequestOp.JOINT_ANGLES, 1),
        s2c(ServerOp.RESPONSE, 1, encode_reply("joint-angles", 1, joints=joints)),
        c2s(RequestOp.HERE, 2),
        s2c(ServerOp.RESPONSE, 2, encode_reply("here", 2, transform=transform)),
        c2s(RequestOp.SET_JOINT_ANGLES, 3, encode_request("set-joint-angles", joints=joints)),
        s2c(ServerOp.NON_FATAL_ERROR, 3, encode_error(ServerOp.NON_FATAL_ERROR, 3, error)),
        c2s(RequestOp.DESCRIBE_SELF, 5),
        s2c(ServerOp.RESPONSE, 4, text),
    ]
    return [encode_tcp(p) for p in packets]


def make_input(path: Path, megabytes: float) -> int:
    """Write the workload (whole rounds, about ``megabytes``); return the number of frames."""
    frames = session_frames()
    one_round = b"".join(frames)
    rounds = max(1, int(megabytes * 1_000_000) // len(one_round))
    with path.open("wb") as f:
        for done in range(0, rounds, 1000):
            f.write(one_round * min(1000, rounds - done))
    return rounds * len(frames)


def first_line(path: Path) -> float:
    start = time.perf_counter()
    proc = subprocess.Popen([str(DECODE), "--link", "tcp", str(path)], stdout=subprocess.PIPE)
    assert proc.stdout is not None
    proc.stdout.readline()
    elapsed = time.perf_counter() - start
    proc.kill()
    proc.wait()
    proc.stdout.close()
    return elapsed


def startup() -> float:
    """Seconds to start Python and import the decoder: the part of the first line that is not decoding."""
    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import manip.decode.cli"], check=True)
    return time.perf_counter() - start


def whole(path: Path, fmt: str) -> tuple[float, float, int]:
    """Seconds, peak RSS (MB) and exit status of decoding the whole file, output read from a pipe."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        [str(DECODE), "--link", "tcp", "--format", fmt, str(path)], stdout=subprocess.PIPE
    )
    assert proc.stdout is not None
    while proc.stdout.read(1 << 20):
        pass
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    elapsed = time.perf_counter() - start
    proc.stdout.close()
    return elapsed, usage.ru_maxrss / 1024.0, proc.returncode


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--mb", type=float, default=100.0, help="input size in megabytes")
    parser.add_argument("--formats", default="tree,json", help="comma-separated --format values")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "stream.bin"
        frames = make_input(path, args.mb)
        size = path.stat().st_size
        print(f"input: {size / 1e6:.1f} MB, {frames} frames of manip TCP-link framing")
        firsts = sorted(first_line(path) for _ in range(5))
        starts = sorted(startup() for _ in range(5))
        verdict = "ok" if firsts[2] < FIRST_LINE_TARGET_S else "OVER TARGET"
        print(
            f"first line: median {firsts[2]:.3f} s of 5 (min {firsts[0]:.3f}), target < 0.5 s: {verdict}; "
            f"of which starting Python and importing the decoder: median {starts[2]:.3f} s "
            f"(min {starts[0]:.3f})"
        )
        for fmt in args.formats.split(","):
            seconds, rss, status = whole(path, fmt)
            verdict = "ok" if rss < RSS_TARGET_MB else "OVER TARGET"
            print(
                f"{fmt:>6}: {seconds:.1f} s, {frames / seconds:,.0f} frames/s, "
                f"{size / 1e6 / seconds:.2f} MB/s, "
                f"peak RSS {rss:.1f} MB (target < {RSS_TARGET_MB:.0f} MB: {verdict}), exit {status}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
