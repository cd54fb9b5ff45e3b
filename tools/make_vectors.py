"""Write src/manip/vectors/manip.json and cougar.json: golden vectors for message bodies and Cougar words.

Deliberately independent of manip's codecs: each vector spells its wire layout out item by item, read
from the 1985 guide (E.1, E.3, Table 1), and bytes are produced here with ``struct`` and an exact
``fractions``-based PDP-11 float encoder.  Tests then check manip's codecs against these files both ways.
Values are exactly representable so a decode must give them back unchanged.
"""

from __future__ import annotations

import json
import struct
from fractions import Fraction
from pathlib import Path
from typing import Any

OUT = Path(__file__).resolve().parents[1] / "src" / "manip" / "vectors"

Item = tuple[str, Any]  # ("f", float) | ("w", word) | ("i", int16) | ("b", byte) | ("t", ascii text)


def f_words(x: float) -> tuple[int, int]:
    """PDP-11 F words of an exactly representable value."""
    if x == 0:
        return 0, 0
    q = Fraction(abs(x))
    e = 0
    while q >= 1:
        q /= 2
        e += 1
    while q < Fraction(1, 2):
        q *= 2
        e -= 1
    m = q * 2**24
    assert m.denominator == 1, f"{x} is not exactly representable"
    frac = int(m) - 2**23
    w0 = (0x8000 if x < 0 else 0) | (e + 128) << 7 | frac >> 16
    return w0, frac & 0xFFFF


def wire(items: list[Item]) -> bytes:
    out = bytearray()
    for kind, v in items:
        if kind == "f":
            out += struct.pack("<HH", *f_words(v))
        elif kind == "w":
            out += struct.pack("<H", v)
        elif kind == "i":
            out += struct.pack("<h", v)
        elif kind == "b":
            out.append(v)
        elif kind == "t":
            out += v.encode("ascii")
    return bytes(out)


def fl(*xs: float) -> list[Item]:
    return [("f", float(x)) for x in xs]


T1 = (1, 0, 0, 0, 1, 0, 0, 0, 1, 500, 150, 400)
T2 = (0, 1, 0, -1, 0, 0, 0, 0, 1, -150.5, 431.75, 20.25)
READY = (0, -90, 90, 0, 0, 0)


def req(opcode: int, name: str, fields: dict[str, Any], items: list[Item]) -> dict[str, Any]:
    return {
        "kind": "request",
        "opcode": f"{opcode:o}",
        "name": name,
        "fields": fields,
        "hex": wire(items).hex(),
    }


def rep(opcode: int, name: str, number: int, fields: dict[str, Any], items: list[Item]) -> dict[str, Any]:
    return {
        "kind": "reply",
        "request_opcode": f"{opcode:o}",
        "name": f"{name} reply",
        "request_number": number,
        "fields": fields,
        "hex": wire([("w", number), *items]).hex(),
    }


def floats(xs: tuple[float, ...]) -> list[float]:
    return [float(x) for x in xs]


