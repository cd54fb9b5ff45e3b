"""The input classes of a fuzz campaign, generated from the spec's tables.

Every class says what it sends, what the spec says the answer must be, and the clauses that say so
(:data:`INPUT_CLASSES`; ``manip-conform fuzz --list-classes`` prints them).  The manip classes take the
opcodes, their data layouts and field types from :data:`manip.spec.SPEC`; the Chaos classes its
opcode table; the link classes the framings of :mod:`manip.codecs.framing`.

:func:`generate` makes input ``number`` of the campaign with seed ``seed`` from those two numbers
alone (and the :class:`GenOptions`: which link, which hazards, which classes), so a campaign can be
rerun exactly and any input sent again on its own.  Inputs never depend on what the target answered.
"""

from __future__ import annotations

import functools
import random
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final, Literal

from manip.codecs.messages import request_op
from manip.codecs.packet import MAX_DATA, Packet
from manip.codecs.pdp11float import F_MAX, F_MIN_NORMAL, pack_f
from manip.conformance.fuzz.steps import ConnPacket, FuzzInput, Pause, Raw, RequestStep, Step, Stray
from manip.conformance.suite.selection import match_id
from manip.spec import SPEC, RequestOpcode
from manip.spec.constants import ChaosOp, RequestOp
from manip.spec.model import HAZARDS, Field, Hazard
from manip.spec.notation import octal

__all__ = [
    "INPUT_CLASSES",
    "GenOptions",
    "InputClass",
    "LinkKind",
    "generate",
    "stray_index",
]

LinkKind = Literal["stream", "datagram"]
Layer = Literal["link", "chaos", "manip"]

STEPS_PER_INPUT: Final = 32
"""Most stray packets one input sends: their source indices are unique within 2,000 inputs."""
MAX_PIPELINE: Final = 500
UNKNOWN_OPCODES: Final = tuple(op for op in range(0o200, 0o400) if op not in SPEC.requests)
"""Data opcodes no request of the spec uses (0300-0377 are 16-bit data, never a request)."""
HERE: Final = int(RequestOp.HERE)
PAUSE: Final = 0.05
"""Seconds a sequence waits for its motion to end (less when the target reports something first)."""


@dataclass(frozen=True)
class GenOptions:
    """What shapes the inputs besides the seed: the target's link, the hazards that may be sent, the
    classes chosen, the contact name."""

    link: LinkKind = "stream"
    hazards: frozenset[Hazard] = frozenset(HAZARDS)
    select: tuple[str, ...] = ()
    """Glob patterns of class ids (``manip.*``); none: every class."""
    contact: str = "PUMA"

    def classes(self) -> list[InputClass]:
        """The classes this campaign draws from: for its link, sendable with its hazards, selected."""
        return [
            c
            for c in INPUT_CLASSES.values()
            if self.link in c.links
            and (c.hazard in self.hazards or c.adapts)
            and (not self.select or any(match_id(p, c.id) for p in self.select))
        ]

    def ops(self, *, fixed: bool = False, floats: bool = False) -> tuple[RequestOpcode, ...]:
        """The spec's request opcodes that may be sent (with a fixed layout, with float fields)."""
        return _ops(self.hazards, fixed, floats)


@functools.cache
def _ops(hazards: frozenset[Hazard], fixed: bool, floats: bool) -> tuple[RequestOpcode, ...]:
    return tuple(
        op
        for op in SPEC.requests.values()
        if op.hazard in hazards
        and (not fixed or op.request.fixed_size is not None)
        and (not floats or _float_offsets(op))
    )


Maker = Callable[[random.Random, GenOptions, int], tuple[tuple[Step, ...], str]]


@dataclass(frozen=True)
class InputClass:
    """One kind of input: what it sends, the answer the spec demands, the clauses saying so."""

    id: str
    layer: Layer
    sends: str
    expected: str
    clauses: tuple[str, ...]
    make: Maker
    weight: int
    hazard: Hazard = "read-only"
    """The worst hazard class of what it sends (motion, power: only on a simulator or --allow-motion)."""
    links: frozenset[LinkKind] = frozenset({"stream", "datagram"})
    adapts: bool = False
    """It draws its opcodes from those the campaign may send, so it runs whatever the hazards allowed
    (on hardware without --allow-motion: the read-only and config opcodes only)."""

    @property
    def level(self) -> str:
        levels = {SPEC.clauses[c].level for c in self.clauses}
        return next(level for level in ("MUST", "SHOULD", "MAY", "INFO") if level in levels)


