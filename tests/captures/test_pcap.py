"""pcap and pcapng: CHUDP datagrams out of tcpdump-style files, manip captures out as pcapng and back,
with the same verify verdict; manip-decode --pcap and manip-capture import/export from the command line."""

from __future__ import annotations

import json
import socket
import struct
from pathlib import Path
from typing import Any

import dpkt
import pytest
from click.testing import CliRunner

from manip.captures import read_capture, read_session
from manip.captures.cli import main as capture_main
from manip.captures.pcap import (
    CHUDP_PORT,
    LINKTYPE_ETHERNET,
    LINKTYPE_LINUX_SLL2,
    LINKTYPE_RAW,
    FlowTracker,
    export_pcapng,
    import_pcap,
    iter_datagrams,
)
from manip.codecs import Packet, encode_chudp, encode_reply
from manip.codecs.framing import CHUDP_HEADER
from manip.conformance.cli import main as conform_main
from manip.decode.cli import main as decode_main
from manip.spec.constants import ChaosOp, RequestOp, ServerOp
from tests.support.paths import ROOT

GOLDEN = ("describe-self", "motion", "errors")
CLIENT = ("192.0.2.7", 5000)  # TEST-NET addresses: only ever written into files here
SERVER = ("192.0.2.1", CHUDP_PORT)


def _session() -> list[tuple[str, Packet]]:
    """RFC, OPN, the initial RESPONSE, a joint-angles request and its reply."""
    joints = (1.5, -90.0, 90.0, 0.25, 10.0, -3.0)
    return [
        ("c2s", Packet(ChaosOp.RFC, 0o440, 0, 0o401, 0x1234, 1, 0, b"PUMA")),
        ("s2c", Packet(ChaosOp.OPN, 0o401, 0x1234, 0o440, 0x5678, 1, 1, struct.pack("<HH", 1, 15))),
        ("s2c", Packet(ServerOp.RESPONSE, 0o401, 0x1234, 0o440, 0x5678, 2, 1, struct.pack("<H", 1))),
        ("c2s", Packet(RequestOp.JOINT_ANGLES, 0o440, 0x5678, 0o401, 0x1234, 2, 2)),
        (
            "s2c",
            Packet(
                ServerOp.RESPONSE,
                0o401,
                0x1234,
                0o440,
                0x5678,
                3,
                2,
                encode_reply("joint-angles", 2, joints=joints),
            ),
        ),
    ]


def _udp(src: tuple[str, int], dst: tuple[str, int], payload: bytes, *, v6: bool = False) -> Any:
    udp = dpkt.udp.UDP(sport=src[1], dport=dst[1], data=payload, ulen=8 + len(payload))
    if v6:
        return dpkt.ip6.IP6(
            src=socket.inet_pton(socket.AF_INET6, src[0]),
            dst=socket.inet_pton(socket.AF_INET6, dst[0]),
            nxt=17, hlim=64, data=udp, plen=len(udp),
        )  # fmt: skip
    return dpkt.ip.IP(
        src=socket.inet_aton(src[0]), dst=socket.inet_aton(dst[0]), p=17, data=udp, len=28 + len(payload)
    )


def _tcpdump_file(path: Path, *, extra: bool = True) -> None:
    """A libpcap file as tcpdump writes it on Ethernet: the session, plus traffic that is not CHUDP."""
    with path.open("wb") as f:
        writer = dpkt.pcap.Writer(f, linktype=LINKTYPE_ETHERNET)
        t = 1_700_000_000.0
        for i, (direction, packet) in enumerate(_session()):
            src, dst = (CLIENT, SERVER) if direction == "c2s" else (SERVER, CLIENT)
            frame = dpkt.ethernet.Ethernet(
                type=dpkt.ethernet.ETH_TYPE_IP, data=_udp(src, dst, encode_chudp(packet))
            )
            writer.writepkt(bytes(frame), t + i * 0.001)
            if extra and i == 2:
                dns = _udp(("192.0.2.7", 5353), ("192.0.2.53", 53), b"\x12\x34\x01\x00")
                writer.writepkt(bytes(dpkt.ethernet.Ethernet(type=dpkt.ethernet.ETH_TYPE_IP, data=dns)), t)
                arp = dpkt.ethernet.Ethernet(type=dpkt.ethernet.ETH_TYPE_ARP, data=b"\0" * 28)
                writer.writepkt(bytes(arp), t)


