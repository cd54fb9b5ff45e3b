"""pcap and pcapng files: CHUDP datagrams read from tcpdump or Wireshark captures, and written for them.

The files themselves are read and written by dpkt (pure Python, no dependencies; it reads pcap with
micro- or nanosecond times and pcapng, writes pcapng with comments, and parses the link layers a
capture of UDP traffic comes in: Ethernet, Linux cooked v1 and v2, BSD loopback, raw IP; IPv4 and IPv6;
UDP).  What is Chaos about them is here:

* :func:`iter_datagrams` streams the UDP datagrams of a capture (any port, or the ones asked for) with
  their addresses and times; nothing but the current packet is held in memory.
* :class:`FlowTracker` turns datagrams into links and directions: one UDP address pair is one CHUDP
  link, and the side that receives the first RFC is the server (failing that, the side a server-only
  packet comes from, or the side the first datagram goes to; ``server=`` says it outright).
* :func:`import_pcap` writes the CHUDP datagrams of a capture into a manip capture (MCAP) that
  ``manip-conform verify`` and ``replay`` accept: every datagram is recorded as a ``chudp`` frame,
  byte for byte.
* :func:`export_pcapng` writes the frames of a manip capture as CHUDP in UDP/IPv4 (link type raw IP),
  which Wireshark opens.  CHUDP frames go out byte for byte; a TCP-link frame is a CHUDP datagram with
  a 2-byte length in place of the 4-byte CHUDP header, so it is re-framed by swapping the two (words,
  trailer and checksum unchanged); a chaosd frame is re-encoded as CHUDP.  The section's comment says
  which links were re-framed, so the file does not pass for a recording of UDP traffic.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import struct
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from typing import IO, Any, Final

from manip import __version__
from manip.codecs.errors import CodecError, DecodeError
from manip.codecs.framing import CHUDP_HEADER, decode_chudp, encode_chudp
from manip.codecs.packet import Direction, Packet
from manip.outfile import OutputError, atomic_output
from manip.spec.constants import ChaosOp

from .reader import Capture, CapturedPacket, iter_packets
from .recorder import CaptureError, Recorder
from .view import Annotator, bad_frame

CHUDP_PORT: Final = 42042
"""The UDP port klh10, simh and the global Chaosnet use for CHUDP."""

# Link types (tcpdump.org's LINKTYPE_ numbers, which pcap and pcapng files carry).
LINKTYPE_NULL: Final = 0
LINKTYPE_ETHERNET: Final = 1
LINKTYPE_RAW: Final = 101
LINKTYPE_LOOP: Final = 108
LINKTYPE_LINUX_SLL: Final = 113
LINKTYPE_IPV4: Final = 228
LINKTYPE_IPV6: Final = 229
LINKTYPE_LINUX_SLL2: Final = 276
_RAW_IP_TYPES: Final = frozenset({LINKTYPE_RAW, 12, 14, LINKTYPE_IPV4, LINKTYPE_IPV6})
"""Raw IP: 101, and the DLT numbers 12 and 14 some systems write for it."""

Address = tuple[str, int]
"""An IP address (text) and a UDP port."""

_PCAP_MAGICS: Final = {b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d"}
_PCAPNG_MAGIC: Final = b"\x0a\x0d\x0d\x0a"


@dataclass(frozen=True, slots=True)
class Datagram:
    """One UDP datagram of a capture file."""

    number: int
    """Its frame number in the file, from 1 (as Wireshark numbers them)."""
    time_ns: int
    src: Address
    dst: Address
    payload: bytes


@dataclass(slots=True)
class PcapStats:
    """What a pass over a capture file saw."""

    frames: int = 0
    udp: int = 0
    """UDP datagrams (any port)."""
    selected: int = 0
    """UDP datagrams on the ports asked for (all of them when no port was given)."""
    not_udp: int = 0
    """Frames that are not UDP over IPv4 or IPv6 (or are IP fragments after the first)."""
    cut: int = 0
    """UDP datagrams not captured whole (the snap length, or the file ends inside one): left out."""

    def summary(self) -> str:
        return (
            f"{self.frames} frames, {self.udp} UDP datagrams, {self.selected} on the ports asked for, "
            f"{self.not_udp} not UDP" + (f", {self.cut} cut short (left out)" if self.cut else "")
        )


def _ip_of(frame: bytes, linktype: int) -> Any:
    """The IP packet of a link-layer frame (a dpkt IP or IP6), or None."""
    import dpkt  # noqa: PLC0415  # imported on first use: most commands never read a pcap

    if linktype == LINKTYPE_ETHERNET:
        return dpkt.ethernet.Ethernet(frame).data
    if linktype == LINKTYPE_LINUX_SLL:
        return dpkt.sll.SLL(frame).data
    if linktype == LINKTYPE_LINUX_SLL2:
        return dpkt.sll2.SLL2(frame).data
    if linktype in (LINKTYPE_NULL, LINKTYPE_LOOP):
        # The address family is host order (NULL) or network order (LOOP); 2 is IPv4 everywhere,
        # IPv6 is 24, 28 or 30 depending on the system: the version nibble says which.
        body = frame[4:]
    elif linktype in _RAW_IP_TYPES:
        body = frame
    else:
        raise CaptureError(
            f"link type {linktype} is not one manip reads (Ethernet, Linux cooked, loopback, raw IP)"
        )
    if not body:
        return None
    return dpkt.ip.IP(body) if body[0] >> 4 == 4 else dpkt.ip6.IP6(body) if body[0] >> 4 == 6 else None


def _udp(ip: Any) -> tuple[Address, Address, bytes] | None:
    import dpkt  # noqa: PLC0415

    if isinstance(ip, dpkt.ip.IP):
        if ip.p != 17 or ip.offset:
            return None
        family = socket.AF_INET
    elif isinstance(ip, dpkt.ip6.IP6):
        if ip.nxt != 17:
            return None
        family = socket.AF_INET6
    else:
        return None
    udp = ip.data
    if not isinstance(udp, dpkt.udp.UDP):
        return None
    src = (socket.inet_ntop(family, ip.src), int(udp.sport))
    dst = (socket.inet_ntop(family, ip.dst), int(udp.dport))
    payload = bytes(udp.data)
    if udp.ulen >= 8:  # Ethernet pads short frames: the UDP length says where the datagram ends
        if len(payload) < udp.ulen - 8:
            raise _Cut
        payload = payload[: udp.ulen - 8]
    return src, dst, payload


class _Cut(Exception):  # noqa: N818  # internal signal, never seen outside this module
    """The datagram was not captured whole (a snap length, or the file ends inside it)."""


def _time_ns(ts: float | Decimal) -> int:
    if isinstance(ts, Decimal):
        return int(ts * 1_000_000_000)
    return round(ts * 1_000_000) * 1000  # the float holds microseconds exactly, no more


MAX_PCAP_RECORD: Final = 1 << 20
"""The longest packet record or block read from a pcap or pcapng file: 1 MiB.  A UDP datagram is at
most 64 KiB and tcpdump's largest snap length 256 KiB; a longer length field is damage (and reading it
would allocate whatever it claims)."""


class _RecordTooLongError(Exception):
    def __init__(self, offset: int, length: int) -> None:
        super().__init__(
            f"damaged at byte {offset}: a packet record claims {length} bytes "
            f"(at most {MAX_PCAP_RECORD} are read)"
        )


class _Bounded:
    """The file as dpkt reads it, refusing a read longer than :data:`MAX_PCAP_RECORD` (a length field
    that lies) before anything is allocated."""

    def __init__(self, stream: IO[bytes]) -> None:
        self._stream = stream

    def read(self, size: int = -1) -> bytes:
        if size < 0 or size > MAX_PCAP_RECORD:
            raise _RecordTooLongError(self._stream.tell(), size)
        return self._stream.read(size)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


def _open_reader(stream: IO[bytes], name: str) -> Any:
    import dpkt  # noqa: PLC0415

    magic = stream.read(4)
    stream.seek(0)
    if not magic:
        raise CaptureError(f"{name} is empty: not a pcap or pcapng file")
    try:
        if magic == _PCAPNG_MAGIC:
            return dpkt.pcapng.Reader(_Bounded(stream))
        if magic in _PCAP_MAGICS:
            return dpkt.pcap.Reader(_Bounded(stream))
    except _RecordTooLongError as exc:
        raise CaptureError(f"{name}: {exc}") from None
    except (ValueError, dpkt.Error, struct.error) as exc:
        raise CaptureError(f"{name}: damaged pcap header: {exc}") from exc
    raise CaptureError(f"{name} is not a pcap or pcapng file (it starts with {magic.hex(' ')})")


def _records(reader: Any, name: str) -> Iterator[tuple[float | Decimal, bytes]]:
    """(time, frame) of each packet record; a file cut inside one ends there, a length that lies is an
    error."""
    import dpkt  # noqa: PLC0415

    packets = iter(reader)
    while True:
        try:
            ts, frame = next(packets)
        except StopIteration:
            return
        except _RecordTooLongError as exc:
            raise CaptureError(f"{name}: {exc}") from None
        except (dpkt.Error, struct.error, ValueError):
            return  # cut inside a packet record
        yield ts, frame


def iter_datagrams(
    source: str | os.PathLike[str] | IO[bytes],
    *,
    ports: Sequence[int] = (),
    stats: PcapStats | None = None,
) -> Iterator[Datagram]:
    """The UDP datagrams of a pcap or pcapng file, in file order (``ports``: only those from or to them).

    Raises :class:`CaptureError` for a file that is missing, not a capture or cut short in its header;
    a file cut inside a later packet ends there (tcpdump killed mid-write leaves such files).
    """
    import dpkt  # noqa: PLC0415

    stats = PcapStats() if stats is None else stats
    wanted = frozenset(ports)
    name = (
        os.fspath(source) if isinstance(source, (str, os.PathLike)) else getattr(source, "name", "<stream>")
    )
    try:
        stream: IO[bytes] = open(source, "rb") if isinstance(source, (str, os.PathLike)) else source  # noqa: SIM115
    except FileNotFoundError:
        raise CaptureError(f"no such file: {name}") from None
    except OSError as exc:
        raise CaptureError(f"cannot read {name}: {exc.strerror}") from exc
    try:
        reader = _open_reader(stream, str(name))
        linktype = int(reader.datalink())
        for ts, frame in _records(reader, str(name)):
            stats.frames += 1
            try:
                found = _udp(_ip_of(frame, linktype))
            except _Cut:
                stats.cut += 1
                continue
            except (dpkt.Error, struct.error, ValueError, IndexError):
                found = None
            if found is None:
                stats.not_udp += 1
                continue
            stats.udp += 1
            src, dst, payload = found
            if wanted and src[1] not in wanted and dst[1] not in wanted:
                continue
            stats.selected += 1
            t_ns = _time_ns(ts)
            if not 0 <= t_ns < 1 << 63:
                raise CaptureError(
                    f"{name}: damaged at frame {stats.frames}: time stamp {ts} is out of range"
                )
            yield Datagram(stats.frames, t_ns, src, dst, payload)
    finally:
        if stream is not source:
            stream.close()


def looks_like_chudp(payload: bytes) -> bool:
    """True when a UDP payload starts like a CHUDP packet datagram (version 1, function 1)."""
    return len(payload) >= len(CHUDP_HEADER) and payload[0] == 1 and payload[1] == 1


def parse_host_port(text: str) -> Address:
    """``HOST:PORT`` (``[V6]:PORT``) as an address; ValueError says what is wrong."""
    host, sep, port = text.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"{text!r} is not HOST:PORT")
    host = host.strip("[]")
    try:
        host = str(ipaddress.ip_address(host))
    except ValueError:
        raise ValueError(f"{host!r} is not an IP address") from None
    return host, int(port)


def _shown(a: Address) -> str:
    return f"[{a[0]}]:{a[1]}" if ":" in a[0] else f"{a[0]}:{a[1]}"


# Packets only a server sends at the start of a conversation: the client cannot be their source.
_SERVER_FIRST: Final = frozenset({ChaosOp.OPN, ChaosOp.ANS})


@dataclass(slots=True)
class Flow:
    """One CHUDP link of a capture file: a client and a server address."""

    link: int
    client: Address
    server: Address

    @property
    def name(self) -> str:
        return f"chudp {_shown(self.client)} -> {_shown(self.server)}"


@dataclass(slots=True)
class FlowTracker:
    """Assigns each datagram its link (one per UDP address pair) and direction (see the module)."""

    server: Address | None = None
    flows: dict[frozenset[Address], Flow] = field(default_factory=dict)

    def place(self, d: Datagram) -> tuple[Flow, Direction, bool]:
        """The datagram's flow and direction, and whether the flow is new."""
        key = frozenset((d.src, d.dst))
        flow = self.flows.get(key)
        new = flow is None
        if flow is None:
            server = self._server_of(d)
            client = d.src if server == d.dst else d.dst
            flow = self.flows[key] = Flow(len(self.flows) + 1, client, server)
        return flow, ("c2s" if d.dst == flow.server else "s2c"), new

    def _server_of(self, d: Datagram) -> Address:
        if self.server is not None and self.server in (d.src, d.dst):
            return self.server
        opcode = d.payload[4] if len(d.payload) > 4 and looks_like_chudp(d.payload) else None  # word 0, MSB
        if opcode is not None and opcode in _SERVER_FIRST:
            return d.src
        if opcode is not None and opcode != ChaosOp.RFC and d.src[1] == CHUDP_PORT != d.dst[1]:
            return d.src
        return d.dst