def manip_vectors() -> list[dict[str, Any]]:
    damping = tuple(2.0 if i % 7 == 0 else 0.0 for i in range(36))
    offsets = (12, -7, 0, 3, -2048, 2047, 1, -1)
    v: list[dict[str, Any]] = [
        req(0o200, "describe-self", {}, []),
        req(0o201, "here", {}, []),
        req(0o202, "joint-angles", {}, []),
        req(0o203, "calibrate", {}, []),
        req(0o204, "move", {"transform": floats(T1)}, fl(*T1)),
        req(0o205, "straight-move", {"transform": floats(T2)}, fl(*T2)),
        req(0o206, "kill-power", {}, []),
        req(0o207, "set-configuration", {"configuration": 1}, [("b", 1)]),
        req(0o210, "hand", {"amount": 0}, [("w", 0)]),
        req(
            0o211,
            "incremental-move",
            {"delta": floats((10, -5, 2.5, 0, 90, -45))},
            fl(10, -5, 2.5, 0, 90, -45),
        ),
        req(
            0o212,
            "incremental-straight-move",
            {"delta": floats((0, 0, -50, 0, 0, 0))},
            fl(0, 0, -50, 0, 0, 0),
        ),
        req(0o213, "free-joint", {"joint": 3}, [("b", 3)]),
        req(0o214, "ready", {}, []),
        req(0o215, "set-joint-angles", {"joints": floats(READY)}, fl(*READY)),
        req(0o216, "set-speed", {"factor": 0.5}, fl(0.5)),
        req(0o217, "enable-power", {}, []),
        req(0o220, "solve-forwards", {"transform": floats(T1), "current": floats(READY)}, fl(*T1, *READY)),
        req(
            0o221, "solve-backwards", {"joints": floats((10, -45, 120, 0, 30, 0))}, fl(10, -45, 120, 0, 30, 0)
        ),
        req(0o240, "read-forces", {}, []),
        req(0o241, "read-raw-gauges", {}, []),
        req(0o242, "set-gauge-offsets", {"offsets": list(offsets)}, [("i", o) for o in offsets]),
        req(0o243, "calibrate-wrist", {}, []),
        req(
            0o244,
            "set-spring",
            {"k": floats((0.5, 0.5, 0.25, 0.125, 0.125, 0.125))},
            fl(0.5, 0.5, 0.25, 0.125, 0.125, 0.125),
        ),
        req(0o245, "set-damping", {"b": floats(damping)}, fl(*damping)),
        req(
            0o246, "set-joint-damping", {"bji": floats((1, 1, 1, 0.5, 0.5, 0.5))}, fl(1, 1, 1, 0.5, 0.5, 0.5)
        ),
        req(0o247, "set-frame-vector", {"offset": floats((0, 0, 125.5))}, fl(0, 0, 125.5)),
        req(0o250, "set-weight", {"weight": 16.0, "cg": floats((0, 0, 50))}, fl(16, 0, 0, 50)),
        req(
            0o251,
            "set-guard",
            {"type_index": 0x8003, "dvec": floats((0, 0, 1, 0, 0, 0)), "tol": 20.0},
            [("w", 0x8003), *fl(0, 0, 1, 0, 0, 0, 20)],
        ),
        req(0o252, "clear-guard", {"index": 3}, [("w", 3)]),
        req(
            0o253,
            "compliant-move",
            {"joints": floats((0, -90, 90, 0, 45, 0)), "scheme": 0},
            [*fl(0, -90, 90, 0, 45, 0), ("w", 0)],
        ),
        req(0o254, "examine-wrist", {"address": 0o1000, "count": 4}, [("w", 0o1000), ("w", 4)]),
        req(0o255, "deposit-wrist", {"address": 0o1000, "value": 0o177777}, [("w", 0o1000), ("w", 0o177777)]),
        req(0o256, "wrist-version", {}, []),
        req(0o257, "request-notifications", {"mask": 3}, [("w", 3)]),
        req(0o260, "reset-abort", {}, []),
        req(0o261, "set-commanded-force", {"force": floats((0, 0, -10, 0, 0, 0))}, fl(0, 0, -10, 0, 0, 0)),
        rep(0o201, "here", 0x0123, {"transform": floats(T2)}, fl(*T2)),
        rep(0o202, "joint-angles", 5, {"joints": floats(READY)}, fl(*READY)),
        rep(0o203, "calibrate", 9, {}, []),
        rep(0o204, "move", 7, {"segment": 1}, [("w", 1)]),
        rep(0o215, "set-joint-angles", 0xFFFF, {"segment": 0x1234}, [("w", 0x1234)]),
        rep(
            0o220,
            "solve-forwards",
            11,
            {"joints": floats((10, -45, 120, 0, 30, 0))},
            fl(10, -45, 120, 0, 30, 0),
        ),
        rep(0o221, "solve-backwards", 12, {"transform": floats(T1)}, fl(*T1)),
        rep(
            0o240,
            "read-forces",
            13,
            {"forces": floats((1.5, -2, 0, 0.25, 0, -0.125))},
            fl(1.5, -2, 0, 0.25, 0, -0.125),
        ),
        rep(0o241, "read-raw-gauges", 14, {"gauges": list(offsets)}, [("i", o) for o in offsets]),
        rep(
            0o254,
            "examine-wrist",
            15,
            {"words": [1, 0o177777, 0o100000]},
            [("w", 3), ("w", 1), ("w", 0o177777), ("w", 0o100000)],
        ),
        rep(0o256, "wrist-version", 16, {"version": 3}, [("w", 3)]),
        rep(
            0o200,
            "describe-self",
            17,
            {"text": '((:BRAND-NAME . "Unimation Puma 600"))'},
            [("t", '((:BRAND-NAME . "Unimation Puma 600"))')],
        ),
        {
            "kind": "terminator",
            "request_opcode": "200",
            "name": "describe-self end",
            "request_number": 17,
            "hex": wire([("w", 17)]).hex(),
        },
        {
            "kind": "async",
            "name": "guard 3 hit, stop",
            "request_number": 20,
            "condition": 1,
            "word2": 1,
            "word3": 3,
            "hex": wire([("w", 20), ("w", 1), ("w", 1), ("w", 3)]).hex(),
        },
        {
            "kind": "async",
            "name": "segment 12 completed",
            "request_number": 21,
            "condition": 2,
            "word2": 0,
            "word3": 12,
            "hex": wire([("w", 21), ("w", 2), ("w", 0), ("w", 12)]).hex(),
        },
    ]

    def err(opcode: int, name: str, number: int, text: str, args: list[int], rendered: str) -> dict[str, Any]:
        body = [("w", number), ("t", text)]
        if args:
            body.append(("b", 0))
            if (len(text) + 1) % 2:  # words start at an even offset of the data
                body.append(("b", 0))
            body += [("w", a) for a in args]
        return {
            "kind": "error",
            "opcode": f"{opcode:o}",
            "name": name,
            "request_number": number,
            "rendered": rendered,
            "args": args,
            "hex": wire(body).hex(),
        }

    v += [
        err(
            0o201,
            "fatal NZI with a joint mask",
            3,
            "During calibration: F NZI No zero index found on joint(s) $.",
            [6],
            "During calibration: F NZI No zero index found on joint(s) 2 and 3.",
        ),
        err(
            0o202,
            "non-fatal JOR",
            8,
            "set-joint-angles: E JOR Joint out of range on joint(s) $",
            [0o41],
            "set-joint-angles: E JOR Joint out of range on joint(s) 1 and 6",
        ),
        err(
            0o202,
            "command error BDL",
            9,
            "dispatch: C BDL Expected ~ data bytes, got ~",
            [48, 44],
            "dispatch: C BDL Expected 48 data bytes, got 44",
        ),
        err(
            0o204,
            "asynchronous error PAN",
            10,
            "move process: E PAN Panic button pressed",
            [],
            "move process: E PAN Panic button pressed",
        ),
        err(
            0o205,
            "asynchronous warning",
            11,
            "wrist: W WSY Wrist resynchronised",
            [],
            "wrist: W WSY Wrist resynchronised",
        ),
    ]
    move = wire(fl(*T1))
    bad_float = bytearray(wire(fl(*READY)))
    bad_float[12:16] = bytes.fromhex("00800000")
    v += [
        {
            "kind": "request-error",
            "opcode": "204",
            "name": "move short by one float",
            "hex": move[:44].hex(),
            "error": {"clause": "request.data-length", "offset": 44},
        },
        {
            "kind": "request-error",
            "opcode": "204",
            "name": "move with a trailing word",
            "hex": (move + b"\0\0").hex(),
            "error": {"clause": "request.data-length", "offset": 48},
        },
        {
            "kind": "request-error",
            "opcode": "215",
            "name": "reserved operand in joint 4",
            "hex": bad_float.hex(),
            "error": {"clause": "float.reserved-operand", "offset": 12},
        },
        {
            "kind": "request-error",
            "opcode": "222",
            "name": "unassigned opcode",
            "hex": "",
            "error": {"clause": "request.unknown-opcode", "offset": 0},
        },
        {
            "kind": "reply-error",
            "request_opcode": "203",
            "name": "done reply with data",
            "hex": wire([("w", 1), ("w", 0)]).hex(),
            "error": {"clause": "response.done-empty"},
        },
        {
            "kind": "reply-error",
            "request_opcode": "201",
            "name": "reply without a request number",
            "hex": "01",
            "error": {"clause": "response.echoes-request-number"},
        },
    ]
    return v


