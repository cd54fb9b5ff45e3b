"""The raw-Chaos NCP cases (manip.conformance.cases.server.ncp): the reference server passes them, a small
conforming fake NCP passes them, and a fake with one flaw at a time fails the case written for it.

The fake is deliberately tiny (no manip layer: every data packet is answered by a RESPONSE quoting its
number) so that each flaw is one switch and nothing else differs between the clean and the broken run.
"""

from __future__ import annotations

import asyncio
import contextlib
import struct
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import pytest

from manip.codecs.framing import CHUDP_HEADER, encode_chudp, encode_tcp
from manip.codecs.packet import MAX_DATA, Packet
from manip.conformance.suite.busy import BUSY_RETRIES
from manip.conformance.suite.case import all_cases
from manip.conformance.suite.context import RunOptions
from manip.conformance.suite.rawchaos import (
    RawError,
    RawPeer,
    Received,
    RefusedError,
    format_packet,
    rfc_until_open,
)
from manip.conformance.suite.results import CaseResult
from manip.conformance.suite.runner import RunConfig, Runner
from manip.links import NcpConfig
from manip.links.virtual_clock import run as run_loop
from manip.ncp.packets import is_data, is_legal_opcode, make_los, pack_status, unpack_status
from manip.ncp.seq import seq_add, seq_gt, seq_le, seq_sub
from manip.reference_server.driver import serve
from manip.spec.constants import ChaosOp

SERVER_ADDR = 0o440
RETRANSMIT = 0.3
DupRfc = Literal["same", "ignore", "new", "refuse"]

CASES = {c.id: c for c in all_cases() if c.id.startswith("server.ncp.")}


@dataclass(frozen=True)
class Flaws:
    """What the fake NCP does wrong (the defaults conform)."""

    retransmit: bool = True
    stop_on_receipt: bool = True
    window: bool = True
    receipt_opens_window: bool = False
    deliver_duplicates: bool = False
    los_unknown: bool = True
    los_answers_los: bool = False
    los_illegal: bool = True
    dup_rfc: DupRfc = "same"
    acknowledge: bool = True


# ------------------------------------------------------------------------------------- the fake NCP


def parse_body(body: bytes) -> Packet | None:
    """Header words and data of a packet-plus-trailer body (MSB-first words) with no legality checks."""
    if len(body) < 22 or len(body) & 1:
        return None
    words = struct.unpack(f">{len(body) // 2}H", body)
    nbytes = words[1] & 0xFFF
    data = struct.pack(f"<{len(words) - 11}H", *words[8:-3])[:nbytes]
    return Packet(words[0] >> 8, words[2], words[3], words[4], words[5], words[6], words[7], data)


Send = Callable[[Packet], None]


@dataclass
class FakeConn:
    index: int
    peer_host: int
    peer_index: int
    rfc_no: int
    send: Send
    opn: Packet | None = None
    tlast: int = 100
    tacked: int = 100
    receipted: int = 100
    twsize: int = 0
    rlast: int = 0
    opened: bool = False
    queue: dict[int, list[object]] = field(default_factory=dict)
    pending: list[bytes] = field(default_factory=list)