def iter_pcap_packets(
    source: str | os.PathLike[str],
    *,
    ports: Sequence[int] = (),
    server: Address | None = None,
    stats: PcapStats | None = None,
) -> Iterator[CapturedPacket]:
    """The CHUDP datagrams of a pcap as captured packets (decoded and annotated, as a capture's would
    be), streaming.  Datagrams are taken as :func:`import_pcap` takes them; ``seq`` is the frame number
    in the file."""
    tracker = FlowTracker(server)
    annotator = Annotator()
    for d in iter_datagrams(source, ports=ports, stats=stats):
        if not ports and not looks_like_chudp(d.payload):
            continue
        flow, direction, _ = tracker.place(d)
        packet: Packet | None
        try:
            packet = decode_chudp(d.payload)
        except DecodeError as exc:
            packet = None
            annotation = bad_frame(exc)
        else:
            annotation = annotator.annotate(flow.link, direction, packet)
        yield CapturedPacket(d.number, d.time_ns, flow.link, direction, d.payload, packet, annotation)


# ---------------------------------------------------------------------------------------- import


@dataclass(slots=True)
class ImportReport:
    """What :func:`import_pcap` wrote."""

    source: str
    output: str
    stats: PcapStats
    flows: list[Flow]
    frames: int = 0
    skipped: Counter[str] = field(default_factory=Counter)

    def summary(self) -> str:
        lines = [
            f"imported {self.frames} CHUDP datagrams of {self.source} into {self.output} "
            f"({len(self.flows)} link(s))",
            f"  {self.stats.summary()}",
        ]
        lines += [f"  L{f.link}: {f.name}" for f in self.flows]
        lines += [f"  skipped {n}: {why}" for why, n in sorted(self.skipped.items())]
        return "\n".join(lines)


