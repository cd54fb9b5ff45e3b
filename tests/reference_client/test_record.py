"""``manip-client --record FILE``: the session's packets in an MCAP capture, read back with
:mod:`manip.captures`, whatever way the command ends (success, a server error, no connection, Ctrl-C)."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import numpy as np
import pytest

from manip.arm.transform import Transform
from manip.captures import Session, read_capture, read_session
from manip.codecs.messages import Reply, decode_server_packet
from manip.reference_client import ClientOptions, aconnect
from manip.reference_client.cli import EXIT_CONNECTION, EXIT_SERVER_ERROR, EXIT_USAGE
from manip.reference_client.ncp_transport import NcpTransport
from manip.spec.constants import RequestOp, ServerOp
from tests.support.client_cli import invoke, watch_until_ctrl_c
from tests.support.scripted import TARGET
from tests.support.servers import free_port


def _opcodes(session: Session) -> list[int | None]:
    return [p.opcode for p in session.requests]


def _only_reply(session: Session, opcode: RequestOp) -> Reply:
    (pair,) = [p for p in session.pairs.values() if p.request.opcode == opcode]
    assert pair.request.packet is not None and pair.complete
    (reply,) = pair.replies
    assert reply.opcode == ServerOp.RESPONSE and reply.request_number == pair.request.packet.packet_no
    decoded = decode_server_packet(ServerOp.RESPONSE, reply.data, opcode)
    assert isinstance(decoded, Reply)
    return decoded


@pytest.mark.parametrize("where", ["before-url", "after-url", "after-command"])
def test_here_is_recorded_with_its_reply_and_command_line(url: str, tmp_path: Path, where: str) -> None:
    path = str(tmp_path / "here.mcap")
    args = {
        "before-url": ["--record", path, url, "here", "--json"],
        "after-url": [url, "--record", path, "here", "--json"],
        "after-command": [url, "here", "--json", f"--record={path}"],
    }[where]
    result = invoke(*args)
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout)

    capture = read_capture(path)
    meta = capture.metadata["manip.capture"]
    assert meta["recorded_by"] == "client" and meta["seed"] == ""
    assert meta["command_line"] == " ".join(["manip-client", *args])
    (session,) = capture.sessions
    assert _opcodes(session) == [RequestOp.HERE]
    assert [p.direction for p in session.requests] == ["c2s"]
    here = _only_reply(session, RequestOp.HERE)
    recorded = Transform.from_floats(here.values["transform"])  # type: ignore[arg-type]
    assert np.allclose(recorded.to_floats(), printed["transform"], atol=1e-4)
    assert capture.events[0].event == "recording-started" and capture.events[-1].event == "recording-stopped"


def test_a_motion_with_power_and_wait(url: str, tmp_path: Path) -> None:
    path = tmp_path / "move.mcap"
    result = invoke(url, "--record", str(path), "move-joints", *map(str, TARGET), "--power", "--wait")
    assert result.exit_code == 0, result.output
    session = read_session(path)
    assert _opcodes(session) == [
        RequestOp.ENABLE_POWER,
        RequestOp.REQUEST_NOTIFICATIONS,
        RequestOp.SET_JOINT_ANGLES,
    ]
    segment = _only_reply(session, RequestOp.SET_JOINT_ANGLES).values["segment"]
    assert f"segment {segment} completed" in result.stdout
    # The completion the client waited for came as an asynchronous response, recorded too.
    assert [p.kind for p in session.server_packets if p.opcode == ServerOp.ASYNCHRONOUS_RESPONSE]


def test_a_server_error_is_recorded_and_the_file_closed(url: str, tmp_path: Path) -> None:
    path = tmp_path / "error.mcap"
    result = invoke(url, "--record", str(path), "move-joints", *map(str, TARGET))  # power is off
    assert result.exit_code == EXIT_SERVER_ERROR
    session = read_session(path)
    assert _opcodes(session) == [RequestOp.SET_JOINT_ANGLES]
    (pair,) = [p for p in session.pairs.values() if p.request.opcode == RequestOp.SET_JOINT_ANGLES]
    (reply,) = pair.replies
    assert reply.kind == "error" and reply.opcode == ServerOp.NON_FATAL_ERROR


def test_no_connection_still_leaves_a_valid_file(tmp_path: Path) -> None:
    path = tmp_path / "nothing.mcap"
    address = f"tcp://127.0.0.1:{free_port()}"
    result = invoke(address, "--record", str(path), "--timeout", "2", "here")
    assert result.exit_code == EXIT_CONNECTION
    capture = read_capture(path)
    assert capture.sessions == []
    assert [e.event for e in capture.events] == ["recording-started", "recording-stopped"]


def test_a_record_file_that_cannot_be_created_is_a_usage_error(url: str, tmp_path: Path) -> None:
    result = invoke(url, "--record", str(tmp_path / "missing" / "x.mcap"), "here")
    assert result.exit_code == EXIT_USAGE
    assert "cannot write the capture" in result.stderr


def test_watch_stopped_by_ctrl_c_leaves_a_complete_capture(tmp_path: Path) -> None:
    path = tmp_path / "watch.mcap"
    watch_until_ctrl_c("--record", str(path))
    session = read_session(path)
    assert _opcodes(session) == [RequestOp.REQUEST_NOTIFICATIONS]
    asyncs = [p for p in session.server_packets if p.kind == "async"]
    assert len(asyncs) == 2
    assert all(p.pair is None for p in asyncs)  # asynchronous packets answer no request


def test_library_wrap_link_is_for_url_sources_only() -> None:
    options = ClientOptions(wrap_link=lambda link: link)

    async def run() -> None:
        await aconnect(lambda: NcpTransport("tcp://127.0.0.1:1"), options)

    with pytest.raises(ValueError, match="wrap_link applies when connecting by URL"):
        asyncio.run(run())