class FakeNcp:
    """A one-host NCP serving a fake 'manip' contact; see the module docstring."""

    def __init__(self, flaws: Flaws) -> None:
        self.flaws = flaws
        self.conns: dict[int, FakeConn] = {}
        self.next_index = 0x2001

    def _acked(self, conn: FakeConn) -> int:
        """What the fake acknowledges: all it received, or (flawed) never beyond the RFC."""
        return conn.rlast if self.flaws.acknowledge else conn.rfc_no

    def _out(self, conn: FakeConn, opcode: int, number: int, data: bytes) -> Packet:
        return Packet(
            opcode, conn.peer_host, conn.peer_index, SERVER_ADDR, conn.index, number, self._acked(conn), data
        )

    def _open(self, p: Packet, send: Send) -> None:
        conn = FakeConn(self.next_index, p.src_host, p.src_index, p.packet_no, send, rlast=p.packet_no)
        self.next_index += 0x0101
        self.conns[conn.index] = conn
        conn.opn = self._out(conn, ChaosOp.OPN, conn.tlast, pack_status(p.packet_no, 15))
        conn.queue[conn.tlast] = [conn.opn, asyncio.get_running_loop().time()]
        send(conn.opn)

    def receive(self, p: Packet, send: Send) -> None:
        flaws = self.flaws
        if len(p.data) > MAX_DATA or not is_legal_opcode(p.opcode):
            if flaws.los_illegal:
                send(make_los(p, SERVER_ADDR, "Illegal packet"))
            return
        if p.opcode == ChaosOp.RFC:
            live = [
                c for c in self.conns.values() if (c.peer_host, c.peer_index) == (p.src_host, p.src_index)
            ]
            if not live or flaws.dup_rfc == "new":
                self._open(p, send)
            elif flaws.dup_rfc == "same" and live[0].opn is not None:
                send(live[0].opn)
            elif flaws.dup_rfc == "refuse":
                send(Packet(ChaosOp.CLS, p.src_host, p.src_index, SERVER_ADDR, 0, 0, 0, b"Busy"))
            return
        conn = self.conns.get(p.dest_index)
        if conn is None or (conn.peer_host, conn.peer_index) != (p.src_host, p.src_index):
            if p.opcode in (ChaosOp.LOS, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD):
                if p.opcode == ChaosOp.LOS and flaws.los_answers_los:
                    send(make_los(p, SERVER_ADDR, "Connection doesn't exist"))
            elif flaws.los_unknown:
                send(make_los(p, SERVER_ADDR, "Connection doesn't exist"))
            return
        self._on_conn(conn, p)
        self._flush(conn)

    def _on_conn(self, conn: FakeConn, p: Packet) -> None:
        if p.opcode == ChaosOp.CLS:
            del self.conns[conn.index]
            return
        if seq_gt(p.ack_no, conn.tacked) and seq_le(p.ack_no, conn.tlast):
            conn.tacked = p.ack_no
            conn.receipted = p.ack_no if seq_gt(p.ack_no, conn.receipted) else conn.receipted
        if p.opcode == ChaosOp.STS and (status := unpack_status(p.data)) is not None:
            receipt, conn.twsize = status
            if seq_gt(receipt, conn.receipted) and seq_le(receipt, conn.tlast):
                conn.receipted = receipt
                if self.flaws.receipt_opens_window:
                    conn.tacked = receipt
            if not conn.opened:
                conn.opened = True
                conn.pending.append(conn.rfc_no.to_bytes(2, "little"))
        elif p.opcode == ChaosOp.SNS:
            self._sts(conn)
        elif is_data(p.opcode) or p.opcode == ChaosOp.EOF:
            n = p.packet_no
            if n == seq_add(conn.rlast, 1):
                conn.rlast = n
                if p.opcode == ChaosOp.EOF:
                    self._sts(conn)
                else:
                    conn.pending.append(n.to_bytes(2, "little"))
            elif seq_le(n, conn.rlast):
                if self.flaws.deliver_duplicates and is_data(p.opcode):
                    conn.pending.append(n.to_bytes(2, "little"))
                else:
                    self._sts(conn)
        if self.flaws.stop_on_receipt:
            for number in [k for k in conn.queue if seq_le(k, conn.receipted)]:
                del conn.queue[number]

    def _sts(self, conn: FakeConn) -> None:
        conn.send(self._out(conn, ChaosOp.STS, seq_add(conn.tlast, 1), pack_status(self._acked(conn), 15)))

    def _flush(self, conn: FakeConn) -> None:
        while conn.pending and (not self.flaws.window or seq_sub(conn.tlast, conn.tacked) < conn.twsize):
            conn.tlast = seq_add(conn.tlast, 1)
            packet = self._out(conn, ChaosOp.DAT, conn.tlast, conn.pending.pop(0))
            conn.queue[conn.tlast] = [packet, asyncio.get_running_loop().time()]
            conn.send(packet)

    def tick(self, now: float) -> None:
        if not self.flaws.retransmit:
            return
        for conn in list(self.conns.values()):
            for entry in conn.queue.values():
                packet, sent_at = entry
                assert isinstance(packet, Packet) and isinstance(sent_at, float)
                if now - sent_at >= RETRANSMIT:
                    entry[1] = now
                    conn.send(replace(packet, ack_no=self._acked(conn)))


