"""Recording the reference server: ``serve(..., wrap_link=)`` with a capture tap, and ``manip-server
--record FILE`` as a process stopped by SIGTERM, read back with :mod:`manip.captures`."""

from __future__ import annotations

import asyncio
import signal
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from manip.arm.transform import Transform
from manip.captures import CapturedPacket, Recorder, RecorderTap, Session, read_capture, read_session
from manip.codecs.messages import Reply, decode_server_packet
from manip.reference_client import ClientOptions, aconnect
from manip.reference_server import ServerConfig, serve
from manip.reference_server.cli import main
from manip.spec.constants import ChaosOp, RequestOp, ServerOp
from tests.support.servers import StartServer

TARGET = (20.0, -70.0, 100.0, 10.0, 30.0, -15.0)
PORT_LINE = "manip-server: listening on "


async def _client_session(url: str, options: ClientOptions | None = None) -> tuple[int, Transform]:
    """describe, here, power on and a joint move; returns the segment and the pose the client read."""
    async with aconnect(url, options) as arm:
        await arm.describe()
        pose = await arm.here()
        await arm.enable_power()
        segment = await arm.set_joint_angles(TARGET)
    return int(segment), pose


def _replies(session: Session, request_opcode: RequestOp) -> list[CapturedPacket]:
    """The replies paired with the session's one request of ``request_opcode``: RESPONSEs from the
    server that echo the request's packet number, the last one final."""
    (pair,) = [p for p in session.pairs.values() if p.request.opcode == request_opcode]
    assert pair.request.packet is not None and pair.complete
    for reply in pair.replies:
        assert reply.direction == "s2c" and reply.opcode == ServerOp.RESPONSE
        assert reply.request_number == pair.request.packet.packet_no
    assert pair.replies[-1].annotation.final
    return pair.replies


def _reply(session: Session, request_opcode: RequestOp) -> Reply:
    """The one reply to the session's one request of ``request_opcode``, decoded."""
    (reply,) = _replies(session, request_opcode)
    decoded = decode_server_packet(reply.opcode or 0, reply.data, request_opcode)
    assert isinstance(decoded, Reply)
    return decoded


def _check_session(session: Session, segment: int, pose: Transform) -> None:
    ops = [RequestOp.DESCRIBE_SELF, RequestOp.HERE, RequestOp.ENABLE_POWER, RequestOp.SET_JOINT_ANGLES]
    assert [p.opcode for p in session.requests] == ops
    assert all(p.direction == "c2s" for p in session.requests)
    # The RFC is paired with the initial RESPONSE, each request with its reply.
    assert len(session.pairs) == 1 + len(ops)
    here = _reply(session, RequestOp.HERE)
    recorded = Transform.from_floats(here.values["transform"])  # type: ignore[arg-type]
    assert np.allclose(recorded.matrix, pose.matrix, atol=1e-4)
    assert _reply(session, RequestOp.SET_JOINT_ANGLES).values["segment"] == segment
    # Describe-self: text packets, then an empty one ends the reply.
    *text, end = _replies(session, RequestOp.DESCRIBE_SELF)
    assert text and all(len(p.data) > 2 for p in text) and len(end.data) == 2


def test_serve_with_a_tap_records_every_connection_on_every_address(tmp_path: Path) -> None:
    # serve() itself, in the test's loop: its wrap_link= and extra_addresses= are what is tested.
    path = tmp_path / "server.mcap"

    async def run() -> list[tuple[int, Transform]]:
        with Recorder(path, how="server", seed=11, command_line=["test", "serve"]) as rec:
            async with serve(
                "tcp://127.0.0.1:0",
                ServerConfig(),
                time_scale=50.0,
                seed=11,
                extra_addresses=["chudp://127.0.0.1:0?addr=440"],
                wrap_link=RecorderTap(rec, "server").wrap,
            ) as server:
                tcp, chudp = server.addresses
                return [await _client_session(tcp), await _client_session(chudp)]

    results = asyncio.run(asyncio.wait_for(run(), 20.0))
    capture = read_capture(path)
    meta = capture.metadata["manip.capture"]
    assert (meta["seed"], meta["command_line"], meta["recorded_by"]) == ("11", "test serve", "server")
    assert sorted(link.framing for link in capture.links.values()) == ["chudp", "tcp"]
    assert len(capture.sessions) == 2
    for session, (segment, pose) in zip(capture.sessions, results, strict=True):
        _check_session(session, segment, pose)
    assert [capture.links[s.link].framing for s in capture.sessions] == ["tcp", "chudp"]


def test_server_and_client_taps_record_the_same_exchange(tmp_path: Path) -> None:
    """Both ends of one session, each recorded by its own node: the same manip packets both ways."""

    async def run() -> None:
        with (
            Recorder(tmp_path / "s.mcap", how="server") as srec,
            Recorder(tmp_path / "c.mcap", how="client") as crec,
        ):
            async with serve(
                "tcp://127.0.0.1:0", time_scale=50.0, wrap_link=RecorderTap(srec, "server").wrap
            ) as server:
                options = ClientOptions(wrap_link=RecorderTap(crec, "client").wrap)
                await _client_session(server.address, options)

    asyncio.run(asyncio.wait_for(run(), 20.0))
    server_side = read_session(tmp_path / "s.mcap")
    client_side = read_session(tmp_path / "c.mcap")
    assert len(server_side.requests) == 4
    assert server_side.exchange() == client_side.exchange()


def test_an_unwritable_record_file_exits_1_before_listening(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        main, ["--listen", "tcp://127.0.0.1:0", "--record", str(tmp_path / "no-such-dir" / "x.mcap")]
    )
    assert result.exit_code == 1, result.output
    assert "cannot write the capture" in result.output
    assert PORT_LINE not in result.output


@pytest.mark.timeout(40)
def test_manip_server_record_survives_sigterm_with_a_client_connected(
    tmp_path: Path, manip_server: StartServer
) -> None:
    # A process on purpose: the command's --record and its exit on SIGTERM are under test.
    path = tmp_path / "run.mcap"
    args = ["--record", str(path), "--seed", "5", "--time-scale", "50", "--log-level", "WARNING"]
    server = manip_server(*args)
    proc, url = server.proc, server.url

    async def run() -> tuple[int, Transform]:
        segment, pose = await _client_session(url)
        # A second client is still connected when the server is stopped: its CLS must be recorded.
        async with aconnect(url) as arm:
            await arm.here()
            proc.send_signal(signal.SIGTERM)
            assert await asyncio.to_thread(proc.wait, 10.0) == 0
        return segment, pose

    segment, pose = asyncio.run(asyncio.wait_for(run(), 30.0))
    _, err = proc.communicate(timeout=5.0)
    assert "Traceback" not in err

    capture = read_capture(path)  # a truncated file would raise CaptureTruncatedError
    meta = capture.metadata["manip.capture"]
    assert meta["seed"] == "5" and meta["recorded_by"] == "server"
    assert meta["command_line"] == f"manip-server --listen tcp://127.0.0.1:0 --record {path} " + " ".join(
        args[2:]
    )
    assert [e.event for e in capture.events][:1] == ["recording-started"]
    assert capture.events[-1].event == "recording-stopped"
    first, second = capture.sessions
    _check_session(first, segment, pose)
    assert [p.opcode for p in second.requests] == [RequestOp.HERE]
    last = second.server_packets[-1]
    assert last.opcode == ChaosOp.CLS and b"Server closing" in last.data
