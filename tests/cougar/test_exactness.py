"""The simulated Cougar's fast paths against the plain numpy formulations they replace.

Cougar keeps what it computes in its memory, where the Puma reads it (EXMN, RFRC, NTD), so each shortcut
the simulator takes -- plain floats where numpy only worked elementwise, decoded regions kept between
stores, JACOB storing the words it kept while its inputs stay -- must store the very same words.  The
references below are the formulations as first written.
"""

from __future__ import annotations

import contextlib
import math
import struct
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.arm import PUMA560_LEE, Transform, forward, jacobian
from manip.codecs.pdp11float import F_MAX, F_MIN_NORMAL, pack_f_array, unpack_f_array
from manip.cougar import Contacts, Spring, Surface, Wrench
from manip.cougar.adc import ADC_MAX, ADC_MIN, GaugeModel
from manip.cougar.compliance import MM_PER_INCH, centre_jacobian, gravity_load, limit, skew
from manip.cougar.jacob import STEPS, Jacob
from manip.cougar.memory import JBUF_J, JBUF_JT, JBUF_P, MAP, Memory, region

FLOAT_REGIONS = [r for r in MAP if r.kind == "float"]
FLOAT_NAMES = st.sampled_from([r.name for r in FLOAT_REGIONS])
angles = st.one_of(
    st.floats(-400.0, 400.0), st.sampled_from([0.0, -0.0, 90.0, -90.0, 180.0]), st.floats(-1e30, 1e30)
)
#: Where the F encoding changes its way: the ends of the F range, just past them, where 4x leaves the
#: IEEE single range, the rounding tie at 24 bits.
EDGES = [
    F_MIN_NORMAL,
    math.nextafter(F_MIN_NORMAL, 0.0),
    F_MIN_NORMAL * (1.0 - 2.0**-25),
    F_MIN_NORMAL * (1.0 - 2.0**-24),
    F_MAX,
    math.nextafter(F_MAX, math.inf),
    math.ldexp(1.0, 126) - math.ldexp(1.0, 101),
    math.nextafter(math.ldexp(1.0, 126) - math.ldexp(1.0, 101), 0.0),
    1.0 + 2.0**-24,
    1.0 + 3 * 2.0**-24,
]
values = st.one_of(
    st.floats(-1e3, 1e3),
    st.sampled_from([0.0, -0.0, 0.3, -0.5, 500.0, F_MAX, -F_MAX, 1e38, 3e-39, 1e-300]),
    st.sampled_from(EDGES).flatmap(lambda x: st.sampled_from([x, -x])),
    st.floats(allow_nan=True, allow_infinity=True),
)


def bits(xs: Sequence[float]) -> bytes:
    return struct.pack(f"<{len(xs)}d", *xs)


# ------------------------------------------------------------------------------------ GUTS arithmetic
def numpy_gravity_load(rotation: np.ndarray, weight: float, cg_mm: np.ndarray) -> np.ndarray:
    f = rotation.T @ np.array([0.0, 0.0, -weight])
    return np.concatenate([f, np.cross(np.asarray(cg_mm) / MM_PER_INCH, f)])


@settings(max_examples=300, deadline=None)
@given(
    st.tuples(*(angles for _ in range(6))),
    st.one_of(st.floats(-200.0, 200.0), st.sampled_from([0.0, -0.0, F_MAX])),
    st.tuples(*(st.one_of(st.floats(-300.0, 300.0), st.sampled_from([0.0, -0.0, F_MAX])) for _ in range(3))),
)
def test_gravity_load_is_the_numpy_formulation(
    q: tuple[float, ...], weight: float, cg: tuple[float, ...]
) -> None:
    r = np.array(forward(q).rotation)
    expected = numpy_gravity_load(r, weight, np.array(cg))
    got = gravity_load(r.tolist(), weight, cg)
    # equal values; a zero's sign is BLAS's business (and no F float can show it)
    assert np.array_equal(np.array(got), expected)
    assert bits([v for v in got if v]) == bits([v for v in expected.tolist() if v])


@settings(max_examples=300, deadline=None)
@given(
    st.lists(values, min_size=6, max_size=6),
    st.sampled_from([0.5, 0.0, -1.0, 1e30]),
    values.filter(lambda v: not math.isnan(v)),  # LIMIT's constants come from memory: F floats, never NaN
)
def test_limit_is_numpys_where_then_clip(force: list[float], dead: float, clamp: float) -> None:
    a = np.array(force)
    with np.errstate(invalid="ignore"):
        expected = np.clip(np.where(np.abs(a) < dead, 0.0, a), -clamp, clamp)
    assert bits(limit(force, dead, clamp)) == bits(expected.tolist())


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.one_of(values, st.floats(-2100.0, 2100.0), st.integers(-2100, 2100).map(lambda i: i + 0.5)),
        min_size=8,
        max_size=8,
    )
)
def test_conversion_is_numpys_rint_and_clip(analog: list[float]) -> None:
    a = np.array(analog)
    finite = np.nan_to_num(a, nan=0.0, posinf=ADC_MAX, neginf=ADC_MIN)
    expected = [int(v) for v in np.clip(np.rint(finite), ADC_MIN, ADC_MAX)]
    assert GaugeModel().convert(a) == expected


