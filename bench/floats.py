"""PDP-11 F-float benchmark (run by hand): manip's codecs against IEEE float32 baselines in the same run.

Each figure is printed next to a baseline doing the nearest IEEE job on the same values in the same
process (``struct`` float32 per value for the scalar and construct rows, ``struct``/numpy float32 for
the bulk rows), so the ratios carry across machines even when the absolute rates do not.

    .venv/bin/python bench/floats.py [--seconds 1.0] [--count 1000000]

Target (issue brief): bulk decode >= 5 M floats/s.  Nothing is asserted about timings.
"""

from __future__ import annotations

import argparse
import functools
import struct
import time
from collections.abc import Callable

import numpy as np
from construct import Array, Float32l, Int16ul, Struct

from manip.codecs.pdp11float import (
    Float32F,
    f_to_u32,
    pack_f,
    pack_f_array,
    u32_to_f,
    unpack_f,
    unpack_f_array,
)

_F32 = struct.Struct("<f")
_U32 = struct.Struct("<I")


def rate(fn: Callable[[], object], seconds: float) -> float:
    """Calls per second: best of five rounds, each about seconds/5 long."""
    n = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        if time.perf_counter() - t0 > 0.05:
            break
        n *= 2
    best = 0.0
    for _ in range(5):
        t0 = time.perf_counter()
        count = 0
        while time.perf_counter() - t0 < seconds / 5:
            for _ in range(n):
                fn()
            count += n
        best = max(best, count / (time.perf_counter() - t0))
    return best


def row(name: str, ours: float, base: float, base_name: str, unit: str = "floats/s") -> None:
    print(
        f"  {name:<22} {ours:>13,.0f} {unit:<9}  {base_name:<24} {base:>13,.0f}   ratio {ours / base:6.2f}x"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0)
    parser.add_argument("--count", type=int, default=1_000_000, help="floats per bulk call")
    args = parser.parse_args()

    rng = np.random.default_rng(1985)
    # Joint angles, positions and transform entries: the magnitudes the protocol carries.
    values = rng.uniform(-1000.0, 1000.0, args.count)
    values[::7] = 0.0  # transforms are full of zeros, which take the bulk decoder's slow branch
    raw = pack_f_array(values)
    ieee = values.astype("<f4").tobytes()
    exact = np.frombuffer(raw, "<u4")
    assert np.array_equal(unpack_f_array(raw), unpack_f_array(exact.astype(np.uint32)))

    small = 1000  # scalar rows: per-value Python calls, timed over a slice
    xs = [float(v) for v in values[:small]]
    us = [int(u) for u in exact[:small]]
    raw_s, ieee_s = raw[: 4 * small], ieee[: 4 * small]
    offsets = range(0, 4 * small, 4)

    print(f"Scalar path, {small:,} values per call (baseline: struct '<f' IEEE float32, same values)")
    base = rate(lambda: [_F32.unpack_from(ieee_s, o)[0] for o in offsets], args.seconds) * small
    row(
        "decode unpack_f",
        rate(lambda: [unpack_f(raw_s, o) for o in offsets], args.seconds) * small,
        base,
        "struct unpack_from",
    )
    row(
        "decode u32_to_f",
        rate(lambda: [u32_to_f(u) for u in us], args.seconds) * small,
        base,
        "struct unpack_from",
    )
    base = rate(lambda: b"".join([_F32.pack(x) for x in xs]), args.seconds) * small
    row(
        "encode pack_f",
        rate(lambda: b"".join([pack_f(x) for x in xs]), args.seconds) * small,
        base,
        "struct pack",
    )
    row("encode f_to_u32", rate(lambda: [f_to_u32(x) for x in xs], args.seconds) * small, base, "struct pack")

    print(f"Bulk numpy path, {args.count:,} floats per call")
    n = args.count
    fmt = struct.Struct(f"<{n}f")
    base = rate(lambda: fmt.unpack(ieee), args.seconds) * n
    dec = rate(lambda: unpack_f_array(raw), args.seconds) * n
    row("decode unpack_f_array", dec, base, f"struct '<{n}f' unpack")
    np_base = rate(lambda: np.frombuffer(ieee, "<f4").astype(np.float64), args.seconds) * n
    row("decode unpack_f_array", dec, np_base, "numpy f4 -> f8")
    base = rate(lambda: fmt.pack(*values), args.seconds) * n
    enc = rate(lambda: pack_f_array(values), args.seconds) * n
    row("encode pack_f_array", enc, base, f"struct '<{n}f' pack")
    np_base = rate(lambda: values.astype("<f4").tobytes(), args.seconds) * n
    row("encode pack_f_array", enc, np_base, "numpy f8 -> f4 bytes")
    listed = values.tolist()
    row(
        "encode (from a list)",
        rate(lambda: pack_f_array(listed), args.seconds) * n,
        base,
        f"struct '<{n}f' pack",
    )
    print(f"  bulk decode target >= 5 M floats/s: {'met' if dec >= 5e6 else 'NOT met'}")

    print("construct, one record = word + Array(12, float) (baseline: the same Struct with Float32l)")
    ours = Struct("n" / Int16ul, "v" / Array(12, Float32F))
    theirs = Struct("n" / Int16ul, "v" / Array(12, Float32l))
    rec = {"n": 7, "v": xs[:12]}
    wire_ours, wire_theirs = ours.build(rec), theirs.build(rec)
    for label, a, b in (("interpreted", ours, theirs), ("compiled", ours.compile(), theirs.compile())):
        row(
            f"parse {label}",
            rate(functools.partial(a.parse, wire_ours), args.seconds),
            rate(functools.partial(b.parse, wire_theirs), args.seconds),
            "Float32l",
            "records/s",
        )
        row(
            f"build {label}",
            rate(functools.partial(a.build, rec), args.seconds),
            rate(functools.partial(b.build, rec), args.seconds),
            "Float32l",
            "records/s",
        )


if __name__ == "__main__":
    main()