@contextlib.asynccontextmanager
async def fake_server(flaws: Flaws, scheme: str = "tcp") -> AsyncIterator[str]:
    """Run the fake NCP on a loopback port; yield its address."""
    ncp = FakeNcp(flaws)
    loop = asyncio.get_running_loop()

    async def ticker() -> None:
        while True:
            await asyncio.sleep(0.05)
            ncp.tick(loop.time())

    tick_task = loop.create_task(ticker())
    try:
        if scheme == "tcp":

            async def client(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
                def send(p: Packet) -> None:
                    if not writer.is_closing():
                        writer.write(encode_tcp(p, hw_dest=p.dest_host, hw_src=SERVER_ADDR))

                with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError):
                    while True:
                        size = int.from_bytes(await reader.readexactly(2), "big")
                        packet = parse_body(await reader.readexactly(size))
                        if packet is not None:
                            ncp.receive(packet, send)
                writer.close()

            server = await asyncio.start_server(client, "127.0.0.1", 0)
            async with server:
                yield f"tcp://127.0.0.1:{server.sockets[0].getsockname()[1]}"
                server.close()
        else:

            class Udp(asyncio.DatagramProtocol):
                def connection_made(self, transport: asyncio.BaseTransport) -> None:
                    self.transport = transport

                def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
                    def send(p: Packet) -> None:
                        self.transport.sendto(encode_chudp(p, hw_dest=p.dest_host, hw_src=SERVER_ADDR), addr)  # type: ignore[attr-defined]

                    if data[:4] == CHUDP_HEADER and (packet := parse_body(data[4:])) is not None:
                        ncp.receive(packet, send)

            transport, _ = await loop.create_datagram_endpoint(Udp, local_addr=("127.0.0.1", 0))
            try:
                yield f"chudp://127.0.0.1:{transport.get_extra_info('sockname')[1]}?addr=440"
            finally:
                transport.close()
    finally:
        tick_task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await tick_task


# ------------------------------------------------------------------------------------- running cases


async def _run_case(
    address: str, case_id: str, seed: int = 7, broken_after: float | None = None
) -> CaseResult:
    options = RunOptions(address=address, reply_timeout=1.0, connect_timeout=2.0, broken_after=broken_after)
    config = RunConfig(options=options, seed=seed)
    return await Runner(config, list(CASES.values())).run_case(CASES[case_id])


def _against_fake(case_id: str, flaws: Flaws, scheme: str = "tcp") -> CaseResult:
    async def go() -> CaseResult:
        async with fake_server(flaws, scheme) as address:
            return await _run_case(address, case_id)

    return asyncio.run(go())


def _against_reference(case_id: str, address: str = "tcp://127.0.0.1:0") -> CaseResult:
    async def go() -> CaseResult:
        async with serve(address) as server:
            return await _run_case(server.address, case_id)

    return asyncio.run(go())


def _why(result: CaseResult) -> str:
    return (
        f"{result.outcome}: {result.reason} {[(v.message, v.expected, v.actual) for v in result.violations]}"
    )


# ------------------------------------------------------------------------------------- tests

CONFORMING_CASES = [
    "server.ncp.los-unknown-connection",
    "server.ncp.duplicate-rfc",
    "server.ncp.retransmission",
    "server.ncp.window",
    "server.ncp.acknowledge",
]


def test_the_cases_cover_the_ncp_clauses() -> None:
    clauses = {c for item in CASES.values() for c in item.clauses}
    assert {"ncp.los", "ncp.window", "ncp.retransmission", "ncp.duplicate-rfc", "ncp.acknowledge"} <= clauses
    assert {item.kind for item in CASES.values()} <= {"negative", "scripted"}
    assert all(item.hazard == "read-only" for item in CASES.values())