def test_datagrams_of_a_tcpdump_file(tmp_path: Path) -> None:
    path = tmp_path / "s.pcap"
    _tcpdump_file(path)
    datagrams = list(iter_datagrams(path))
    assert len(datagrams) == 6  # five CHUDP, one DNS; the ARP frame is not UDP
    assert [d.number for d in datagrams] == [1, 2, 3, 4, 6, 7]
    assert datagrams[0].src == CLIENT and datagrams[0].dst == SERVER
    assert datagrams[0].time_ns == 1_700_000_000_000_000_000
    assert [d.payload for d in iter_datagrams(path, ports=[CHUDP_PORT])] == [
        encode_chudp(p) for _, p in _session()
    ]


def test_import_takes_the_chudp_datagrams_and_finds_the_server(tmp_path: Path) -> None:
    path, out = tmp_path / "s.pcap", tmp_path / "s.mcap"
    _tcpdump_file(path)
    report = import_pcap(path, out)
    assert report.frames == 5 and report.skipped["UDP datagrams that are not CHUDP"] == 1
    (flow,) = report.flows
    assert (flow.client, flow.server) == (CLIENT, SERVER)
    session = read_session(out)
    assert [(p.direction, p.packet) for p in session.packets] == _session()
    assert [p.op for p in session.requests] == ["joint-angles"]
    assert all(pair.complete for pair in session.pairs.values())
    capture = read_capture(out)
    assert capture.links[1].framing == "chudp" and "192.0.2.1:42042" in capture.links[1].name


def test_the_server_is_the_side_the_rfc_goes_to_whatever_comes_first(tmp_path: Path) -> None:
    tracker = FlowTracker()
    session = _session()
    # a capture that starts after the RFC: the OPN comes from the server
    from manip.captures.pcap import Datagram

    flow, direction, new = tracker.place(Datagram(1, 0, SERVER, CLIENT, encode_chudp(session[1][1])))
    assert new and direction == "s2c" and flow.server == SERVER
    # --server says it outright
    tracker = FlowTracker(server=CLIENT)
    flow, direction, _ = tracker.place(Datagram(1, 0, CLIENT, SERVER, encode_chudp(session[0][1])))
    assert flow.server == CLIENT and direction == "s2c"


@pytest.mark.parametrize("linktype", [LINKTYPE_RAW, LINKTYPE_LINUX_SLL2])
def test_ipv6_and_other_link_types(tmp_path: Path, linktype: int) -> None:
    path = tmp_path / "s.pcapng"
    client, server = ("2001:db8::7", 5000), ("2001:db8::1", CHUDP_PORT)
    with path.open("wb") as f:
        writer = dpkt.pcapng.Writer(f, linktype=linktype)
        for i, (direction, packet) in enumerate(_session()):
            src, dst = (client, server) if direction == "c2s" else (server, client)
            ip = _udp(src, dst, encode_chudp(packet), v6=True)
            frame = bytes(ip) if linktype == LINKTYPE_RAW else bytes(dpkt.sll2.SLL2(ethtype=0x86DD, data=ip))
            writer.writepkt(frame, 1_700_000_000.0 + i)
    (flow,) = import_pcap(path, tmp_path / "s.mcap").flows
    assert flow.server == server
    assert len(read_session(tmp_path / "s.mcap").packets) == 5


def test_a_file_cut_inside_a_packet_keeps_what_is_whole(tmp_path: Path) -> None:
    path = tmp_path / "s.pcap"
    _tcpdump_file(path, extra=False)
    data = path.read_bytes()
    path.write_bytes(data[:-10])
    assert len(list(iter_datagrams(path))) == 4


def test_unreadable_inputs_say_what_is_wrong(tmp_path: Path) -> None:
    runner = CliRunner()
    result = runner.invoke(
        capture_main, ["import", str(tmp_path / "nope.pcap"), "-o", str(tmp_path / "o.mcap")]
    )
    assert result.exit_code == 2 and "does not exist" in result.stderr  # a usage error, as in manip-decode
    assert not (tmp_path / "o.mcap").exists()
    text = tmp_path / "notes.txt"
    text.write_text("hello, not a capture\n")
    result = runner.invoke(capture_main, ["import", str(text), "-o", str(tmp_path / "o.mcap")])
    assert result.exit_code == 1 and "not a pcap or pcapng file" in result.stderr
    empty = tmp_path / "nothing.pcap"
    with empty.open("wb") as f:
        dpkt.pcap.Writer(f)
    result = runner.invoke(capture_main, ["import", str(empty), "-o", str(tmp_path / "o.mcap")])
    assert result.exit_code == 1 and "no CHUDP datagrams" in result.stderr
    result = runner.invoke(decode_main, ["--pcap", str(tmp_path / "nope.pcap")])
    assert result.exit_code == 2 and "no such file: " in result.stderr