def import_pcap(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    ports: Sequence[int] = (),
    server: Address | None = None,
    command_line: Sequence[str] | None = None,
) -> ImportReport:
    """Write the CHUDP datagrams of a pcap or pcapng file into a manip capture at ``output``.

    Without ``ports`` every UDP datagram that starts like CHUDP is taken; with them, every datagram
    from or to those ports (one that is not CHUDP is kept as a bad frame, as a recorder would).
    """
    stats = PcapStats()
    tracker = FlowTracker(server)
    report = ImportReport(os.fspath(source), os.fspath(output), stats, [])
    datagrams = iter_datagrams(source, ports=ports, stats=stats)
    first = next(datagrams, None)  # a missing or unreadable file fails before the output is made
    with Recorder(
        output,
        how=f"import of {os.path.basename(os.fspath(source))}",
        command_line=command_line,
        metadata={"imported_from": os.fspath(source)},
        clock_ns=lambda: first.time_ns if first is not None else 0,
    ) as recorder:
        links: dict[int, int] = {}
        for d in _chain(first, datagrams):
            if not ports and not looks_like_chudp(d.payload):
                report.skipped["UDP datagrams that are not CHUDP"] += 1
                continue
            flow, direction, new = tracker.place(d)
            if new:
                links[flow.link] = recorder.open_link("chudp", name=flow.name, t_ns=d.time_ns)
                report.flows.append(flow)
            recorder.frame(links[flow.link], direction, d.payload, d.time_ns)
            report.frames += 1
            last = d.time_ns
        if report.frames:
            recorder.clock_ns = lambda: last
    return report