def numpy_surface(s: Surface, tool: Transform) -> Wrench:
    n = np.array(s.normal, dtype=np.float64)
    n /= np.linalg.norm(n)
    depth = max(-float(np.dot(tool.p - np.array(s.point, dtype=np.float64), n)), 0.0)
    if depth == 0.0:
        return Wrench()
    n = np.array(s.normal, dtype=np.float64)
    return Wrench.of(s.stiffness * depth * n / np.linalg.norm(n))


@settings(max_examples=200, deadline=None)
@given(
    st.tuples(*(st.floats(-50.0, 50.0) for _ in range(3))),
    st.tuples(*(st.floats(-1.0, 1.0) for _ in range(3))).filter(lambda n: max(map(abs, n)) > 1e-3),
    st.tuples(*(st.floats(-50.0, 50.0) for _ in range(3))),
)
def test_contacts_are_the_numpy_formulas(point: tuple[float, ...], normal: tuple[float, ...],
                                         at: tuple[float, ...]) -> None:  # fmt: skip
    tool = Transform.trans(*at)
    surface = Surface(point=point, normal=normal, stiffness=3.0)
    expected = numpy_surface(surface, tool)
    assert surface.wrench(tool) == expected
    spring = Spring(anchor=point, stiffness=0.5, rest_length=2.0)
    d = np.array(point) - tool.p
    length = float(np.linalg.norm(d))
    pull = Wrench() if length == 0.0 else Wrench.of(0.5 * (length - 2.0) * d / length)
    assert spring.wrench(tool) == pull
    both = Contacts((surface, spring)).wrench(tool)
    assert both == Wrench.of(np.add(expected.force, pull.force), np.add(expected.torque, pull.torque))


# ------------------------------------------------------------------------------------ memory
def decoded(memory: Memory, name: str) -> list[float]:
    r = region(name)
    words = memory.read_words(r.address, r.words)
    return unpack_f_array(struct.pack(f"<{len(words)}H", *words), reserved="zero").tolist()


def addresses() -> st.SearchStrategy[int]:
    """A word inside or around the float regions."""
    low, high = FLOAT_REGIONS[0].address - 8, MAP[-1].end
    return st.integers(low // 2, high // 2 - 1).map(lambda i: 2 * i)


operations = st.one_of(
    st.tuples(st.just("word"), addresses(), st.integers(0, 0xFFFF)),
    st.tuples(st.just("words"), addresses(), st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=40)),
    st.tuples(st.just("bad words"), addresses(), st.lists(st.integers(0, 0xFFFF), min_size=1, max_size=8)),
    st.tuples(st.just("floats"), addresses(), st.lists(values, min_size=1, max_size=40)),
    st.tuples(st.just("put"), FLOAT_NAMES, st.randoms()),
    st.tuples(st.just("int16s"), addresses(), st.lists(st.integers(-0x8000, 0x7FFF), min_size=1, max_size=8)),
)


@settings(max_examples=150, deadline=None)
@given(st.lists(operations, max_size=25), st.lists(FLOAT_NAMES, max_size=6))
def test_decoded_regions_follow_every_store(ops: list[tuple[object, ...]], watched: list[str]) -> None:
    memory = Memory()
    for op, where, data in ops:
        for name in watched:  # decode now, so that the store must make the memory forget it
            memory.floats(name)
            memory.array(name)
        try:
            if op == "word":
                memory.write_word(where, data)  # type: ignore[arg-type]
            elif op == "words":
                memory.write_words(where, data)  # type: ignore[arg-type]
            elif op == "bad words":  # the words before the bad one are stored
                memory.write_words(where, [*data, 0x10000])  # type: ignore[list-item, arg-type]
            elif op == "floats":
                memory.write_floats(where, data)  # type: ignore[arg-type]
            elif op == "int16s":
                memory.write_int16s(where, data)  # type: ignore[arg-type]
            else:
                r = region(where)  # type: ignore[arg-type]
                rng = data
                memory.put(r.name, [rng.uniform(-1e3, 1e3) for _ in range(r.count)])  # type: ignore[attr-defined]
        except ValueError:
            pass
        for r in FLOAT_REGIONS:
            expected = decoded(memory, r.name)
            assert bits(memory.floats(r.name)) == bits(expected), r.name
            assert bits(memory.array(r.name).tolist()) == bits(expected), r.name
            assert bits(memory.get(r.name).tolist()) == bits(expected), r.name


