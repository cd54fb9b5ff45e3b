"""Codec benchmark (run by hand): a Here response through manip's codecs against a struct baseline.

The message is the common case of the protocol: a Chaos header, the request number and a 12-float
transform (66 bytes).  The baseline is hand-written ``struct`` code doing the same job in the same run,
so the printed ratios are comparable across machines.  Also: the bulk numpy float path.

    .venv/bin/python bench/codec_speed.py [--seconds 1.0]

Targets (issue 2): single-packet decode >= 0.5x the baseline's rate; bulk decode >= 5 M floats/s.
"""

from __future__ import annotations

import argparse
import math
import struct
import time
from collections.abc import Callable

import numpy as np

from manip.codecs.chaos import decode_raw, encode_raw
from manip.codecs.messages import decode_reply, encode_reply
from manip.codecs.packet import Packet
from manip.codecs.pdp11float import pack_f_array, unpack_f_array
from manip.spec.constants import ServerOp

TRANSFORM = (0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -150.5, 431.75, 20.25)

_BASE = struct.Struct("<BB8H12I")  # header words + request number + 12 raw floats


def _f(u: int) -> float:
    """Minimal PDP-11 F decode for the baseline (no reserved-operand or dirty-zero policy)."""
    hi = u & 0xFFFF
    e = (hi >> 7) & 0xFF
    if e == 0:
        return 0.0
    v = math.ldexp(((hi & 0x7F) << 16 | (u >> 16)) | 0x800000, e - 152)
    return -v if hi & 0x8000 else v


def _u(x: float) -> int:
    if x == 0:
        return 0
    m, ex = math.frexp(abs(x))
    frac = round(m * 2**24)
    e = ex + 128
    if frac == 2**24:
        frac, e = 2**23, e + 1
    hi = (0x8000 if x < 0 else 0) | e << 7 | (frac >> 16) & 0x7F
    return hi | (frac & 0xFFFF) << 16


def baseline_decode(b: bytes) -> tuple[int, int, tuple[float, ...]]:
    fields = _BASE.unpack(b)
    return fields[7], fields[9], tuple(_f(u) for u in fields[10:])


def baseline_encode(number: int, transform: tuple[float, ...]) -> bytes:
    return _BASE.pack(0, ServerOp.RESPONSE, 50, 0o401, 1, 0o440, 2, 7, 3, number, *(_u(x) for x in transform))


def manip_decode(b: bytes) -> tuple[int, int, tuple[float, ...]]:
    p = decode_raw(b)
    r = decode_reply(p.data, "here")
    t = r.values["transform"]
    assert isinstance(t, tuple)
    return p.packet_no, r.request_number, t


def manip_encode(number: int, transform: tuple[float, ...]) -> bytes:
    data = encode_reply("here", number, transform=transform)
    return encode_raw(Packet(ServerOp.RESPONSE, 0o401, 1, 0o440, 2, 7, 3, data))


def _calibrate(fn: Callable[[], object]) -> int:
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        if time.perf_counter() - t0 > 0.02:
            return n
        n *= 2


def _round(fn: Callable[[], object], n: int) -> float:
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def rates(ours: Callable[[], object], base: Callable[[], object], seconds: float) -> tuple[float, float]:
    """Best calls/s of each, measured in alternating rounds so machine load hits both alike."""
    n_ours, n_base = _calibrate(ours), _calibrate(base)
    best_ours = best_base = 0.0
    deadline = time.perf_counter() + seconds
    while time.perf_counter() < deadline:
        best_ours = max(best_ours, _round(ours, n_ours))
        best_base = max(best_base, _round(base, n_base))
    return best_ours, best_base


def rate(fn: Callable[[], object], seconds: float) -> float:
    return rates(fn, fn, seconds)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0)
    args = parser.parse_args()

    wire = manip_encode(7, TRANSFORM)
    assert wire == baseline_encode(7, TRANSFORM), "baseline and manip disagree on the bytes"
    assert manip_decode(wire)[2] == baseline_decode(wire)[2] == TRANSFORM

    print(f"Here response, {len(wire)} bytes (header + request number + 12 PDP-11 floats)")
    rows = [
        ("decode", lambda: manip_decode(wire), lambda: baseline_decode(wire), 0.5),
        ("encode", lambda: manip_encode(7, TRANSFORM), lambda: baseline_encode(7, TRANSFORM), None),
    ]
    for name, ours, base, target in rows:
        r_ours, r_base = rates(ours, base, args.seconds)
        goal = (
            f"   target >= {target}x: {'met' if r_ours / r_base >= target else 'NOT met'}" if target else ""
        )
        print(
            f"  {name}: manip {r_ours:>10,.0f}/s   struct baseline {r_base:>10,.0f}/s   "
            f"ratio {r_ours / r_base:.2f}x{goal}"
        )

    count = 1_000_000
    rng = np.random.default_rng(1985)
    values = rng.uniform(-1e6, 1e6, count)
    raw = pack_f_array(values)
    floats_in = np.frombuffer(raw, dtype="<u4")
    ieee = values.astype("<f4").tobytes()
    dec = rate(lambda: unpack_f_array(raw), args.seconds) * count
    enc = rate(lambda: pack_f_array(values), args.seconds) * count
    ieee_dec = rate(lambda: np.frombuffer(ieee, dtype="<f4").astype(np.float64), args.seconds) * count
    assert floats_in.size == count
    print(f"Bulk numpy path, {count:,} floats per call")
    print(
        f"  decode {dec / 1e6:8.1f} M floats/s   (IEEE float32 -> float64 baseline {ieee_dec / 1e6:.1f} M/s, "
        f"ratio {dec / ieee_dec:.2f}x)   target >= 5 M/s: {'met' if dec >= 5e6 else 'NOT met'}"
    )
    print(f"  encode {enc / 1e6:8.1f} M floats/s")


if __name__ == "__main__":
    main()