def _chain(first: Datagram | None, rest: Iterator[Datagram]) -> Iterator[Datagram]:
    if first is not None:
        yield first
        yield from rest


# ---------------------------------------------------------------------------------------- export


SERVER_ADDRESS: Final = ("127.0.0.1", CHUDP_PORT)
"""Where the exported server sits; each link's client is 127.0.1.N (N = link id), port 42042."""


def _client_address(link: int) -> Address:
    return (str(ipaddress.IPv4Address("127.0.1.0") + link % 65536), CHUDP_PORT)


def _udp_ipv4(src: Address, dst: Address, payload: bytes, ident: int) -> bytes:
    import dpkt  # noqa: PLC0415

    udp = dpkt.udp.UDP(sport=src[1], dport=dst[1], data=payload, ulen=8 + len(payload))
    ip = dpkt.ip.IP(
        src=socket.inet_aton(src[0]),
        dst=socket.inet_aton(dst[0]),
        p=dpkt.ip.IP_PROTO_UDP,
        ttl=64,
        id=ident & 0xFFFF,
        data=udp,
        len=20 + 8 + len(payload),
    )
    return bytes(ip)


@dataclass(slots=True)
class ExportReport:
    """What :func:`export_pcapng` wrote."""

    source: str
    output: str
    datagrams: int = 0
    reframed: dict[int, str] = field(default_factory=dict)
    """Link id -> its framing, for the links whose frames were re-framed as CHUDP."""
    skipped: Counter[str] = field(default_factory=Counter)

    def summary(self) -> str:
        lines = [f"exported {self.datagrams} CHUDP datagrams of {self.source} into {self.output}"]
        lines += [f"  L{k}: {v} frames re-framed as CHUDP" for k, v in sorted(self.reframed.items())]
        lines += [f"  skipped {n}: {why}" for why, n in sorted(self.skipped.items())]
        return "\n".join(lines)


