"""A scripted Cougar for testing the Puma side on its own: it speaks Table 1 words, nothing more.

It is deliberately not a model of the wrist: forces come from a joint-space "wall" (joint ``wall_joint``
pressing past ``wall_at`` degrees makes a force along x proportional to the penetration), NTD pushes
back along that joint in proportion to the force (a crude compliance law), raw gauges are fixed offsets
plus a linear image of the gravity load of a point mass on the hand.  Every command received is logged.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from manip.arm.kinematics import PUMA600, forward
from manip.arm.trajectory import TICK
from manip.codecs.cougar import CougarMsg, WordStream, encode
from manip.codecs.messages import (
    AsyncResponse,
    ErrorReply,
    Reply,
    ServerMessage,
    decode_server_packet,
    encode_request,
)
from manip.reference_server import ServerConfig, ServerSession
from manip.reference_server.wrist import Wrist
from manip.spec import SPEC
from manip.spec.constants import CougarCommand, CougarResponse, ServerOp

#: Gauges per unit of wrench (an 8x6 matrix with the resolved-force pattern, scaled).
GAUGE_MATRIX = 4.0 * np.array(
    [
        [0, 1, 0, 0, 0, 1],
        [0, 0, 1, 0, 1, 0],
        [1, 0, 0, 0, 0, 1],
        [0, 0, 1, 1, 0, 0],
        [0, -1, 0, 0, 0, 1],
        [0, 0, 1, 0, -1, 0],
        [-1, 0, 0, 0, 0, 1],
        [0, 0, 1, -1, 0, 0],
    ],
    dtype=float,
)


@dataclass
class Guard:
    stop: bool
    dvec: tuple[float, ...]
    tol: float


@dataclass
class FakeCougar:
    offsets: tuple[int, ...] = (30, -12, 7, 0, -45, 100, 3, -8)
    weight: float = 40.0  # hand weight along -z world, for the gravity load on the gauges
    cg: tuple[float, float, float] = (0.0, 0.0, 2.0)
    wall_joint: int = 1  # 0-based
    wall_at: float | None = None
    stiffness: float = 5.0  # force per degree of penetration
    gain: float = 4.0  # NTD deg/s per unit force
    version: int = 0o105
    silent: set[int] = field(default_factory=set)  # command codes never answered
    memory: dict[int, int] = field(default_factory=dict)
    log: list[CougarMsg] = field(default_factory=list)
    out_of_sync_on: int | None = None  # answer this command code with OUT-OF-SYNC instead
    ticks: int = 0
    sensed: tuple[float, ...] = PUMA600.ready

    def __post_init__(self) -> None:
        self.stream = WordStream("command")
        self.guards: dict[int, Guard] = {}
        self.inbox: list[int] = []

    # contract of CougarSim
    def receive(self, words: Iterable[int]) -> None:
        self.inbox.extend(words)

    def tick(self, now: float) -> list[int]:
        self.ticks += 1
        out: list[int] = []
        force = self.force()
        for index, guard in sorted(self.guards.items()):
            if sum(f * d for f, d in zip(force, guard.dvec, strict=True)) > guard.tol:
                del self.guards[index]
                code = CougarResponse.GUARD_STOP if guard.stop else CougarResponse.GUARD_CONTINUE
                out += encode("response", code, index=index)
        words, self.inbox = self.inbox, []
        for item in self.stream.feed(words):
            assert isinstance(item, CougarMsg), item
            self.log.append(item)
            out += self.execute(item)
        return out

    # physics (of a sort)
    def penetration(self) -> float:
        if self.wall_at is None:
            return 0.0
        return max(0.0, self.sensed[self.wall_joint] - self.wall_at)

    def force(self) -> tuple[float, ...]:
        return (self.stiffness * self.penetration(), 0.0, 0.0, 0.0, 0.0, 0.0)

    def gauges(self) -> tuple[int, ...]:
        rot = forward(self.sensed, PUMA600.geometry).matrix[:3, :3]
        f = rot.T @ np.array([0.0, 0.0, -self.weight])
        tau = np.cross(np.array(self.cg), f)
        load = GAUGE_MATRIX @ np.concatenate([f, tau])
        return tuple(int(o + round(v)) for o, v in zip(self.offsets, load, strict=True))

    def execute(self, msg: CougarMsg) -> list[int]:
        code, v = msg.code, msg.values
        if code == self.out_of_sync_on:
            return encode("response", CougarResponse.OUT_OF_SYNC, code=code)
        if code in self.silent:
            return []
        match code:
            case CougarCommand.SEN:
                self.sensed = tuple(v["theta_sensed"])  # type: ignore[arg-type]
            case CougarCommand.NPR:
                self.sensed = tuple(v["theta_sensed"])  # type: ignore[arg-type]
                ntd = [0.0] * 6
                ntd[self.wall_joint] = -self.gain * self.force()[0]
                return encode("response", CougarResponse.NTD, delta_theta=tuple(ntd))
            case CougarCommand.RFRC:
                return encode("response", CougarResponse.FORCES, forces=self.force())
            case CougarCommand.RRAW:
                return encode("response", CougarResponse.RAW, gauges=self.gauges())
            case CougarCommand.EXMN:
                a, n = v["address"], v["count"]
                assert isinstance(a, int) and isinstance(n, int)
                data = tuple(self.memory.get((a + i) & 0xFFFF, 0) for i in range(n))
                return encode("response", CougarResponse.EXMN_DATA, words=data)
            case CougarCommand.DPST:
                a, value = v["address"], v["value"]
                assert isinstance(a, int) and isinstance(value, int)
                self.memory[a] = value
            case CougarCommand.VERS:
                return encode("response", CougarResponse.VERSION, version=self.version)
            case CougarCommand.GUARDS:
                ti = v["type_index"]
                assert isinstance(ti, int)
                self.guards[ti & 0xF] = Guard(bool(ti & 0x8000), tuple(v["dvec"]), float(v["tol"]))  # type: ignore[arg-type]
            case CougarCommand.GUARDC:
                index = v["index"]
                assert isinstance(index, int)
                self.guards.pop(index & 0xF, None)
        return []

    def commands(self, code: int) -> list[CougarMsg]:
        return [m for m in self.log if m.code == code]


# ------------------------------------------------------------------------------- a session client
class WristClient:
    """Drives a ServerSession with a wrist on a fake 16 ms clock; decodes every packet, deferred
    replies included (it remembers which opcode each packet number carried)."""

    def __init__(
        self, wrist: Wrist, *, powered: bool = True, now: float = 10.0, config: ServerConfig | None = None
    ) -> None:
        config = replace(config or ServerConfig(), powered_at_open=powered)
        self.session = ServerSession(config, wrist=wrist)
        self.now = now
        self.packet_no = 0o100
        self.ops: dict[int, int] = {}
        self.session.on_open(now, self.packet_no)
        self.log: list[ServerMessage] = []

    def _decode(self, packets: Any) -> list[ServerMessage]:
        out = []
        for p in packets:
            op = None
            if p.opcode == ServerOp.RESPONSE and len(p.data) >= 2:
                op = self.ops.get(int.from_bytes(p.data[:2], "little"))
            out.append(decode_server_packet(p.opcode, p.data, op))
        self.log += out
        return out

    def send(self, op: str, **values: Any) -> list[ServerMessage]:
        spec_op = SPEC.request(op)
        self.packet_no += 1
        self.ops[self.packet_no] = spec_op.opcode
        out = self.session.on_request(self.now, spec_op.opcode, self.packet_no, encode_request(op, **values))
        return self._decode(out.packets)

    def tick(self) -> list[ServerMessage]:
        self.now += TICK
        return self._decode(self.session.tick(self.now).packets)

    def run(self, seconds: float) -> list[ServerMessage]:
        out: list[ServerMessage] = []
        for _ in range(round(seconds / TICK)):
            out += self.tick()
        return out

    def call(self, op: str, limit: float = 30.0, **values: Any) -> ServerMessage:
        """Send a request and tick until its answer (reply or error) arrives; returns it."""
        number = self.packet_no + 1
        got = self.send(op, **values)
        start = self.now
        while True:
            for msg in got:
                final = (ServerOp.NON_FATAL_ERROR, ServerOp.FATAL_ERROR)
                if isinstance(msg, Reply) or (isinstance(msg, ErrorReply) and msg.opcode in final):
                    assert isinstance(msg, Reply | ErrorReply)
                    if msg.request_number == number:
                        return msg
            assert self.now - start < limit, f"{op}: no answer in {limit} s"
            got = self.tick()

    def asyncs(self) -> list[AsyncResponse]:
        return [m for m in self.log if isinstance(m, AsyncResponse)]

    def errors(self, opcode: int) -> list[ErrorReply]:
        return [m for m in self.log if isinstance(m, ErrorReply) and m.opcode == opcode]