def cougar_vectors() -> list[dict[str, Any]]:
    def words(items: list[Item]) -> list[int]:
        out: list[int] = []
        for kind, val in items:
            if kind == "f":
                out += f_words(val)
            elif kind == "i":
                out.append(val & 0xFFFF)
            else:
                out.append(val)
        return out

    def cmd(
        direction: str, code: int, name: str, fields: dict[str, Any], items: list[Item]
    ) -> dict[str, Any]:
        return {
            "direction": direction,
            "code": code,
            "name": name,
            "fields": fields,
            "words": [f"{w:04x}" for w in [code, *words(items)]],
        }

    six = (1, -2, 0.5, 0, 0, 100)
    offsets = (5, -5, 0, 2047, -2048, 1, 2, 3)
    npr = (*READY, 0, -90, 90, 0, 0, 1, 0, 0, 0, 0, 0, 0.25)
    return [
        cmd("command", 0, "NOP", {}, []),
        cmd("command", 1, "WINIT", {}, []),
        cmd("command", 2, "SEN", {"theta_sensed": floats(READY)}, fl(*READY)),
        cmd("command", 3, "FINIT", {"theta_sensed": floats(READY)}, fl(*READY)),
        cmd(
            "command",
            4,
            "NPR",
            {
                "theta_sensed": floats(npr[:6]),
                "theta_commanded": floats(npr[6:12]),
                "rate_difference": floats(npr[12:]),
            },
            fl(*npr),
        ),
        cmd("command", 5, "NFC", {"force": floats(six)}, fl(*six)),
        cmd("command", 6, "NK", {"k": floats(six)}, fl(*six)),
        cmd("command", 7, "NB", {"b": [float(i) for i in range(36)]}, fl(*range(36))),
        cmd("command", 8, "NBJI", {"bji": floats(six)}, fl(*six)),
        cmd("command", 9, "NFV", {"offset": [0.0, 0.0, 125.5]}, fl(0, 0, 125.5)),
        cmd("command", 10, "RST", {}, []),
        cmd("command", 11, "DPST", {"address": 0o1000, "value": 7}, [("w", 0o1000), ("w", 7)]),
        cmd("command", 12, "EXMN", {"address": 0o1000, "count": 3}, [("w", 0o1000), ("w", 3)]),
        cmd("command", 13, "VERS", {"version": 1}, [("w", 1)]),
        cmd("command", 14, "RFRC", {}, []),
        cmd("command", 15, "NEWWC", {"weight": 16.0, "cg": [0.0, 0.0, 50.0]}, fl(16, 0, 0, 50)),
        cmd(
            "command",
            16,
            "GUARDS",
            {"type_index": 0x8005, "dvec": floats((0, 0, 1, 0, 0, 0)), "tol": 20.0},
            [("w", 0x8005), *fl(0, 0, 1, 0, 0, 0, 20)],
        ),
        cmd("command", 17, "GUARDC", {"index": 5}, [("w", 5)]),
        cmd("command", 18, "RRAW", {}, []),
        cmd("command", 19, "WGOV", {"offsets": list(offsets)}, [("i", o) for o in offsets]),
        cmd("response", 1, "NTD", {"delta_theta": floats(six)}, fl(*six)),
        cmd("response", 2, "OUT-OF-SYNC", {"code": 99}, [("w", 99)]),
        cmd("response", 4, "EXMN-DATA", {"words": [1, 2, 3]}, [("w", 3), ("w", 1), ("w", 2), ("w", 3)]),
        cmd("response", 5, "FORCES", {"forces": floats(six)}, fl(*six)),
        cmd("response", 6, "GUARD-STOP", {"index": 5}, [("w", 5)]),
        cmd("response", 7, "GUARD-CONTINUE", {"index": 2}, [("w", 2)]),
        cmd("response", 8, "VERSION", {"version": 1}, [("w", 1)]),
        cmd("response", 9, "RAW", {"gauges": list(offsets)}, [("i", o) for o in offsets]),
    ]


def main() -> None:
    manip = {
        "format": "manip-vectors/1",
        "subject": "manip-messages",
        "notes": "Request data and server packet data (after the Chaos header). Words are little-endian;"
        " floats are PDP-11 F floats, bytes [w0.lo, w0.hi, w1.lo, w1.hi]; opcodes are octal strings."
        " Replies begin with the request number. Error offsets count from the start of the data.",
        "vectors": manip_vectors(),
    }
    cougar = {
        "format": "manip-vectors/1",
        "subject": "cougar-words",
        "notes": "Table 1 messages as 16-bit words in hex, code word first; floats are two words,"
        " sign/exponent word first.",
        "vectors": cougar_vectors(),
    }
    (OUT / "manip.json").write_text(json.dumps(manip, indent=1) + "\n")
    (OUT / "cougar.json").write_text(json.dumps(cougar, indent=1) + "\n")
    print(f"wrote {OUT / 'manip.json'} and cougar.json")


if __name__ == "__main__":
    main()