def _as_chudp(framing: str, frame: bytes, packet: Any) -> bytes | None:
    """The CHUDP datagram carrying a recorded frame, or None when it cannot be made."""
    if framing == "chudp":
        return frame
    if framing == "tcp" and len(frame) >= 2:
        return CHUDP_HEADER + frame[2:]  # the same words: only the delimiting differs
    if packet is None:
        return None
    trailer = packet.trailer
    try:
        if trailer is None:
            return encode_chudp(packet)
        return encode_chudp(packet, hw_dest=trailer.dest, hw_src=trailer.source)
    except CodecError:
        return None


def _link_framings(source: str) -> dict[int, tuple[str, str]]:
    """Link id -> (framing, name) of a capture's raw channels, from a first pass over the file (which
    also finds any damage before the output is begun)."""
    if not os.path.exists(source):
        raise CaptureError(f"no such file: {source}")
    capture = Capture(source)
    for _ in iter_packets(source, capture=capture):
        pass
    return {link: (info.framing, info.name) for link, info in capture.links.items()}


def export_comment(source: str, links: dict[int, tuple[str, str]]) -> str:
    """The section comment of an exported file: where it comes from, and which links were re-framed."""
    lines = [
        f"Exported by manip-capture {__version__} from {os.path.basename(source)}.",
        f"Each Chaos packet is one CHUDP datagram (UDP port {CHUDP_PORT}) in IPv4; the server is "
        f"{_shown(SERVER_ADDRESS)}, the client of link N is 127.0.1.N.",
    ]
    for link, (framing, name) in sorted(links.items()):
        shown = f" ({name})" if name else ""
        if framing == "chudp":
            how = "recorded as CHUDP; datagrams byte for byte"
        elif framing == "tcp":
            how = (
                "manip TCP-link frames re-framed as CHUDP: the 2-byte length replaced by the CHUDP "
                "header 01 01 00 00; header, data, trailer and checksum unchanged"
            )
        else:
            how = f"{framing} frames re-encoded as CHUDP (checksum computed afresh)"
        lines.append(f"Link {link}{shown}: {how}.")
    return "\n".join(lines)