def stray_index(number: int, step: int) -> int:
    """The source index of stray packet ``step`` of input ``number``: the answer's destination, so
    unique within a batch (0x0100-0xfeff; the batch connection's own index is 0xffNN)."""
    return 0x0100 + (number % 2000 * STEPS_PER_INPUT + step) % 0xFE00


# --------------------------------------------------------------------------------------- field values


@functools.cache
def _float_offsets(op: RequestOpcode) -> tuple[int, ...]:
    offsets: list[int] = []
    pos = 0
    for f in op.request.fields:
        if f.type.element == "float" and f.type.count:
            offsets += [pos + 4 * i for i in range(f.type.count)]
        pos += f.type.fixed_size or 0
    return tuple(offsets)


def _float_value(rng: random.Random, op: RequestOpcode, f: Field) -> float:
    """A float a request of ``op`` may well carry: small moves, speeds the arm can keep up with,
    angles and lengths of the arm's size, now and then 0, 1 or -1."""
    if op.name == "set-speed":
        return rng.uniform(0.1, 1.0)  # slower factors are valid but leave the arm crawling for minutes
    if f.type.name == "pose-delta":
        return rng.uniform(-3.0, 3.0)
    pick = rng.random()
    if pick < 0.15:
        return rng.choice((0.0, 1.0, -1.0))
    if pick < 0.6:
        return rng.uniform(-180.0, 180.0)
    return rng.uniform(-1000.0, 1000.0)


def _word_value(rng: random.Random) -> int:
    return rng.choice((0, 1, 2, 3, 7, 0o17, 0o377, 0xFFFF)) if rng.random() < 0.5 else rng.randrange(0x10000)


def valid_data(rng: random.Random, op: RequestOpcode) -> bytes:
    """Data laid out as ``op``'s request layout says, field by field, with plausible values."""
    out = bytearray()
    for f in op.request.fields:
        element, count = f.type.element, f.type.count or 0
        for _ in range(count):
            if element == "float":
                out += pack_f(_float_value(rng, op, f))
            elif element == "word":
                out += struct.pack("<H", _word_value(rng))
            elif element == "int16":
                out += struct.pack("<h", rng.randrange(-32768, 32768))
            elif element == "small":  # one byte, or one word whose low byte counts
                value = rng.randrange(0, 8)
                out += bytes([value]) if rng.random() < 0.3 else struct.pack("<H", value)
    return bytes(out)


def _reserved_operand(rng: random.Random) -> bytes:
    """Sign 1, exponent 0, any fraction: the PDP-11 reserved operand, sign/exponent word first."""
    return struct.pack("<HH", 0x8000 | rng.randrange(0x80), rng.randrange(0x10000))


def _extreme_float(rng: random.Random, op: RequestOpcode) -> bytes:
    """A valid but extreme F float: the largest and smallest magnitudes, a dirty zero, the top and
    bottom exponents with any fraction.  Set speed gets only factors outside 0 < n <= 1."""
    sign = 0x8000 if rng.random() < 0.5 else 0
    if op.name == "set-speed":
        return rng.choice(
            (
                pack_f(-F_MAX),
                pack_f(F_MAX),
                pack_f(-F_MIN_NORMAL),
                struct.pack("<HH", 0, 0),
                pack_f(rng.uniform(1.0001, 1e6)),
                pack_f(-rng.uniform(0.0, 1e6)),
                struct.pack("<HH", 0x7F80 | rng.randrange(0x80), rng.randrange(0x10000)),
            )
        )
    choice = rng.randrange(7)
    if choice == 0:
        return pack_f(F_MAX if not sign else -F_MAX)
    if choice == 1:
        return pack_f(F_MIN_NORMAL if not sign else -F_MIN_NORMAL)
    if choice == 2:  # dirty zero: exponent 0, sign 0, fraction non-zero (reads as 0.0)
        return struct.pack("<HH", rng.randrange(0x80), rng.randrange(1, 0x10000))
    if choice == 3:  # the top exponent
        return struct.pack("<HH", sign | 0x7F80 | rng.randrange(0x80), rng.randrange(0x10000))
    if choice == 4:  # the bottom exponent
        return struct.pack("<HH", sign | 0x0080 | rng.randrange(0x80), rng.randrange(0x10000))
    if choice == 5:
        return pack_f(rng.choice((1e30, -1e30, 1e-30, -1e-30, 1e10, -1e10)))
    return struct.pack("<HH", rng.randrange(0x10000), rng.randrange(0x10000)) if not sign else b"\0\0\0\0"