@pytest.mark.parametrize("case_id", CONFORMING_CASES)
def test_reference_server_passes(case_id: str) -> None:
    result = _against_reference(case_id)
    assert result.outcome == "pass", _why(result)


def test_oversize_is_skipped_on_tcp() -> None:
    result = _against_reference("server.ncp.los-oversize")
    assert result.outcome == "skip"


def test_reference_server_answers_an_illegal_opcode() -> None:
    result = _against_reference("server.ncp.los-illegal-opcode")
    assert result.outcome == "pass", _why(result)


@pytest.mark.parametrize(
    ("case_id", "scheme"),
    [(c, "tcp") for c in CONFORMING_CASES]
    + [("server.ncp.los-illegal-opcode", "tcp"), ("server.ncp.los-oversize", "chudp")],
)
def test_conforming_fake_passes(case_id: str, scheme: str) -> None:
    result = _against_fake(case_id, Flaws(), scheme)
    assert result.outcome == "pass", _why(result)


@pytest.mark.parametrize(
    ("case_id", "flaws", "clause", "says"),
    [
        ("server.ncp.los-unknown-connection", Flaws(los_unknown=False), "ncp.los", "no LOS"),
        ("server.ncp.los-unknown-connection", Flaws(los_answers_los=True), "ncp.los", "LOS to a connection"),
        (
            "server.ncp.los-illegal-opcode",
            Flaws(los_illegal=False),
            "chaos.opcode.legal",
            "no LOS for opcode",
        ),
        ("server.ncp.duplicate-rfc", Flaws(dup_rfc="new"), "ncp.duplicate-rfc", "second connection"),
        ("server.ncp.duplicate-rfc", Flaws(dup_rfc="refuse"), "ncp.duplicate-rfc", "new request"),
        ("server.ncp.retransmission", Flaws(retransmit=False), "ncp.retransmission", "not sent again"),
        ("server.ncp.retransmission", Flaws(stop_on_receipt=False), "ncp.retransmission", "kept coming"),
        (
            "server.ncp.retransmission",
            Flaws(deliver_duplicates=True),
            "ncp.retransmission",
            "answered a second",
        ),
        ("server.ncp.window", Flaws(window=False), "ncp.window", "nothing acknowledged yet"),
        ("server.ncp.window", Flaws(receipt_opens_window=True), "ncp.window", "receipt"),
        ("server.ncp.acknowledge", Flaws(acknowledge=False), "ncp.acknowledge", "never acknowledged"),
    ],
)
def test_flawed_fake_fails(case_id: str, flaws: Flaws, clause: str, says: str) -> None:
    result = _against_fake(case_id, flaws)
    assert result.outcome == "fail", _why(result)
    violation = result.violations[0]
    assert violation.clause == clause
    assert says in violation.message
    assert violation.expected and violation.actual
    assert violation.data, "a failure shows the packet bytes"


def test_oversize_on_chudp_flawed_fake_fails() -> None:
    result = _against_fake("server.ncp.los-oversize", Flaws(los_illegal=False), "chudp")
    assert result.outcome == "fail", _why(result)
    assert len(result.violations[0].data) > 4 + 16 + MAX_DATA  # the forged datagram itself


def test_duplicate_rfc_ignored_passes() -> None:
    """Ignoring a duplicate RFC (the retransmitted OPN then answers it) conforms as well."""
    result = _against_fake("server.ncp.duplicate-rfc", Flaws(dup_rfc="ignore"))
    assert result.outcome == "pass", _why(result)


def test_broken_is_not_judged_unless_the_run_knows_the_timer() -> None:
    result = _against_reference("server.ncp.broken")
    assert result.outcome == "not-judged" and "--broken-after" in result.reason


def _broken_against_reference(server_timer: float, told: float) -> CaseResult:
    async def go() -> CaseResult:
        async with serve("tcp://127.0.0.1:0", options=NcpConfig.breaking_after(server_timer)) as server:
            return await _run_case(server.address, "server.ncp.broken", broken_after=told)

    return asyncio.run(go())