def _write_pcapng(
    stream: IO[bytes], src: str, links: dict[int, tuple[str, str]], shb: Any, idb: Any, report: ExportReport
) -> None:
    import dpkt  # noqa: PLC0415

    dpkt.pcapng.Writer(stream, shb=shb, idb=idb)  # writes the section and interface blocks
    for item in iter_packets(src):
        framing = links.get(item.link, ("raw", ""))[0]
        payload = _as_chudp(framing, item.frame, item.packet)
        if payload is None:
            report.skipped[f"{framing} frames that do not decode (cannot be re-framed)"] += 1
            continue
        client = _client_address(item.link)
        ends = (client, SERVER_ADDRESS) if item.direction == "c2s" else (SERVER_ADDRESS, client)
        frame = _udp_ipv4(*ends, payload, item.seq)
        # Nanosecond times (if_tsresol 9): the writer's own packing is in microseconds.
        t = item.time_ns
        stream.write(
            bytes(dpkt.pcapng.EnhancedPacketBlockLE(ts_high=t >> 32, ts_low=t & 0xFFFFFFFF, pkt_data=frame))
        )
        report.datagrams += 1


def export_pcapng(source: str | os.PathLike[str], output: str | os.PathLike[str] | IO[bytes]) -> ExportReport:
    """Write every frame of a manip capture as a CHUDP datagram in UDP/IPv4 into a pcapng file."""
    import dpkt  # noqa: PLC0415

    src = os.fspath(source)
    links = _link_framings(src)
    out_name = os.fspath(output) if isinstance(output, (str, os.PathLike)) else getattr(output, "name", "")
    report = ExportReport(src, str(out_name) or "<stream>")
    report.reframed = {k: f for k, (f, _) in links.items() if f != "chudp"}
    end = dpkt.pcapng.PcapngOptionLE(code=dpkt.pcapng.PCAPNG_OPT_ENDOFOPT)
    shb = dpkt.pcapng.SectionHeaderBlockLE(
        opts=[
            dpkt.pcapng.PcapngOptionLE(code=dpkt.pcapng.PCAPNG_OPT_COMMENT, text=export_comment(src, links)),
            end,
        ]
    )
    idb = dpkt.pcapng.InterfaceDescriptionBlockLE(
        snaplen=65535,
        linktype=LINKTYPE_RAW,
        opts=[
            dpkt.pcapng.PcapngOptionLE(code=dpkt.pcapng.PCAPNG_OPT_IF_NAME, data=b"manip"),
            dpkt.pcapng.PcapngOptionLE(code=dpkt.pcapng.PCAPNG_OPT_IF_TSRESOL, data=b"\x09"),
            end,
        ],
    )
    if isinstance(output, (str, os.PathLike)):
        try:
            with atomic_output(output, "wb") as stream:
                _write_pcapng(stream, src, links, shb, idb, report)
        except OutputError as exc:
            raise CaptureError(str(exc)) from exc
    else:
        _write_pcapng(output, src, links, shb, idb, report)
    return report


__all__ = [
    "CHUDP_PORT",
    "Datagram",
    "ExportReport",
    "Flow",
    "FlowTracker",
    "ImportReport",
    "PcapStats",
    "export_pcapng",
    "import_pcap",
    "iter_datagrams",
    "iter_pcap_packets",
    "looks_like_chudp",
    "parse_host_port",
]
