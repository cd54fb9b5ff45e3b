"""Recording live sessions: the transparent proxy (TCP link and CHUDP), taps on either side, the CLI."""

from __future__ import annotations

import asyncio
from pathlib import Path

from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from manip.captures import Recorder, RecorderTap, Session, TappedLink, read_capture, read_session
from manip.captures.cli import main as capture_main
from manip.captures.proxy import Endpoint, TcpFrameCutter, parse_endpoint, start_proxy
from manip.codecs.framing import encode_tcp
from manip.codecs.messages import decode_reply, encode_request, request_op
from manip.codecs.packet import Packet
from manip.links import ChaosConnection, open_connection, start_server
from manip.reference_server.driver import serve
from manip.spec.constants import ServerOp


async def call(conn: ChaosConnection, op: str, **values: object) -> Packet:
    number = await conn.send(encode_request(op, **values), request_op(op).opcode)
    while True:
        packet = await asyncio.wait_for(conn.receive(), 5)
        if (
            packet.opcode != ServerOp.ASYNCHRONOUS_RESPONSE
            and int.from_bytes(packet.data[:2], "little") == number
        ):
            return packet


async def short_session(url: str) -> list[Packet]:
    conn = await open_connection(url, timeout=5)
    replies = [await asyncio.wait_for(conn.receive(), 5)]
    replies.append(await call(conn, "joint-angles"))
    replies.append(
        await call(conn, "move", transform=(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 3.0))
    )  # no power
    replies.append(await call(conn, "here"))
    await conn.close()
    return replies


def summary(session: Session) -> list[tuple[str, str | None, str]]:
    return [(p.direction, p.op, p.kind) for p in session.packets if p.kind != "control"]


EXPECTED = [
    ("s2c", "rfc", "reply"),
    ("c2s", "joint-angles", "request"),
    ("s2c", "joint-angles", "reply"),
    ("c2s", "move", "request"),
    ("s2c", "move", "error"),
    ("c2s", "here", "request"),
    ("s2c", "here", "reply"),
]


def test_tcp_proxy_records_a_real_session_transparently(tmp_path: Path) -> None:
    path = tmp_path / "proxy.mcap"

    async def run() -> list[Packet]:
        async with serve("tcp://127.0.0.1:0", time_scale=20.0) as server:
            with Recorder(path, how="proxy tcp") as rec:
                proxy, bound = await start_proxy(
                    rec, Endpoint("tcp", "127.0.0.1", 0), parse_endpoint(server.address)
                )
                try:
                    return await short_session(f"tcp://127.0.0.1:{bound.port}")
                finally:
                    await server.wait_idle()
                    await proxy.aclose()

    replies = asyncio.run(run())
    joints = decode_reply(replies[1].data, "joint-angles").values["joints"]
    capture = read_capture(path)
    (session,) = capture.sessions
    assert summary(session) == EXPECTED
    recorded = [p for p in session.server_packets if p.kind != "control"]
    assert [p.packet for p in recorded] == replies  # what the client got is what was recorded
    assert recorded[1].annotation.fields == {"joints": joints}
    assert [p.frame for p in session.packets] == [encode_tcp(p.packet) for p in session.packets if p.packet]
    assert {e.event for e in capture.events} >= {"link-open", "link-closed"}
    assert capture.metadata["manip.capture"]["recorded_by"] == "proxy tcp"


def test_chudp_relay_records_a_real_session(tmp_path: Path) -> None:
    path = tmp_path / "relay.mcap"

    async def run() -> None:
        async with serve("chudp://127.0.0.1:0?addr=440", time_scale=20.0) as server:
            with Recorder(path, how="proxy chudp") as rec:
                upstream = parse_endpoint(server.address)
                proxy, bound = await start_proxy(rec, Endpoint("chudp", "127.0.0.1", 0), upstream)
                try:
                    await short_session(f"chudp://127.0.0.1:{bound.port}?addr=440")
                    await server.wait_idle()
                finally:
                    await proxy.aclose()

    asyncio.run(run())
    capture = read_capture(path)
    assert capture.links[1].framing == "chudp"
    (session,) = capture.sessions
    assert summary(session) == EXPECTED