# --------------------------------------------------------------------------------------- manip classes


def _pick_op(rng: random.Random, ops: Sequence[RequestOpcode]) -> RequestOpcode:
    return ops[rng.randrange(len(ops))]


def _valid(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    op = _pick_op(rng, g.ops())
    data = valid_data(rng, op)
    note = f"{op.name} with {len(data)} data bytes laid out as its layout says"
    if op.name == "enable-power":  # power off again: the rest of the batch is not to drive the arm about
        return (RequestStep(op.opcode, data), RequestStep(_op("kill-power"), b"")), f"{note}, then kill power"
    return (RequestStep(op.opcode, data),), note


def _unknown(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    opcode = UNKNOWN_OPCODES[rng.randrange(len(UNKNOWN_OPCODES))]
    size = rng.choice((0, 0, 1, 2, 4, rng.randrange(64), rng.randrange(MAX_DATA + 1)))
    data = rng.randbytes(size)
    return (RequestStep(opcode, data),), f"unknown opcode 0{opcode:o} with {size} data bytes"


def _wrong_sizes(op: RequestOpcode) -> tuple[int, set[int]]:
    size = op.request.fixed_size
    assert size is not None
    small = any(f.type.element == "small" for f in op.request.fields)
    return size, {size} | ({size - 1} if small else set())


def _wrong_length(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    op = _pick_op(rng, g.ops(fixed=True))
    size, accepted = _wrong_sizes(op)
    while True:
        wanted = rng.choice(
            (
                size + 1,
                size + 2,
                size - 1,
                size - 2,
                size + 4,
                size - 4,
                0,
                2 * size + 1,
                MAX_DATA,
                rng.randrange(MAX_DATA + 1),
            )
        )
        if 0 <= wanted <= MAX_DATA and wanted not in accepted:
            break
    # Valid values cut or padded with zero bytes (clean zeros): executed anyway, they would be served.
    data = valid_data(rng, op)[:wanted].ljust(wanted, b"\0")
    return (RequestStep(op.opcode, data),), f"{op.name} with {wanted} data bytes (its layout: {size})"


def _reserved_float(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    op = _pick_op(rng, g.ops(floats=True))
    data = bytearray(valid_data(rng, op))
    offsets = _float_offsets(op)
    hits = rng.sample(offsets, rng.randint(1, min(3, len(offsets))))
    for at in hits:
        data[at : at + 4] = _reserved_operand(rng)
    where = ", ".join(str(at) for at in sorted(hits))
    return (RequestStep(op.opcode, bytes(data)),), f"{op.name} with a reserved-operand float at byte {where}"


def _extreme(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    op = _pick_op(rng, g.ops(floats=True))
    data = bytearray(valid_data(rng, op))
    offsets = _float_offsets(op)
    hits = rng.sample(offsets, rng.randint(1, len(offsets)))
    for at in hits:
        data[at : at + 4] = _extreme_float(rng, op)
    return (RequestStep(op.opcode, bytes(data)),), f"{op.name} with {len(hits)} extreme float(s)"


def _any_request(rng: random.Random, g: GenOptions, n: int) -> RequestStep:
    """A request of a random manip class (no pipelines, no sequences)."""
    maker = rng.choice((_valid, _valid, _valid, _unknown, _wrong_length, _reserved_float, _extreme))
    steps, _ = maker(rng, g, n)
    first = steps[0]
    assert isinstance(first, RequestStep)
    return first


def _pipeline(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    count = MAX_PIPELINE if rng.random() < 0.05 else rng.randint(2, 60)
    safe = GenOptions(g.link, frozenset({"read-only"}), g.select, g.contact)
    steps: list[Step] = []
    for _ in range(count):
        request = _any_request(rng, safe, n)
        steps.append(RequestStep(request.opcode, request.data, lazy=True))
    return tuple(steps), f"{count} read-only requests sent without reading a reply"


def _op(name: str) -> int:
    return request_op(name).opcode


def _small_move(rng: random.Random) -> RequestStep:
    op = SPEC.request(rng.choice(("incremental-move", "incremental-straight-move")))
    deltas = [rng.uniform(-2.0, 2.0) for _ in range(3)] + [0.0, 0.0, 0.0]
    return RequestStep(op.opcode, b"".join(pack_f(d) for d in deltas))


def _sequence(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    """Short scripts the spec says how to answer step by step."""
    script = rng.randrange(6)
    if script == 0:  # a motion request without power: NAP (motion.no-power)
        steps: list[Step] = [RequestStep(_op("kill-power"), b""), _small_move(rng)]
        return tuple(steps), "kill power, then a small incremental move"
    if script == 1:  # segments (ready is always reachable): their numbers, their completion responses
        mask = rng.choice((2, 3, 1, 0))
        notify = RequestStep(_op("request-notifications"), struct.pack("<H", mask))
        steps = [
            RequestStep(_op("enable-power"), b""),
            notify,
            RequestStep(_op("ready"), b""),
            RequestStep(_op("ready"), b""),
        ]
        steps += [Pause(PAUSE), RequestStep(HERE, b"")]
        note = f"enable power, notifications mask {mask}, ready twice, a pause, here (power left on)"
        return tuple(steps), note
    if script == 2:  # free joint: the next packet is discarded with done (free-joint.replies)
        joint = rng.randint(1, 6)
        steps = [
            RequestStep(_op("enable-power"), b""),
            RequestStep(_op("free-joint"), struct.pack("<H", joint)),
        ]
        steps += [_any_request(rng, g, n), RequestStep(HERE, b""), RequestStep(_op("kill-power"), b"")]
        return tuple(steps), f"enable power, free joint {joint}, a request (discarded), here, kill power"
    if script == 3:  # a speed, then a move at it
        factor = rng.uniform(0.2, 1.0)
        steps = [
            RequestStep(_op("enable-power"), b""),
            RequestStep(_op("set-speed"), pack_f(factor)),
            _small_move(rng),
        ]
        steps.append(RequestStep(_op("kill-power"), b""))
        return tuple(steps), f"enable power, speed {factor:.2f}, a small move, kill power"
    if script == 4:  # what describe self says of the operations and the joint vectors, then a request
        steps = [
            RequestStep(_op("describe-self"), b""),
            _any_request(rng, g, n),
            RequestStep(_op("joint-angles"), b""),
        ]
        return tuple(steps), "describe self, a request, joint angles"
    # One joint anywhere within +-200 degrees, the others near 0: beyond a stated limit it must be
    # refused (describe.joint-limits), so an arm that states narrower limits than it has shows.
    steps = [RequestStep(_op("describe-self"), b""), RequestStep(_op("enable-power"), b"")]
    for _ in range(4):
        angles = [rng.uniform(-20.0, 20.0) for _ in range(6)]
        angles[rng.randrange(6)] = rng.uniform(-200.0, 200.0)
        steps.append(RequestStep(_op("set-joint-angles"), b"".join(pack_f(a) for a in angles)))
    steps.append(RequestStep(_op("kill-power"), b""))
    return tuple(
        steps
    ), "describe self, enable power, set joint angles four times (one joint far out), kill power"


def _fragmented(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    chunk = rng.choice((1, 1, 2, 3, 5, 7))
    request = _any_request(rng, GenOptions(g.link, frozenset({"read-only"}), g.select, g.contact), n)
    name = SPEC.requests[request.opcode].name if request.opcode in SPEC.requests else f"0{request.opcode:o}"
    return (
        RequestStep(request.opcode, request.data, chunk=chunk),
    ), f"{name} written {chunk} byte(s) at a time"


# --------------------------------------------------------------------------------------- Chaos classes


def _stray(
    n: int,
    step: int,
    opcode: int,
    *,
    data: bytes = b"",
    dest_index: int = 0,
    packet_no: int = 0,
    ack_no: int = 0,
    dest_host: int = 0,
) -> Packet:
    return Packet(opcode, dest_host, dest_index, 0, stray_index(n, step), packet_no, ack_no, data)


def _nowhere(rng: random.Random) -> int:
    """An index no connection is likely to have (the target's own are random too: one in 65,535)."""
    return rng.randrange(1, 0x10000)


_NO_CONNECTION_OPS: Final = (ChaosOp.DAT, ChaosOp.DAT, ChaosOp.DWD, ChaosOp.SNS, ChaosOp.STS, ChaosOp.EOF)


def _no_connection(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    opcode = int(rng.choice(_NO_CONNECTION_OPS))
    if opcode in (ChaosOp.DAT, ChaosOp.DWD):
        opcode += rng.randrange(0o100)
    p = _stray(n, 0, opcode, data=rng.randbytes(rng.randrange(64)), dest_index=_nowhere(rng))
    p = p.with_(packet_no=rng.randrange(0x10000), ack_no=rng.randrange(0x10000))
    return (Stray(p, "los", "ncp.los"),), f"opcode 0{opcode:o} to index {octal(p.dest_index)}, no connection"


def _illegal_opcode(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    opcode = rng.choice((0, rng.randrange(0o17, 0o200)))
    p = _stray(n, 0, opcode, data=rng.randbytes(rng.randrange(32)), dest_index=_nowhere(rng))
    return (Stray(p, "los", "chaos.opcode.legal"),), f"illegal opcode 0{opcode:o}"


def _no_los_for_los(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    opcode = int(rng.choice((ChaosOp.LOS, ChaosOp.CLS, ChaosOp.ANS, ChaosOp.FWD)))
    p = _stray(n, 0, opcode, data=b"fuzz", dest_index=_nowhere(rng))
    return (
        Stray(p, "silence", "ncp.los"),
    ), f"{ChaosOp(opcode).name} to index {octal(p.dest_index)}, no connection"


def _ignored(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    """Packets a host drops without a word: for another host, MNT, RUT."""
    if rng.random() < 0.5:
        other = rng.randrange(1, 0x10000)
        p = _stray(n, 0, ChaosOp.DAT, data=b"\0\0", dest_index=_nowhere(rng), dest_host=other)
        return (Stray(p, "silence", "ncp.los"),), f"a data packet for host {octal(other)}, not the target"
    opcode = int(rng.choice((ChaosOp.MNT, ChaosOp.RUT)))
    p = _stray(n, 0, opcode, data=rng.randbytes(rng.randrange(16)), dest_index=_nowhere(rng))
    return (Stray(p, "silence", "ncp.los"),), f"{ChaosOp(opcode).name}, which a host drops"


def _oversize(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    size = rng.randint(MAX_DATA + 1, MAX_DATA + 64)
    p = _stray(n, 0, ChaosOp.DAT, data=rng.randbytes(size), dest_index=_nowhere(rng))
    return (Stray(p, "los", "chaos.data.max-488"),), f"a data packet with {size} data bytes"


def _rfc_flood(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    count = rng.randint(1, 20)
    contact = g.contact.encode("ascii")
    steps: list[Step] = []
    for i in range(count):
        p = _stray(n, i, ChaosOp.RFC, data=contact, packet_no=rng.randrange(0x10000))
        steps.append(Stray(p, "answer", "connect.one-server-per-robot"))
    return tuple(steps), f"{count} RFC(s) for {g.contact} from as many indices, the robot busy"


def _rfc_unknown(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    name = "".join(rng.choice("ABCDEFGHIJKLMNOPQRSTUVWXYZ-") for _ in range(rng.randint(1, 12)))
    if name == g.contact:
        name += "X"
    p = _stray(n, 0, ChaosOp.RFC, data=name.encode("ascii"), packet_no=rng.randrange(0x10000))
    return (Stray(p, "answer", "connect.contact-name"),), f"RFC for contact {name!r}, which is not served"


def _duplicate_rfc(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    p = _stray(n, 0, ChaosOp.RFC, data=g.contact.encode("ascii"), packet_no=rng.randrange(0x10000))
    return (Stray(p, "answer", "ncp.duplicate-rfc"), Stray(p, "answer", "ncp.duplicate-rfc")), "an RFC twice"


def _out_of_window(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    if rng.random() < 0.5:
        offset = rng.choice((1, 2, rng.randint(1, 1000)))
        step = ConnPacket("ahead", HERE, offset=offset, clause="ncp.window")
        return (step,), f"here numbered {offset} past the receive window"
    offset = rng.randint(1, 200)
    step = ConnPacket("behind", HERE, offset=offset, clause="ncp.retransmission")
    return (step,), f"here numbered {offset} before the next packet (a stale number)"


def _duplicate(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    return (
        ConnPacket("duplicate", HERE, clause="ncp.retransmission"),
    ), "the last request again, same number"


def _wrong_source(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    offset = rng.randrange(1, 0x10000)
    step = ConnPacket("wrong-source", HERE, offset=offset, clause="ncp.los")
    return (step,), "here to the connection's index from another source index"


def _sense(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    if rng.random() < 0.7:
        return (ConnPacket("sns", ChaosOp.SNS, clause="ncp.retransmission"),), "SNS on the connection"
    data = rng.randbytes(rng.randrange(32))
    return (
        ConnPacket("unc", ChaosOp.UNC, data=data, clause="request.opcode-range"),
    ), "UNC on the connection"


# --------------------------------------------------------------------------------------- link classes


def _damaged(
    rng: random.Random, n: int, damage: Literal["checksum", "nbytes", "header-byte"], clause: str
) -> tuple[tuple[Step, ...], str]:
    """A packet that would draw a LOS (data to no connection), damaged so the link must drop it."""
    p = _stray(n, 0, ChaosOp.DAT, data=rng.randbytes(rng.randrange(2, 64)), dest_index=_nowhere(rng))
    return (Stray(p, "silence", clause, damage=damage, counted=True),), f"a data packet with a bad {damage}"


def _bad_checksum(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    return _damaged(rng, n, "checksum", "chudp.checksum")


def _bad_nbytes(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    return _damaged(rng, n, "nbytes", "chaos.header.nbytes")


def _header_byte(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    return _damaged(rng, n, "header-byte", "chaos.header.unused-byte-zero")


def _chudp_header(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    p = _stray(n, 0, ChaosOp.DAT, data=rng.randbytes(8), dest_index=_nowhere(rng))
    damage: Literal["version", "function"] = rng.choice(("version", "function"))
    return (
        Stray(p, "silence", "chudp.header", damage=damage, counted=True),
    ), f"a datagram with a bad {damage}"


def _chudp_length(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    p = _stray(n, 0, ChaosOp.DAT, data=rng.randbytes(8), dest_index=_nowhere(rng))
    damage: Literal["short", "long"] = rng.choice(("short", "long"))
    return (Stray(p, "silence", "chudp.length", damage=damage, counted=True),), f"a datagram too {damage}"


def _bad_length(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    length = rng.choice((0, 2, 20, 21, 23, 511, 512, rng.randrange(0x10000) | 1, rng.randrange(512, 0x10000)))
    data = length.to_bytes(2, "big") + rng.randbytes(rng.randrange(64))
    return (Raw(data, "link.tcp.framing", closes=True, counted=1),), f"a frame length of {length}"


_TEXTS: Final = (
    b"GET / HTTP/1.0\r\n\r\n",
    b"SSH-2.0-OpenSSH_9.6\r\n",
    b"HELO manip.invalid\r\n",
    b"\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03",  # the start of a TLS client hello
)


def _garbage(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    if g.link == "datagram":
        data = rng.randbytes(rng.randrange(1, 600))
        return (Raw(data, "chudp.header", counted=1),), f"a datagram of {len(data)} random bytes"
    if rng.random() < 0.4:
        text = rng.choice(_TEXTS)
        return (Raw(text, "link.tcp.framing", closes=True, counted=1),), f"text {text[:12]!r} on a new link"
    # A first byte of 2 or more makes a length above 510: the stream is lost at once, never waits.
    data = bytes([rng.randrange(2, 256)]) + rng.randbytes(rng.randrange(1, 200))
    return (Raw(data, "link.tcp.framing", closes=True, counted=1),), f"{len(data)} random bytes on a new link"


def _truncated(rng: random.Random, g: GenOptions, n: int) -> tuple[tuple[Step, ...], str]:
    if rng.random() < 0.3:
        return (
            Raw(b"", "link.tcp.framing", hold=rng.random() < 0.5),
        ), "a link opened and left without a byte"
    length = rng.randrange(22, 511, 2)
    data = length.to_bytes(2, "big") + rng.randbytes(rng.randrange(0, length))
    hold = rng.random() < 0.5
    left = "left open" if hold else "closed"
    return (Raw(data, "link.tcp.framing", hold=hold),), f"{len(data)} bytes of a {length}-byte frame, {left}"


# --------------------------------------------------------------------------------------- the table

_STREAM: Final[frozenset[LinkKind]] = frozenset({"stream"})
_DATAGRAM: Final[frozenset[LinkKind]] = frozenset({"datagram"})

_TABLE: Final[tuple[InputClass, ...]] = (
    InputClass(
        "manip.valid",
        "manip",
        "every request opcode the spec defines, data laid out as its layout says, plausible values",
        "exactly one reply echoing the request's number: the response the spec gives the opcode (done, "
        "data, segment number, multi-packet text) or a non-fatal error",
        ("request.one-reply", "response.echoes-request-number", "response.data-layout"),
        _valid,
        20,
        hazard="power",
        adapts=True,
    ),
    InputClass(
        "manip.unknown-opcode",
        "manip",
        "data opcodes no request uses (0222-0237, 0262-0377), 0 to 488 data bytes",
        "a non-fatal error (0202) of severity C (manip: C UOP), the connection still open",
        ("request.unknown-opcode",),
        _unknown,
        8,
    ),
    InputClass(
        "manip.wrong-length",
        "manip",
        "every request opcode at wrong data lengths (near its layout, 0, 488)",
        "a non-fatal error of severity C (manip: C BDL), not executed",
        ("request.data-length",),
        _wrong_length,
        12,
        hazard="power",
        adapts=True,
    ),
    InputClass(
        "manip.reserved-float",
        "manip",
        "requests with float fields, one to three of them the reserved operand (sign 1, exponent 0)",
        "a non-fatal error of severity C (manip: C BFL), not executed",
        ("request.reserved-float", "float.reserved-operand"),
        _reserved_float,
        8,
        hazard="power",
        adapts=True,
    ),
    InputClass(
        "manip.extreme-float",
        "manip",
        "requests with float fields at the extremes of PDP-11 floats (largest, smallest, dirty zero, top "
        "and bottom exponents); set speed with factors outside 0 < n <= 1",
        "one reply (a response or a non-fatal error, never a crash); set speed: a command error (C BVA)",
        ("request.one-reply", "float.dirty-zero", "speed.range"),
        _extreme,
        8,
        hazard="power",
        adapts=True,
    ),
    InputClass(
        "manip.pipeline",
        "manip",
        "2 to 60 (now and then 500) read-only requests of the classes above, sent without reading a reply",
        "every request answered, in order, each reply echoing its request's number",
        ("request.one-reply", "response.echoes-request-number"),
        _pipeline,
        3,
    ),
    InputClass(
        "manip.sequence",
        "manip",
        "short scripts: kill power then move; power, notifications and ready; free joint then a request; "
        "a speed then a move; describe self then requests; describe self then set joint angles",
        "what the spec says step by step: NAP without power, increasing segment numbers, "
        "segment-completed responses only when asked for, the packet after free joint answered done; "
        "answers as describe self said (operations served, joint vectors, joint limits)",
        (
            "motion.no-power",
            "segment.number-increases",
            "async.only-when-requested",
            "async.layout",
            "free-joint.replies",
            "describe.reply-shape",
            "describe.operations-answered",
            "describe.operations-complete",
            "describe.dof-joint-vectors",
            "describe.joint-limits",
            "motion.abort",
        ),
        _sequence,
        4,
        hazard="power",
    ),
    InputClass(
        "link.fragmented",
        "link",
        "a read-only request whose frame is written 1 to 7 bytes at a time",
        "served as if written at once",
        ("link.tcp.framing",),
        _fragmented,
        2,
        links=_STREAM,
    ),
    InputClass(
        "chaos.no-connection",
        "chaos",
        "data, SNS, STS and EOF packets to an index that is no connection",
        'a LOS ("Connection doesn\'t exist") back to the sender',
        ("ncp.los",),
        _no_connection,
        4,
    ),
    InputClass(
        "chaos.illegal-opcode",
        "chaos",
        "packets with opcode 0 or 017-0177",
        "a LOS back to the sender",
        ("chaos.opcode.legal", "ncp.los"),
        _illegal_opcode,
        3,
    ),
    InputClass(
        "chaos.no-los-for-los",
        "chaos",
        "LOS, CLS, ANS and FWD to an index that is no connection",
        "nothing: a LOS or CLS never draws a LOS",
        ("ncp.los",),
        _no_los_for_los,
        2,
    ),
    InputClass(
        "chaos.ignored",
        "chaos",
        "a data packet for another host; MNT and RUT",
        "nothing (a host drops them)",
        ("ncp.los",),
        _ignored,
        1,
    ),
    InputClass(
        "chaos.oversize",
        "chaos",
        "a CHUDP datagram with 489 to 552 data bytes",
        "a LOS (more than 488 data bytes)",
        ("chaos.data.max-488", "ncp.los"),
        _oversize,
        2,
        links=_DATAGRAM,
    ),
    InputClass(
        "chaos.rfc-flood",
        "chaos",
        "1 to 20 RFCs for the contact from as many indices while the robot has its client",
        "each answered: CLS (busy: one client per robot), or OPN on a server with room for more",
        ("connect.one-server-per-robot",),
        _rfc_flood,
        2,
    ),
    InputClass(
        "chaos.rfc-unknown-contact",
        "chaos",
        "an RFC for a contact name the target does not serve",
        "a CLS refusal",
        ("connect.contact-name",),
        _rfc_unknown,
        1,
    ),
    InputClass(
        "chaos.duplicate-rfc",
        "chaos",
        "the same RFC twice (same source index and number)",
        "answered, and no second connection opened",
        ("ncp.duplicate-rfc",),
        _duplicate_rfc,
        1,
    ),
    InputClass(
        "chaos.out-of-window",
        "chaos",
        "a here request numbered past the connection's receive window, or before its next packet",
        "not delivered: no reply to it, the connection serving on in order",
        ("ncp.window", "ncp.retransmission"),
        _out_of_window,
        3,
    ),
    InputClass(
        "chaos.duplicate",
        "chaos",
        "the connection's last request again, with the same packet number",
        "delivered once: no second reply",
        ("ncp.retransmission",),
        _duplicate,
        2,
    ),
    InputClass(
        "chaos.wrong-source",
        "chaos",
        "a here request to the connection's index from a source index that is not its peer's",
        "a LOS back to that source index; the connection unharmed",
        ("ncp.los",),
        _wrong_source,
        2,
    ),
    InputClass(
        "chaos.sense",
        "chaos",
        "SNS on the connection; UNC (uncontrolled data) on the connection",
        "SNS: an STS; UNC: no reply (it is no request)",
        ("ncp.retransmission", "request.opcode-range"),
        _sense,
        2,
    ),
    InputClass(
        "link.bad-checksum",
        "link",
        "a packet that would draw a LOS, its checksum wrong",
        "dropped and counted by the link: no LOS",
        ("chudp.checksum",),
        _bad_checksum,
        3,
    ),
    InputClass(
        "link.bad-nbytes",
        "link",
        "a packet that would draw a LOS, its byte count not the data it carries",
        "dropped and counted: no LOS",
        ("chaos.header.nbytes",),
        _bad_nbytes,
        2,
    ),
    InputClass(
        "link.header-byte",
        "link",
        "a packet that would draw a LOS, the unused low byte of its first header word set",
        "dropped and counted: no LOS",
        ("chaos.header.unused-byte-zero",),
        _header_byte,
        1,
    ),
    InputClass(
        "link.bad-length",
        "link",
        "a new TCP link whose first frame length is odd, below 22 or above 510",
        "the link dropped (its framing is lost), the bad frame counted",
        ("link.tcp.framing",),
        _bad_length,
        2,
        links=_STREAM,
    ),
    InputClass(
        "link.garbage",
        "link",
        "a new link carrying random bytes or a line of another protocol (HTTP, SSH, SMTP, TLS); on CHUDP "
        "a datagram of random bytes",
        "TCP: the link dropped, counted; CHUDP: the datagram dropped, counted",
        ("link.tcp.framing", "chudp.header"),
        _garbage,
        2,
    ),
    InputClass(
        "link.truncated",
        "link",
        "a new link with part of a frame (or nothing), then closed or left open",
        "nothing to answer; the target frees the link (in time: its frame timeout) without a traceback",
        ("link.tcp.framing",),
        _truncated,
        1,
        links=_STREAM,
    ),
    InputClass(
        "link.chudp-header",
        "link",
        "a datagram whose CHUDP version or function byte is wrong",
        "dropped and counted: no LOS",
        ("chudp.header",),
        _chudp_header,
        2,
        links=_DATAGRAM,
    ),
    InputClass(
        "link.chudp-length",
        "link",
        "a datagram cut short or with bytes after the trailer",
        "dropped and counted: no LOS",
        ("chudp.length",),
        _chudp_length,
        2,
        links=_DATAGRAM,
    ),
)

INPUT_CLASSES: Final[dict[str, InputClass]] = {c.id: c for c in _TABLE}

for _c in _TABLE:
    for _clause in _c.clauses:
        if _clause not in SPEC.clauses:
            raise RuntimeError(f"fuzz class {_c.id} names unknown clause {_clause!r}")


@functools.cache
def _pool(options: GenOptions) -> tuple[InputClass, ...]:
    return tuple(options.classes())


def generate(seed: int, number: int, options: GenOptions) -> FuzzInput:
    """Input ``number`` of the campaign ``seed``: its class drawn by weight, then its steps."""
    pool = _pool(options)
    if not pool:
        raise ValueError("no input class is left to draw from")
    rng = random.Random(seed << 40 | number)
    total = sum(c.weight for c in pool)
    pick = rng.randrange(total)
    for chosen in pool:
        pick -= chosen.weight
        if pick < 0:
            break
    steps, note = chosen.make(rng, options, number)
    return FuzzInput(number, chosen.id, steps, note)
