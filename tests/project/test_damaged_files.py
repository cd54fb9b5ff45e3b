"""Damaged and hostile files against every reader: a clear error naming the file, the offset and what is
wrong (never a traceback), bounded memory, and damage never passed as a clean file.  The seeded campaign
of ``tools/damaged_files.py`` runs here in a short form; the long form is run by hand."""

from __future__ import annotations

import os
import struct
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest
from click.testing import CliRunner, Result

from manip.captures import CaptureError, Recorder, read_capture, recover
from manip.captures.bounds import CaptureDamagedError
from manip.captures.cli import main as capture_main
from manip.captures.pcap import import_pcap, iter_datagrams
from manip.codecs.packet import Packet
from manip.conformance.cli import main as conform_main
from manip.decode.cli import main as decode_main
from manip.outfile import OutputError, atomic_output
from tests.support.paths import ROOT
from tests.support.tools import load_tool

MOTION = ROOT / "captures" / "motion.mcap"


def _tool() -> ModuleType:
    return load_tool("damaged_files")


DAMAGED = _tool()


def _no_traceback(result: Result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output and "internal error" not in result.output


def _chunks(data: bytes) -> list[tuple[int, int, int]]:
    spans: list[tuple[int, int, int]] = DAMAGED.chunk_spans(data)
    assert spans
    return spans


def _with_chunk_damage(tmp_path: Path, how: str) -> tuple[Path, int]:
    """motion.mcap with its first chunk damaged: ``flip`` one bit of its compressed records, ``invert16``
    sixteen bytes of them, ``crc`` its CRC alone.  Returns the file and the chunk record's offset."""
    data = bytearray(MOTION.read_bytes())
    crc_at, lo, hi = _chunks(bytes(data))[0]
    if how == "flip":
        data[lo + (hi - lo) // 2] ^= 0x10
    elif how == "invert16":
        at = lo + (hi - lo) // 3
        data[at : at + 16] = bytes(b ^ 0xFF for b in data[at : at + 16])
    else:
        data[crc_at] ^= 0x01
    path = tmp_path / f"{how}.mcap"
    path.write_bytes(bytes(data))
    return path, crc_at - 9 - 24


# ---------------------------------------------------------------------------------------- MCAP


@pytest.mark.parametrize("how", ["flip", "invert16", "crc"])
def test_a_damaged_chunk_is_an_error_naming_the_file_and_offset(tmp_path: Path, how: str) -> None:
    path, offset = _with_chunk_damage(tmp_path, how)
    with pytest.raises(CaptureDamagedError) as caught:
        read_capture(path)
    assert caught.value.offset == offset
    assert str(path) in str(caught.value) and f"byte {offset}" in str(caught.value)
    runner = CliRunner()
    for args in (
        ["info", str(path)],
        ["info", "--json", str(path)],
        ["export", str(path), "-o", str(tmp_path / "x")],
    ):
        result = runner.invoke(capture_main, args)
        _no_traceback(result)
        assert result.exit_code == 1 and f"byte {offset}" in result.stderr, args
    assert not (tmp_path / "x").exists()  # nothing half-written is left
    result = runner.invoke(decode_main, ["--mcap", str(path)])
    _no_traceback(result)
    assert result.exit_code == 1 and "damaged" in result.stderr


@pytest.mark.parametrize("how", ["invert16", "crc"])
def test_verify_and_replay_call_a_damaged_capture_damaged_never_conformant(tmp_path: Path, how: str) -> None:
    path, _ = _with_chunk_damage(tmp_path, how)
    for command in (["verify", str(path), "-q"], ["replay", str(path), "-q"]):
        result = CliRunner().invoke(conform_main, command)
        _no_traceback(result)
        assert result.exit_code == 3, result.output
        assert "conformant" not in result.output.replace("non-conformant", "") and "damaged" in result.output


def test_a_record_longer_than_the_file_is_refused_without_allocating_it(tmp_path: Path) -> None:
    data = bytearray(MOTION.read_bytes())
    crc_at, _, _ = _chunks(bytes(data))[0]
    chunk = crc_at - 9 - 24
    data[chunk + 1 : chunk + 9] = struct.pack("<Q", (1 << 63) - 1)  # the first chunk's length
    path = tmp_path / "huge.mcap"
    path.write_bytes(bytes(data))
    with pytest.raises(CaptureError, match=r"huge\.mcap"):
        read_capture(path)
    report = recover(path, tmp_path / "out.mcap")
    assert f"record at byte {chunk}" in report.stopped_because and "more than" in report.stopped_because
    assert report.damaged and "the file was complete" not in report.summary()


def test_export_of_a_short_file_that_is_not_mcap_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "short.mcap"
    path.write_bytes(b"\x89MCAP0\r\n\x01")
    result = CliRunner().invoke(capture_main, ["export", str(path), "-o", str(tmp_path / "x.pcapng")])
    _no_traceback(result)
    assert result.exit_code == 1 and "short.mcap" in result.stderr


def test_recover_keeps_what_a_bad_crc_still_lets_it_read(tmp_path: Path) -> None:
    path, offset = _with_chunk_damage(tmp_path, "crc")
    report = recover(path, tmp_path / "out.mcap")
    assert report.crc_chunks == 1 and report.bad_chunks == 0 and report.messages > 0
    assert report.damaged
    summary = report.summary()
    assert "the file was complete" not in summary
    assert f"chunk at byte {offset}" in summary and "CRC mismatch" in summary
    assert read_capture(tmp_path / "out.mcap").sessions  # the rebuilt file reads


def test_recover_of_dev_zero_is_refused_at_once_in_bounded_memory(tmp_path: Path) -> None:
    """The command's own peak (VmHWM of its address space, which starts at exec), not wait4's
    ru_maxrss: that one also counts the test worker's pages the child shared between fork and exec."""
    if not os.path.exists("/dev/zero"):
        pytest.skip("no /dev/zero")
    peak = (
        "import atexit, sys\n"
        "def peak():\n"
        "    status = open('/proc/self/status').read()\n"
        "    print('peak-kb', status.split('VmHWM:')[1].split()[0], file=sys.stderr)\n"
        "atexit.register(peak)\n"
        "from manip.captures.cli import main\n"
        "main()\n"
    )
    out = tmp_path / "z.mcap"
    proc = subprocess.run(
        [sys.executable, "-c", peak, "recover", "/dev/zero", "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert proc.returncode == 1 and "not an MCAP file" in proc.stderr, proc.stderr
    (peak_kb,) = [int(line.split()[1]) for line in proc.stderr.splitlines() if line.startswith("peak-kb ")]
    assert peak_kb < 200 * 1024
    assert not out.exists()


# ---------------------------------------------------------------------------------------- pcap


def test_a_pcap_packet_record_that_claims_gigabytes_is_refused(tmp_path: Path) -> None:
    pcapng = tmp_path / "m.pcapng"
    assert CliRunner().invoke(capture_main, ["export", str(MOTION), "-o", str(pcapng)]).exit_code == 0
    import dpkt  # type: ignore[import-untyped]

    classic = tmp_path / "m.pcap"
    with pcapng.open("rb") as f, classic.open("wb") as out:
        writer = dpkt.pcap.Writer(out, linktype=101)
        for ts, frame in dpkt.pcapng.Reader(f):
            writer.writepkt(frame, ts)
    data = bytearray(classic.read_bytes())
    data[24 + 8 : 24 + 12] = struct.pack("<I", 0xFFFFFFF0)  # the first packet's captured length
    classic.write_bytes(bytes(data))
    with pytest.raises(CaptureError, match=r"m\.pcap: damaged at byte \d+: a packet record claims"):
        list(iter_datagrams(classic))
    with pytest.raises(CaptureError, match="claims"):
        import_pcap(classic, tmp_path / "out.mcap")
    result = CliRunner().invoke(decode_main, ["--pcap", str(classic)])
    _no_traceback(result)
    assert result.exit_code == 1 and "claims" in result.stderr


def test_decode_of_a_capture_with_malformed_packets_says_why_it_exits_1(tmp_path: Path) -> None:
    with Recorder(tmp_path / "bad.mcap") as rec:
        link = rec.open_link("tcp")
        rec.packet(link, "c2s", Packet(0o201, 0o440, 1, 0o401, 2, 1, 0, b"\x01"), t_ns=10**9)
    result = CliRunner().invoke(decode_main, ["--mcap", str(tmp_path / "bad.mcap")])
    assert result.exit_code == 1
    assert "malformed" in result.stderr and "on purpose" in result.stderr


def test_decode_of_a_cougar_stream_says_why_it_exits_1(tmp_path: Path) -> None:
    cut = tmp_path / "cut.hex"
    cut.write_text("0004 4080")  # a command cut short
    result = CliRunner().invoke(decode_main, ["--cougar", "command", str(cut)])
    assert result.exit_code == 1 and "ends inside a message" in result.stderr
    if os.path.exists("/dev/zero"):
        result = CliRunner().invoke(decode_main, ["--cougar", "command", "/dev/zero"])
        _no_traceback(result)
        assert result.exit_code == 1 and "too long" in result.stderr


# ---------------------------------------------------------------------------------------- output


def test_atomic_output_leaves_the_old_file_and_no_temporary_on_failure(tmp_path: Path) -> None:
    target = tmp_path / "report.json"
    target.write_text("old")

    class BoomError(Exception):
        pass

    with pytest.raises(BoomError), atomic_output(target) as f:
        f.write("half")
        raise BoomError
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["report.json"]
    with atomic_output(target) as f:
        f.write("new")
    assert target.read_text() == "new" and os.listdir(tmp_path) == ["report.json"]
    if os.path.exists("/dev/full"):
        with pytest.raises(OutputError, match="cannot write /dev/full"), atomic_output("/dev/full") as f:
            f.write("x" * 100_000)
    with pytest.raises(OutputError, match="missing"), atomic_output(tmp_path / "missing" / "x") as f:
        f.write("x")


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_a_full_disk_is_an_error_naming_the_path(tmp_path: Path) -> None:
    runner = CliRunner()
    for args in (["export", str(MOTION), "-o", "/dev/full"], ["recover", str(MOTION), "-o", "/dev/full"]):
        result = runner.invoke(capture_main, args)
        _no_traceback(result)
        assert result.exit_code == 1 and "cannot write /dev/full" in result.stderr, args
    for option in ("--json", "--junit", "--html", "--markdown"):
        result = runner.invoke(conform_main, ["verify", str(MOTION), "-q", option, "/dev/full"])
        _no_traceback(result)
        assert result.exit_code == 2 and "cannot write /dev/full" in result.output, option
    saved = tmp_path / "report.json"
    assert runner.invoke(conform_main, ["verify", str(MOTION), "-q", "--json", str(saved)]).exit_code == 0
    result = runner.invoke(conform_main, ["report", str(saved), "--html", "/dev/full"])
    _no_traceback(result)
    assert result.exit_code == 2 and "cannot write /dev/full" in result.output


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_a_recorder_on_a_full_disk_keeps_the_error_and_never_raises_mid_session(
    caplog: pytest.LogCaptureFixture,
) -> None:
    recorder = Recorder("/dev/full")
    link = recorder.open_link("tcp")
    for i in range(2000):  # past the write buffer: the error happens mid-session, and is held
        recorder.packet(link, "c2s", Packet(0o201, 0o440, 1, 0o401, 2, i, 0, bytes(40)), t_ns=10**9 + i)
    recorder.flush()
    recorder.close()
    assert recorder.write_error is not None
    assert "cannot write the capture /dev/full" in str(recorder.write_error)
    said = [r.getMessage() for r in caplog.records if "cannot write the capture" in r.getMessage()]
    assert len(said) == 1  # once, not once a packet


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_capture_record_on_a_full_disk_exits_1_naming_the_file() -> None:
    upstream = "tcp://127.0.0.1:9"  # nothing connects: the recording holds its own events only
    args = ["record", "--listen", "tcp://127.0.0.1:0", "--upstream", upstream, "-o", "/dev/full"]
    result = CliRunner().invoke(capture_main, [*args, "--seconds", "0.1"])
    _no_traceback(result)
    assert result.exit_code == 1 and "cannot write the capture /dev/full" in result.stderr


# ---------------------------------------------------------------------------------------- campaign


def test_a_short_seeded_campaign_of_damaged_files_finds_nothing_bad() -> None:
    """Every reader on 48 damaged inputs (every kind of damage, every family of file): no traceback, no
    hang, no runaway memory, no damaged chunk passed as clean."""
    outcomes = DAMAGED.campaign(11, 48, timeout=20.0)
    bad = [o for o in outcomes if o.outcome in DAMAGED.BAD]
    assert not bad, "\n".join(f"{o.outcome} {o.reader} {o.input}: {o.detail}" for o in bad[:10])
    assert {o.kind for o in outcomes} == set(DAMAGED.KINDS)
    assert sum(o.outcome == "rejected" for o in outcomes) > len(outcomes) // 3


def test_the_campaign_sees_a_silent_acceptance() -> None:
    """The judge of the campaign calls exit 0 on a damaged chunk silent (so the campaign can fail)."""
    item = DAMAGED.Input("x", "mcap", "crc", b"", in_chunk=True)
    verify = next(r for r in DAMAGED.READERS if r.name == "verify")
    assert DAMAGED.judge(verify, item, 0, "conformant", "")[0] == "silent"
    assert DAMAGED.judge(verify, item, 3, "", "")[0] == "traceback"  # an exit with no message
