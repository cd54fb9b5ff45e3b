"""A fake client of the reference server's sans-I/O session (:class:`Client`): numbers its packets,
keeps the clock and decodes what the session sends; shared by the session and fault-switch tests."""

from __future__ import annotations

from typing import Any

from manip.arm.trajectory import TICK
from manip.codecs.messages import Reply, ServerMessage, decode_server_packet, encode_request
from manip.reference_server import Output, ServerConfig, ServerSession
from manip.spec import SPEC
from manip.spec.constants import ServerOp

GOAL = (10.0, -80.0, 100.0, 20.0, 30.0, 40.0)
OTHER = (-20.0, -100.0, 80.0, -10.0, 20.0, -30.0)


class Client:
    """A fake client: numbers its packets, keeps the clock, decodes what the session sends."""

    def __init__(self, config: ServerConfig | None = None, *, rfc: int = 0o1000, now: float = 100.0) -> None:
        self.session = ServerSession(config)
        self.now = now
        self.packet_no = rfc
        self.initial = self.session.on_open(now, rfc)
        self.closed = False

    def _decode(self, out: Output, op: int | None) -> list[ServerMessage]:
        self.closed = self.closed or out.close
        return [
            decode_server_packet(p.opcode, p.data, op if p.opcode == ServerOp.RESPONSE else None)
            for p in out.packets
        ]

    def raw(self, opcode: int, data: bytes, *, ack_no: int | None = None) -> Output:
        self.packet_no = (self.packet_no + 1) & 0xFFFF
        return self.session.on_request(self.now, opcode, self.packet_no, data, ack_no)

    def send(self, op: str, data: bytes | None = None, **values: Any) -> list[ServerMessage]:
        """Send a request by spec name; returns every packet the session answered with, decoded."""
        spec_op = SPEC.request(op)
        out = self.raw(spec_op.opcode, encode_request(op, **values) if data is None else data)
        return self._decode(out, spec_op.opcode)

    def one(self, op: str, data: bytes | None = None, **values: Any) -> ServerMessage:
        (msg,) = self.send(op, data, **values)
        return msg

    def run(self, seconds: float) -> list[ServerMessage]:
        """Tick every 16 ms for ``seconds``; the asynchronous packets sent meanwhile."""
        out: list[ServerMessage] = []
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.now = min(end, self.now + TICK)
            out += self._decode(self.session.tick(self.now), None)
        return out

    def settle(self, limit: float = 30.0) -> list[ServerMessage]:
        """Tick until the arm is at rest."""
        out: list[ServerMessage] = []
        start = self.now
        while self.session.arm.moving:
            assert self.now - start < limit, "the arm never came to rest"
            out += self.run(TICK)
        return out


def reply(msg: ServerMessage) -> Reply:
    assert isinstance(msg, Reply), msg
    return msg