def test_reference_server_gives_up_a_silent_connection() -> None:
    result = _broken_against_reference(1.0, told=1.0)
    assert result.outcome == "pass", _why(result)
    assert any("SNS probe" in note for note in result.notes)
    assert result.deadline > 1.0 + CASES["server.ncp.broken"].deadline  # the wait is on top


@pytest.mark.waits
def test_a_server_that_keeps_a_silent_connection_is_caught() -> None:
    result = _broken_against_reference(60.0, told=1.0)
    assert result.outcome == "warn", _why(result)  # a SHOULD clause
    assert result.violations[0].clause == "ncp.broken"
    assert "LOS" in result.violations[0].expected


def test_raw_peer_handshake_and_forged_frames() -> None:
    """The raw peer opens a connection by hand and forges frames the codecs refuse to encode."""

    async def go() -> None:
        async with fake_server(Flaws()) as address, await RawPeer.open(address) as peer:
            conn = await peer.handshake(0x0A01, 0xFFFF)
            assert conn.opn.packet.ack_no == 0xFFFF and conn.next_packet_no == 0
            conn.sts(ack=conn.opn_no, window=3)
            initial = await peer.receive(conn.mine, 2.0)
            assert initial is not None and initial.packet.data == (0xFFFF).to_bytes(2, "little")
            forged = peer.send_forged(conn.packet(0o20, packet_no=5, data=b"x"))
            assert forged[2] == 0o20 and len(forged) == 2 + 16 + 2 + 6
            los = await peer.receive(lambda p: p.opcode == ChaosOp.LOS, 2.0)
            assert los is not None and los.raw[2] == ChaosOp.LOS
            assert "LOS" in format_packet(los.packet)

    asyncio.run(go())


# ------------------------------------------------------------------------------------ opening by hand


def _opening(answers: list[Packet | None], *, ended: str | None = None) -> tuple[int, Received | Exception]:
    """``rfc_until_open`` against scripted answers (None: nothing within the wait), in virtual time: how
    many RFCs went out, and what it returned or raised."""
    sent: list[int] = []

    async def answer(wait: float) -> Received | None:
        packet = answers.pop(0) if answers else None
        if packet is None:
            await asyncio.sleep(wait)
            return None
        return Received(packet, b"", 0.0)

    async def go() -> Received | Exception:
        try:
            return await rfc_until_open(
                lambda: sent.append(1), answer, contact="PUMA", timeout=5.0, ended=lambda: ended
            )
        except RawError as exc:
            return exc

    outcome = run_loop(go(), virtual=True)
    return len(sent), outcome


def _answer(opcode: int, text: bytes = b"") -> Packet:
    return Packet(opcode, 0o401, 0x0A01, 0o440, 1, 7, 0, text)


def test_both_raw_openers_retry_busy_and_refuse_the_rest_alike() -> None:
    tries, got = _opening(
        [_answer(ChaosOp.CLS, b"Busy"), _answer(ChaosOp.CLS, b"busy"), _answer(ChaosOp.OPN)]
    )
    assert tries == 3 and isinstance(got, Received) and got.packet.opcode == ChaosOp.OPN
    tries, got = _opening([None, _answer(ChaosOp.OPN)])  # an RFC lost: sent again after RFC_RETRY
    assert tries == 2 and isinstance(got, Received)
    tries, got = _opening([_answer(ChaosOp.CLS, b"no such contact")])
    assert tries == 1 and isinstance(got, RefusedError) and "no such contact" in str(got)
    tries, got = _opening([_answer(ChaosOp.CLS, b"Busy")] * 1000)  # busy past the patience: refused
    assert isinstance(got, RefusedError) and "'Busy'" in str(got) and tries == 1 + BUSY_RETRIES
    tries, got = _opening([], ended="the target closed the link")
    assert tries == 1 and isinstance(got, RawError) and "the target closed the link" in str(got)
