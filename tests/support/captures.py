"""A recorded session for the capture tests: the packets of one connection both ways (RFC to CLS, with a
multi-packet reply, an error, an asynchronous packet and a retransmission) and a recorder of them."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

from manip.captures import Recorder
from manip.codecs.error_string import ErrorMessage
from manip.codecs.messages import encode_async, encode_error, encode_reply, encode_request
from manip.codecs.packet import Packet
from manip.spec.constants import ChaosOp, RequestOp, ServerOp

CLIENT = (0o401, 0x1234)
SERVER = (0o440, 0x5678)


def c2s(opcode: int, number: int, data: bytes = b"") -> Packet:
    return Packet(opcode, SERVER[0], SERVER[1], CLIENT[0], CLIENT[1], number, 0, data)


def s2c(opcode: int, number: int, data: bytes = b"") -> Packet:
    return Packet(opcode, CLIENT[0], CLIENT[1], SERVER[0], SERVER[1], number, 0, data)


def word(n: int) -> bytes:
    return struct.pack("<H", n)


JOINTS = (1.5, -90.0, 90.0, 0.25, 10.0, -3.0)


def session_packets() -> list[tuple[str, Packet]]:
    """A session: RFC, OPN, initial RESPONSE, a here, a multi reply, an error, an async, a retransmission."""
    rfc = Packet(ChaosOp.RFC, SERVER[0], 0, CLIENT[0], CLIENT[1], 1, 0, b"PUMA")
    err = ErrorMessage("move", "E", "NAP", "No arm power")
    return [
        ("c2s", rfc),
        ("s2c", s2c(ChaosOp.OPN, 1, struct.pack("<HH", 1, 15))),
        ("s2c", s2c(ServerOp.RESPONSE, 2, word(1))),
        ("c2s", c2s(RequestOp.JOINT_ANGLES, 2)),
        ("s2c", s2c(ServerOp.RESPONSE, 3, encode_reply("joint-angles", 2, joints=JOINTS))),
        ("c2s", c2s(RequestOp.DESCRIBE_SELF, 3)),
        ("s2c", s2c(ServerOp.RESPONSE, 4, word(3) + b"((:A . 1))")),
        ("s2c", s2c(ServerOp.RESPONSE, 5, word(3))),
        ("c2s", c2s(RequestOp.MOVE, 4, encode_request("move", transform=tuple(float(i) for i in range(12))))),
        ("c2s", c2s(RequestOp.MOVE, 4, encode_request("move", transform=tuple(float(i) for i in range(12))))),
        ("s2c", s2c(ServerOp.NON_FATAL_ERROR, 6, encode_error(ServerOp.NON_FATAL_ERROR, 4, err))),
        ("s2c", s2c(ServerOp.ASYNCHRONOUS_RESPONSE, 7, encode_async(4, 2, 0, 7))),
        ("c2s", Packet(ChaosOp.EOF, SERVER[0], SERVER[1], CLIENT[0], CLIENT[1], 5, 0)),
        ("s2c", s2c(ChaosOp.CLS, 0, b"Bye")),
    ]


def record(path: Path, packets: list[tuple[str, Packet]], **kw: Any) -> None:
    with Recorder(path, how="test", seed=7, command_line=["test", "x"], **kw) as rec:
        link = rec.open_link("tcp", name="test link")
        for i, (direction, packet) in enumerate(packets):
            rec.packet(link, direction, packet, t_ns=1_000_000_000 + i * 1000)  # type: ignore[arg-type]