# ---------------------------------------------------------------------------------------- round trips


def _verdicts(path: Path, judge: str, tmp_path: Path) -> tuple[int, list[tuple[str, str, list[Any]]]]:
    report = tmp_path / f"{path.stem}-{judge}.json"
    result = CliRunner().invoke(
        conform_main, ["verify", str(path), "--judge", judge, "--json", str(report), "-q"]
    )
    data = json.loads(report.read_text())
    cases = [(c["id"], c["outcome"], [v.get("clause") for v in c["violations"]]) for c in data["cases"]]
    assert data["exit_code"] == result.exit_code
    return result.exit_code, cases


@pytest.mark.parametrize("name", GOLDEN)
def test_export_then_import_gives_the_same_verify_verdict(tmp_path: Path, name: str) -> None:
    original = ROOT / "captures" / f"{name}.mcap"
    pcapng, back = tmp_path / f"{name}.pcapng", tmp_path / f"{name}.mcap"
    export_pcapng(original, pcapng)
    import_pcap(pcapng, back)
    assert read_session(back).exchange() == read_session(original).exchange()
    for judge in ("server", "client"):
        code, cases = _verdicts(original, judge, tmp_path)
        assert _verdicts(back, judge, tmp_path) == (code, cases)
        assert cases
    assert (
        _verdicts(ROOT / "captures" / "errors.mcap", "client", tmp_path)[0] == 1
    )  # a verdict that can differ


def test_export_reframes_tcp_link_frames_and_says_so(tmp_path: Path) -> None:
    original = ROOT / "captures" / "motion.mcap"
    out = tmp_path / "m.pcapng"
    result = CliRunner().invoke(capture_main, ["export", str(original), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "L1: tcp frames re-framed as CHUDP" in result.output
    with out.open("rb") as f:
        reader = dpkt.pcapng.Reader(f)
        assert reader.datalink() == LINKTYPE_RAW
        f.seek(0)
        head = f.read(8)
        shb = dpkt.pcapng.SectionHeaderBlockLE(head + f.read(struct.unpack_from("<I", head, 4)[0] - 8))
    comment = next(o.text for o in shb.opts if o.code == dpkt.pcapng.PCAPNG_OPT_COMMENT)
    assert "re-framed as CHUDP" in comment and "motion.mcap" in comment
    frames = [p.frame for p in read_session(original).packets]
    datagrams = list(iter_datagrams(out))
    assert [d.payload for d in datagrams] == [CHUDP_HEADER + frame[2:] for frame in frames]
    times = [p.time_ns for p in read_session(original).packets]
    assert all(abs(d.time_ns - t) <= 1000 for d, t in zip(datagrams, times, strict=True))  # to the µs


def test_manip_decode_pcap(tmp_path: Path) -> None:
    path = tmp_path / "s.pcap"
    _tcpdump_file(path)
    result = CliRunner().invoke(decode_main, ["--pcap", str(path)])
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("s.pcap: first packet at 2023-11-14 22:13:20.000000Z")
    assert (
        "request joint-angles" in result.stdout
        and "joints: (1.5, -90.0, 90.0, 0.25, 10.0, -3.0)" in result.stdout
    )
    result = CliRunner().invoke(decode_main, ["--pcap", str(path), "--port", "53"])
    assert result.exit_code == 1  # on a port asked for, a datagram that is not CHUDP is shown as a bad frame
    assert "bad frame" in result.stdout and "CHUDP version is 18, expected 1" in result.stdout
    result = CliRunner().invoke(
        decode_main, ["--pcap", str(path), "--filter", "opcode=joint-angles", "--format", "json"]
    )
    packets = json.loads(result.stdout)
    assert [p["label"] for p in packets] == ["packet 6", "packet 7"]  # the request and its reply
    result = CliRunner().invoke(
        capture_main, ["import", str(path), "-o", str(tmp_path / "s.mcap"), "--server", "nope"]
    )
    assert result.exit_code == 2 and "HOST:PORT" in result.output