def test_taps_on_both_ends_record_the_same_session(tmp_path: Path) -> None:
    server_file, client_file = tmp_path / "server.mcap", tmp_path / "client.mcap"

    async def handler(conn: ChaosConnection) -> None:
        await conn.send(conn.rfc.packet_no.to_bytes(2, "little") if conn.rfc else b"\0\0", ServerOp.RESPONSE)
        async for packet in conn:
            reply = encode_reply_for(packet)
            await conn.send(reply, ServerOp.RESPONSE)

    async def run() -> None:
        with Recorder(server_file, how="server") as srec, Recorder(client_file, how="client") as crec:
            server = await start_server(
                "tcp://127.0.0.1:0", "PUMA", handler, wrap_link=RecorderTap(srec, "server").wrap
            )
            conn = await open_connection(
                f"tcp://127.0.0.1:{server.port}", wrap_link=RecorderTap(crec, "client").wrap
            )
            assert isinstance(conn.node.links[0], TappedLink)
            await conn.receive()
            for _ in range(3):
                await call(conn, "joint-angles")
            await conn.close()
            await server.aclose()

    asyncio.run(run())
    s, c = read_session(server_file), read_session(client_file)

    def data(session: Session) -> list[tuple[str, int, bytes, int | None]]:
        return [(p.direction, p.packet.packet_no, p.data, p.pair) for p in session.packets
                if p.packet is not None and p.packet.opcode >= 0o200]  # fmt: skip

    assert data(s) == data(c) and len(data(s)) == 7
    assert [p.op for p in s.requests] == ["joint-angles"] * 3


def encode_reply_for(packet: Packet) -> bytes:
    from manip.codecs.messages import encode_reply

    return encode_reply("joint-angles", packet.packet_no, joints=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0))


@settings(max_examples=80, deadline=None)
@given(
    st.lists(st.integers(0, 40), min_size=1, max_size=8),
    st.lists(st.integers(1, 64), min_size=1, max_size=20),
)
def test_the_frame_cutter_finds_every_frame_however_the_stream_is_split(
    sizes: list[int], cuts: list[int]
) -> None:
    frames = [
        encode_tcp(Packet(0o201, 0o440, 1, 0o401, 2, i, 0, bytes(range(n)))) for i, n in enumerate(sizes)
    ]
    stream = b"".join(frames)
    cutter, got, pos, i = TcpFrameCutter(), [], 0, 0
    while pos < len(stream):
        step = cuts[i % len(cuts)]
        got += cutter.feed(stream[pos : pos + step])
        pos, i = pos + step, i + 1
    assert got == frames and cutter.pending == 0 and cutter.lost is None


def test_the_frame_cutter_stops_at_an_impossible_length() -> None:
    cutter = TcpFrameCutter()
    good = encode_tcp(Packet(0o201, 0o440, 1, 0o401, 2, 1, 0, b""))
    assert cutter.feed(good + b"\x00\x03abc") == [good]
    assert cutter.lost is not None and "length 3" in cutter.lost
    assert cutter.feed(good) == []


def test_cli_info_and_recover(tmp_path: Path) -> None:
    path = tmp_path / "proxy.mcap"

    async def run() -> None:
        async with serve("tcp://127.0.0.1:0", time_scale=20.0) as server:
            with Recorder(path) as rec:
                proxy, bound = await start_proxy(
                    rec, Endpoint("tcp", "127.0.0.1", 0), parse_endpoint(server.address)
                )
                await short_session(f"tcp://127.0.0.1:{bound.port}")
                await server.wait_idle()
                await proxy.aclose()

    asyncio.run(run())
    runner = CliRunner()
    result = runner.invoke(capture_main, ["info", str(path)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "spec_revision" in out and "sessions: 1" in out and "contact 'PUMA'" in out
    assert "request joint-angles" in out and "non-fatal-error" in out and "E NAP" in out
    cut = tmp_path / "cut.mcap"
    with path.open("rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes  # type: ignore[union-attr]
    last = max(c.chunk_start_offset for c in chunks)
    cut.write_bytes(path.read_bytes()[: last + 20])
    result = runner.invoke(capture_main, ["info", str(cut)])
    assert result.exit_code == 1 and "recover" in result.output
    result = runner.invoke(capture_main, ["recover", str(cut), "-o", str(tmp_path / "fixed.mcap")])
    assert result.exit_code == 0 and "recovered" in result.output and "lost" in result.output
    assert runner.invoke(capture_main, ["info", str(tmp_path / "fixed.mcap")]).exit_code == 0


def test_cli_record_refuses_mixed_schemes(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    result = CliRunner().invoke(
        capture_main,
        ["record", "--listen", "tcp://127.0.0.1:0", "--upstream", "chudp://127.0.0.1:1", "-o", str(out)],
    )
    assert result.exit_code == 2 and "same link" in result.output
    assert not out.exists()  # refused before anything was written
