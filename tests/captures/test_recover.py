"""Recovering truncated and damaged captures, including a recorder killed with SIGKILL mid-session."""

from __future__ import annotations

import asyncio
import io
import os
import signal
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from manip.captures import CaptureError, CaptureTruncatedError, Recorder, read_capture, read_session, recover
from manip.codecs.messages import encode_request
from manip.codecs.packet import Packet
from manip.links import open_connection
from manip.reference_server.driver import serve
from manip.spec.constants import RequestOp
from tests.support.paths import ROOT

Msg = tuple[str, int, int, bytes]


def messages(path: Path) -> list[Msg]:
    """(topic, log_time, sequence, data) of every message, in file order."""
    topics: dict[int, str] = {}
    out: list[Msg] = []
    with path.open("rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, Channel):
                topics[record.id] = record.topic
            elif isinstance(record, Message):
                out.append((topics[record.channel_id], record.log_time, record.sequence, bytes(record.data)))
    return out


def chunk_messages(data: bytes, offset: int) -> int:
    """Messages in the chunk record at ``offset`` of a file (read with mcap's own reader)."""
    stream = StreamReader(io.BytesIO(data[offset:]), skip_magic=True, emit_chunks=True)
    chunk = next(iter(stream.records))
    assert isinstance(chunk, Chunk)
    return sum(isinstance(r, Message) for r in breakup_chunk(chunk))


def small_capture(path: Path, compression: str, n: int = 60, chunk_size: int = 700) -> None:
    with Recorder(path, compression=compression, chunk_size=chunk_size) as rec:
        link = rec.open_link("tcp")
        for i in range(n):
            data = encode_request("set-speed", factor=0.5 + i)
            packet = Packet(RequestOp.SET_SPEED, 0o440, 1, 0o401, 2, i + 2, 0, data)
            rec.packet(link, "c2s", packet, t_ns=10**9 + i)


@pytest.fixture(scope="module", params=["none", "zstd"])
def original(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("orig") / f"small-{request.param}.mcap"
    small_capture(path, request.param)
    return path


def test_a_complete_file_is_rewritten_whole(original: Path, tmp_path: Path) -> None:
    out = tmp_path / "out.mcap"
    report = recover(original, out)
    assert report.complete and report.lost_bytes == 0 and not report.partial_chunk
    assert messages(out) == messages(original)
    assert "complete" in report.summary()


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut_fraction=st.floats(min_value=0.0, max_value=1.0))
def test_truncation_anywhere_keeps_a_prefix_and_every_whole_chunk(
    original: Path, tmp_path: Path, cut_fraction: float
) -> None:
    data = original.read_bytes()
    header_end = 8 + 9 + 60  # magic, then the header record (profile, library) at least
    cut = header_end + int(cut_fraction * (len(data) - header_end))
    cut_file = tmp_path / "cut.mcap"
    cut_file.write_bytes(data[:cut])
    out = tmp_path / "out.mcap"
    try:
        report = recover(cut_file, out)
    except CaptureError as exc:  # only when the header record itself is cut
        assert "header" in str(exc)
        return
    with original.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    whole = [c for c in summary.chunk_indexes if c.chunk_start_offset + c.chunk_length <= cut]
    orig = messages(original)
    got = messages(out)
    assert got == orig[: len(got)]  # nothing invented, nothing reordered
    assert len(got) >= sum(chunk_messages(data, c.chunk_start_offset) for c in whole)
    with out.open("rb") as f:  # the new file has a valid summary
        new_summary = make_reader(f).get_summary()
    assert new_summary is not None and new_summary.statistics is not None
    assert new_summary.statistics.message_count == len(got) == report.messages
    assert report.good_bytes + report.lost_bytes == len(data[:cut]) or report.complete


def test_a_cut_uncompressed_chunk_gives_back_its_whole_messages(tmp_path: Path) -> None:
    src = tmp_path / "big-chunk.mcap"
    small_capture(src, "none", chunk_size=6000)
    with src.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    last = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[1]  # after the schemas' chunk
    cut = last.chunk_start_offset + last.chunk_length * 3 // 4
    (tmp_path / "cut.mcap").write_bytes(src.read_bytes()[:cut])
    report = recover(tmp_path / "cut.mcap", tmp_path / "out.mcap")
    assert report.partial_chunk and report.partial_messages > 0
    assert report.partial_start_ns == last.message_start_time
    assert "salvaged" in report.summary()


def test_a_damaged_chunk_is_skipped_and_the_rest_kept(tmp_path: Path) -> None:
    src = tmp_path / "src.mcap"
    small_capture(src, "zstd")
    with src.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    assert len(chunks) >= 3
    victim = chunks[1]
    data = bytearray(src.read_bytes())
    data[victim.chunk_start_offset + victim.chunk_length - 3] ^= 0x55  # inside the compressed records
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    report = recover(tmp_path / "bad.mcap", tmp_path / "out.mcap")
    assert report.bad_chunks == 1 and report.chunks == len(chunks) - 1
    assert report.complete
    assert 0 < report.messages < len(messages(src))


def test_not_an_mcap_file(tmp_path: Path) -> None:
    (tmp_path / "x.mcap").write_bytes(b"hello")
    with pytest.raises(CaptureError, match="not an MCAP"):
        recover(tmp_path / "x.mcap")
    with pytest.raises(CaptureError, match="new file"):
        recover(tmp_path / "x.mcap", tmp_path / "x.mcap")


def test_the_reader_points_at_recover_for_a_truncated_file(original: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(original.read_bytes()[: original.stat().st_size // 2])
    with pytest.raises(CaptureTruncatedError, match="manip-capture recover"):
        read_capture(cut)


# ------------------------------------------------------------------------------ SIGKILL


def test_a_recorder_killed_mid_session_loses_at_most_about_a_second(tmp_path: Path) -> None:
    out = tmp_path / "killed.mcap"

    async def run() -> tuple[list[tuple[int, int]], int]:
        async with serve("tcp://127.0.0.1:0", time_scale=20.0) as server:
            proc = await asyncio.create_subprocess_exec(
                sys.executable, "-m", "manip.captures.cli", "record",
                "--listen", "tcp://127.0.0.1:0", "--upstream", server.address,
                "-o", str(out), "--flush-interval", "1.0",
                stdout=asyncio.subprocess.PIPE,
            )  # fmt: skip
            try:
                assert proc.stdout is not None
                line = (await asyncio.wait_for(proc.stdout.readline(), 20)).decode()
                assert line.startswith("manip-capture: recording tcp://"), line
                proxy = line.split()[2]
                conn = await open_connection(proxy)
                await conn.receive()  # the initial RESPONSE
                answered: list[tuple[int, int]] = []  # (request number, time its reply came)
                end = time.monotonic() + 2.6
                while time.monotonic() < end:
                    number = await conn.send(encode_request("here"), RequestOp.HERE)
                    await conn.receive()
                    answered.append((number, time.time_ns()))
                    await asyncio.sleep(0.02)
                killed_at = time.time_ns()
                proc.send_signal(signal.SIGKILL)
                await proc.wait()
                conn.abort("recorder gone")
                return answered, killed_at
            finally:
                if proc.returncode is None:
                    proc.kill()
                    await proc.wait()

    answered, killed_at = asyncio.run(run())
    assert len(answered) > 40
    with pytest.raises(CaptureTruncatedError):
        read_capture(out)
    fixed = tmp_path / "fixed.mcap"
    report = recover(out, fixed)
    assert not report.complete and report.chunks >= 2
    kept = {p.request_number for p in read_session(fixed).requests}
    must_have = {n for n, t in answered if t < killed_at - 1_250_000_000}
    assert must_have and must_have <= kept
    assert report.last_message_ns is not None and report.last_message_ns > killed_at - 1_250_000_000
    assert os.path.getsize(fixed) > 0


def test_recover_writes_the_default_name_its_help_gives(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from manip.captures.cli import main as capture_main

    source = tmp_path / "s.mcap"
    source.write_bytes((ROOT / "captures" / "motion.mcap").read_bytes())
    help_text = CliRunner().invoke(capture_main, ["recover", "--help"]).output
    assert "s.mcap -> s.recovered.mcap" in " ".join(help_text.split())
    result = CliRunner().invoke(capture_main, ["recover", str(source)])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "s.recovered.mcap").exists() and not (tmp_path / "s.mcap.recovered.mcap").exists()