@settings(max_examples=500, deadline=None)
@given(
    st.one_of(
        st.lists(st.one_of(values, st.integers(-(2**140), 2**140), st.booleans()), max_size=70),
        st.lists(values, max_size=70).map(np.array),
        st.lists(values, min_size=36, max_size=36).map(lambda v: np.array(v).reshape(6, 6).T),
    )
)
def test_encoded_floats_are_what_write_floats_stored_before(xs: list[float] | np.ndarray) -> None:
    x = np.array(xs, dtype=np.float64).reshape(-1)
    if x.size and not (np.all(np.isfinite(x)) and np.abs(x).max() <= F_MAX):
        x, saturated = np.clip(np.nan_to_num(x, nan=0.0, posinf=F_MAX, neginf=-F_MAX), -F_MAX, F_MAX), True
    else:
        saturated = False
    assert Memory.encode_floats(xs) == (pack_f_array(x), saturated)


# ------------------------------------------------------------------------------------ JACOB
def numpy_centre_jacobian(theta: np.ndarray, fv: np.ndarray) -> np.ndarray:
    """The centre Jacobian as first written: the correction made even when FV is zero."""
    j = jacobian(theta, PUMA560_LEE, frame="tool")
    j[:3] -= skew(fv) @ j[3:] * (math.pi / 180.0)
    return j


class ReferenceJacob:
    """JACOB as first written: every step computes and encodes from scratch."""

    def __init__(self) -> None:
        self.step_index = 0
        self.j = np.zeros((6, 6))
        self.bji = np.zeros(6)

    def step(self, memory: Memory) -> None:
        bit = memory.word("jacob_front") & 1
        back = region(f"jbuf{bit ^ 1}").address
        if self.step_index == 0:
            self.bji = memory.get("bji")
            with contextlib.suppress(ValueError):
                self.j = numpy_centre_jacobian(memory.get("theta_sensed"), memory.get("fv"))
            memory.write_floats(back + 4 * JBUF_J, self.j)
        elif self.step_index == 1:
            memory.write_floats(back + 4 * JBUF_JT, self.j.T)
        elif self.step_index == 2:
            memory.write_floats(back + 4 * JBUF_P, self.bji[:, None] * self.j.T)
        else:
            memory.set_word("jacob_front", bit ^ 1)
        self.step_index = (self.step_index + 1) % STEPS


deposit_regions = ["theta_sensed", "fv", "bji", "jbuf0", "jbuf1", "jacob_front"]


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 6), st.lists(st.tuples(st.sampled_from(deposit_regions),
                                                                 st.integers(0, 215), st.integers(0, 0xFFFF)),
                                                       max_size=3)), max_size=20))  # fmt: skip
def test_jacob_stores_what_computing_every_step_afresh_stores(
    script: list[tuple[int, list[tuple[str, int, int]]]],
) -> None:
    fast, slow = Memory(), Memory()
    jacob, reference = Jacob(PUMA560_LEE), ReferenceJacob()
    for memory in (fast, slow):
        memory.put("theta_sensed", (10.0, -80.0, 95.0, 5.0, 20.0, 30.0))
        memory.put("bji", (0.5, 1.0, 2.0, 1e38, 3.0, 0.0))
    for steps, deposits in script:
        for name, index, value in deposits:  # the Puma's DPST, between background steps
            r = region(name)
            for memory in (fast, slow):
                memory.write_word(r.address + 2 * (index % r.words), value)
        for _ in range(steps):
            jacob.step(fast)
            reference.step(slow)
            assert fast.read_words(0, 0o10000) == slow.read_words(0, 0o10000)
            assert fast.float_faults == slow.float_faults


def test_jacob_recomputes_when_an_input_changes_and_only_then(monkeypatch: pytest.MonkeyPatch) -> None:
    import manip.cougar.jacob as jacob_module

    calls: list[int] = []

    def counted(*args: Any) -> np.ndarray:
        calls.append(1)
        return centre_jacobian(*args)

    monkeypatch.setattr(jacob_module, "centre_jacobian", counted)
    memory = Memory()
    jacob = Jacob(PUMA560_LEE)

    def front() -> np.ndarray:
        return memory.get(f"jbuf{memory.word('jacob_front') & 1}")

    def stored_j() -> np.ndarray:
        return front()[:36].reshape(6, 6)

    def expected_j() -> np.ndarray:
        j = centre_jacobian(memory.get("theta_sensed"), memory.get("fv"), PUMA560_LEE)
        return unpack_f_array(pack_f_array(j)).reshape(6, 6)

    memory.put("theta_sensed", (10.0, -80.0, 95.0, 5.0, 20.0, 30.0))
    jacob.run(memory, 3 * STEPS)
    assert len(calls) == 1 and np.array_equal(stored_j(), expected_j())
    memory.put("bji", (1.0,) * 6)  # P changes, J does not
    jacob.run(memory, STEPS)
    assert len(calls) == 1 and np.array_equal(front()[72:], front()[36:72])  # P = 1·Jᵀ
    memory.put("fv", (0.0, 0.0, 100.0))
    jacob.run(memory, STEPS)
    assert len(calls) == 2 and np.array_equal(stored_j(), expected_j())
