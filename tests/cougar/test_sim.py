"""The Cougar simulator behind its word protocol: every command of Table 1, GUTS, guards, memory, JACOB."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from manip.arm import READY, Transform, jacobian
from manip.codecs.cougar import CougarMsg, WordStream, encode
from manip.codecs.pdp11float import f_to_words
from manip.cougar import (
    Contacts,
    CougarConfig,
    CougarSim,
    FreeSpace,
    GaugeModel,
    Spring,
    Surface,
    Wrench,
)
from manip.cougar.adc import resolution_pattern
from manip.cougar.compliance import centre_jacobian, voltmat
from manip.cougar.jacob import STEPS, front_buffer
from manip.cougar.memory import MAP, MEMORY_BYTES, Memory, region
from manip.spec import SPEC
from tests.support.strategies import cougar_values

DT = 1 / 60
TOOL_Z = 864.87 + 150.0  # tool point height at READY (wrist centre + default 150 mm tool)


def cmd(name: str, **values: Any) -> list[int]:
    """Encode a command, taking ints where Table 1 has floats."""
    msg = next(m for m in SPEC.cougar_commands.values() if m.name == name)
    for f in msg.data:
        if f.element == "float" and f.name in values:
            v = values[f.name]
            values[f.name] = tuple(float(x) for x in v) if isinstance(v, (tuple, list)) else float(v)
    return encode("command", name, **values)


def answers(out: list[int]) -> list[CougarMsg]:
    stream = WordStream("response")
    items = stream.feed(out)
    assert stream.pending == ()
    assert all(isinstance(i, CougarMsg) for i in items), items
    return [i for i in items if isinstance(i, CougarMsg)]


class Driver:
    """Feeds commands tick by tick and collects the decoded answers."""

    def __init__(self, sim: CougarSim) -> None:
        self.sim = sim
        self.t = 0.0

    def run(self, *commands: list[int], ticks: int = 1) -> list[CougarMsg]:
        for c in commands:
            self.sim.receive(c)
        out: list[int] = []
        for _ in range(ticks):
            out += self.sim.tick(self.t)
            self.t += DT
        return answers(out)

    def one(self, *commands: list[int]) -> CougarMsg:
        (msg,) = self.run(*commands)
        return msg

    def forces(self) -> np.ndarray:
        return np.array(self.one(cmd("RFRC")).values["forces"])


def ceiling(depth_mm: float, stiffness: float = 10.0) -> Surface:
    """A ceiling ``depth_mm`` below the tool point at READY: the tool is pressed into it from below."""
    return Surface(point=(0.0, 0.0, TOOL_Z - depth_mm), normal=(0.0, 0.0, -1.0), stiffness=stiffness)


def float_words(x: float) -> tuple[int, int]:
    return f_to_words(x)


# ------------------------------------------------------------------------------------ every command
@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_every_command_answers_as_table_1_says(data: st.DataObject) -> None:
    msg = data.draw(st.sampled_from(sorted(SPEC.cougar_commands.values(), key=lambda m: m.code)))
    values = data.draw(cougar_values(msg))
    if msg.name == "GUARDS":  # a guard that cannot trip on a zero force
        values["tol"] = abs(values["tol"])
    sim = CougarSim(CougarConfig(hand_weight_oz=0.0))
    got = Driver(sim).run(encode("command", msg.name, **values))
    expected = {
        "NPR": ["NTD"],
        "EXMN": ["EXMN-DATA"],
        "VERS": ["VERSION"],
        "RFRC": ["FORCES"],
        "RRAW": ["RAW"],
    }.get(msg.name, [])
    assert [m.name for m in got] == expected
    assert sim.stats.commands == 1


def test_version_exchange() -> None:
    d = Driver(CougarSim(CougarConfig(version=0o123)))
    msg = d.one(cmd("VERS", version=42))
    assert msg.values["version"] == 0o123
    assert d.sim.memory.word("puma_version") == 42
    assert d.sim.terminal.startswith("Cougar 83")


def test_rraw_reports_filtered_gauges_with_the_offsets_added_back() -> None:
    offsets = (37, -120, 5, 88, -3, 250, -77, 14)
    sim = CougarSim(CougarConfig(gauges=GaugeModel(offsets=offsets), hand_weight_oz=0.0))
    d = Driver(sim)
    assert d.one(cmd("RRAW")).values["gauges"] == offsets  # no load, no WGOV: the offsets themselves
    d.run(cmd("WGOV", offsets=offsets), ticks=60)
    raw = d.one(cmd("RRAW")).values["gauges"]
    # no load: the readings are the offsets again once the WGOV step has passed the filter, within its
    # floor dead band (approached from above: exact; from below: up to 3 counts low)
    assert all(o - 3 <= r <= o for r, o in zip(raw, offsets, strict=True)), (raw, offsets)
    assert np.abs(d.forces()).max() < 1.0  # and with WGOV they cancel


def test_a_wgov_mid_run_reaches_the_forces_through_the_filter() -> None:
    """Erratum cougar-filter-rounding: the offsets are subtracted before the filter (§8.3), so a WGOV
    while the wrist is loaded moves the filtered readings (and the forces) along the filter's step
    response, Y_k = (u_k + u_k-1 + 6 Y_k-1) >> 3 with u_k-1 taken with the old offsets, not in one jump
    as subtracting after the filter would; with constant offsets both orders are bit-identical."""
    load = (300, -200, 150, 0, -50, 75, 400, -10)
    sim = CougarSim(CougarConfig(gauges=GaugeModel(offsets=load), hand_weight_oz=0.0))
    d = Driver(sim)
    d.run(ticks=20)
    filtered = sim.memory.get_int16s("gauge_filtered")
    assert list(filtered) == list(load)  # the constant reading, offsets zero
    step = (80, -80, 8, 0, 16, -24, 400, -10)
    d.run(cmd("WGOV", offsets=step))  # COMINT runs it after this tick's ADC8
    y_prev, u_prev = list(load), list(load)
    seen = []
    for _ in range(40):
        d.run()
        y = [int(v) for v in sim.memory.get_int16s("gauge_filtered")]
        u = [a - o for a, o in zip(load, step, strict=True)]
        assert y == [(u[i] + u_prev[i] + 6 * y_prev[i]) >> 3 for i in range(8)]
        seen.append(y)
        y_prev, u_prev = y, u
    first = seen[0]
    # the first tick moves each channel by (a floor of) an eighth of its offset step: not the whole step
    assert first == [a + ((-o) >> 3) for a, o in zip(load, step, strict=True)]
    assert first != [a - o for a, o in zip(load, step, strict=True)]
    settled = seen[-1]
    assert all(a - o - 3 <= y <= a - o for y, a, o in zip(settled, load, step, strict=True))


# ------------------------------------------------------------------------------------ forces, gravity
@pytest.mark.parametrize(
    "q", [READY, (0, -90, 90, 0, 90, 0), (30, -60, 120, 45, -60, 90), (-100, -150, 170, -80, 30, 200)]
)
def test_gravity_compensation_zeroes_the_hand_in_any_pose(q: tuple[float, ...]) -> None:
    d = Driver(CougarSim(CougarConfig(hand_weight_oz=40.0, hand_cg_mm=(10.0, -5.0, 80.0))))
    d.run(cmd("SEN", theta_sensed=q), ticks=40)
    # Exact up to ADC8's dead band: each filtered gauge may sit up to 3 counts low (errata).
    assert np.all(np.abs(d.forces()) <= dead_band_bound(d.sim) + 1e-3)


def dead_band_bound(sim: CougarSim) -> np.ndarray:
    """The largest force error 3 counts on every gauge can make, per component."""
    return np.asarray(3.0 * np.abs(sim.memory.get("voltmat").reshape(6, 8)).sum(axis=1))


def test_uncompensated_object_shows_its_weight_until_newwc() -> None:
    config = CougarConfig(payload_weight_oz=16.0, payload_cg_mm=(0.0, 0.0, 100.0))
    d = Driver(CougarSim(config))
    d.run(cmd("SEN", theta_sensed=READY), ticks=40)
    f = d.forces()
    # READY: hand axes are world axes; the robot holds the object up: +16 oz along z
    assert f[2] == pytest.approx(16.0, abs=0.3)
    d.run(cmd("NEWWC", weight=16.0, cg=(0.0, 0.0, 100.0)), ticks=2)
    assert np.abs(d.forces()).max() < 0.6


def test_contact_force_is_the_force_the_robot_applies() -> None:
    d = Driver(CougarSim(environment=ceiling(5.0, stiffness=10.0)))
    d.run(ticks=40)
    f = d.forces()
    assert f[:3] == pytest.approx([0.0, 0.0, 50.0], abs=0.3)  # pushing up into the ceiling with 50 oz


def test_frame_vector_moves_the_torque_reference() -> None:
    # A spring pulling the tool sideways: at the wrist centre its lever gives a torque, at the tool none.
    spring = Spring(anchor=(100.0, 149.09 - 20.32 * 0, TOOL_Z), stiffness=0.2)
    d = Driver(CougarSim(CougarConfig(hand_weight_oz=0.0), environment=spring))
    d.run(ticks=40)
    at_wrist = d.forces()
    d.run(cmd("NFV", offset=(0.0, 0.0, 150.0)), ticks=3)
    at_tool = d.forces()
    assert np.allclose(at_wrist[:3], at_tool[:3], atol=0.3)
    assert abs(at_wrist[4]) > 10.0
    assert np.abs(at_tool[3:]).max() < 0.5


def test_nfv_changes_only_the_torque_rows() -> None:
    config = CougarConfig(gauges=GaugeModel(cross_coupling=0.03))
    sim = CougarSim(config)
    vm = region("voltmat")
    before = sim.memory.read_words(vm.address, vm.words)
    Driver(sim).run(cmd("NFV", offset=(12.0, -30.0, 150.0)))
    after = sim.memory.read_words(vm.address, vm.words)
    assert after[: 3 * 16] == before[: 3 * 16]  # force rows: 3 rows x 8 floats x 2 words, untouched
    assert after[3 * 16 :] != before[3 * 16 :]
    full = voltmat(sim.memory.get("calmat"), np.array([12.0, -30.0, 150.0]))
    assert np.allclose(sim.memory.get("voltmat").reshape(6, 8), full, rtol=1e-6, atol=1e-9)


def test_nfv_leaves_elements_it_does_not_affect_bit_identical() -> None:
    cal = resolution_pattern(1.0) * 2048 / 10 / 8  # the ideal wrist's sparse calibration matrix
    sim = CougarSim(CougarConfig(calibration=tuple(cal.reshape(-1))))
    vm = region("voltmat")
    before = np.array(sim.memory.read_words(vm.address, vm.words)).reshape(6, 8, 2)
    Driver(sim).run(cmd("NFV", offset=(0.0, 0.0, 100.0)))
    after = np.array(sim.memory.read_words(vm.address, vm.words)).reshape(6, 8, 2)
    r = np.array([0.0, 0.0, 100.0 / 25.4])
    coupling = np.array([np.cross(r, cal[:3, j]) for j in range(8)]).T  # column j: r x cal_f[:, j]
    changed = np.any(after != before, axis=2)
    assert not changed[:3].any()
    assert np.array_equal(changed[3:], coupling != 0)
    assert 0 < changed.sum() < 24


def test_limit_is_off_by_default_and_works_when_deposited_on() -> None:
    d = Driver(CougarSim(environment=ceiling(5.0, stiffness=200.0)))  # 1000 oz: beyond LIMIT's clamp
    d.run(ticks=40)
    assert d.forces()[2] > 500.0
    d.run(cmd("DPST", address=region("flags").address, value=1))
    f = d.forces()
    assert f[2] == 500.0
    assert np.all(f[[0, 1, 3, 4, 5]] == 0.0)  # everything else is inside the 0.5 dead band


def test_limit_from_config() -> None:
    d = Driver(CougarSim(CougarConfig(limit_on=True, limit_clamp=20.0), environment=ceiling(5.0)))
    d.run(ticks=40)
    assert d.forces()[2] == 20.0


# ------------------------------------------------------------------------------------ calibration
def test_calibration_in_two_positions_recovers_the_gauge_offsets() -> None:
    offsets = (37, -120, 5, 88, -3, 250, -77, 14)
    config = CougarConfig(gauges=GaugeModel(offsets=offsets), hand_weight_oz=40.0, hand_cg_mm=(5, 8, 70))
    d = Driver(CougarSim(config))
    readings = []
    # Hand horizontal, then turned half a turn about its approach vector: gravity reverses in hand axes.
    for q in ((0, -90, 90, 0, 90, 0), (0, -90, 90, 0, 90, 180)):
        d.run(cmd("SEN", theta_sensed=q), ticks=40)
        readings.append(np.array(d.one(cmd("RRAW")).values["gauges"]))
    assert np.abs(readings[0] - readings[1]).max() > 100  # gravity really is visible
    estimate = np.rint((readings[0] + readings[1]) / 2).astype(int)
    assert np.abs(estimate - np.array(offsets)).max() <= 3  # ADC8's floor dead band (errata)
    d.run(cmd("WGOV", offsets=tuple(int(x) for x in estimate)), cmd("SEN", theta_sensed=READY), ticks=40)
    assert np.abs(d.forces()[:3]).max() < 1.5


# ------------------------------------------------------------------------------------ guards
def guard(index: int, stop: bool, dvec: tuple[float, ...], tol: float) -> list[int]:
    return cmd("GUARDS", type_index=(0x8000 if stop else 0) | index, dvec=dvec, tol=tol)


@pytest.mark.parametrize(("stop", "code"), [(True, "GUARD-STOP"), (False, "GUARD-CONTINUE")])
def test_guard_trips_exactly_once(stop: bool, code: str) -> None:
    d = Driver(CougarSim(environment=ceiling(5.0)))  # Fz = +50 oz
    got = d.run(guard(9, stop, (0, 0, 1, 0, 0, 0), 40.0), ticks=30)
    assert [(m.name, m.values["index"]) for m in got] == [(code, 9)]
    assert d.sim.memory.word("guard_active") == 0
    assert d.sim.stats.guards_tripped == 1
    again = d.run(guard(9, stop, (0, 0, 1, 0, 0, 0), 40.0), ticks=5)  # re-armed: trips once more
    assert [m.name for m in again] == [code]


def test_guard_below_tolerance_or_cleared_never_trips() -> None:
    d = Driver(CougarSim(environment=ceiling(5.0)))
    assert d.run(guard(1, True, (0, 0, 1, 0, 0, 0), 60.0), ticks=20) == []  # 50 < 60
    assert d.run(guard(2, True, (0, 0, -1, 0, 0, 0), 10.0), ticks=20) == []  # wrong direction
    d.run(guard(3, False, (0, 0, 1, 0, 0, 0), 10.0), cmd("GUARDC", index=3))
    assert d.run(ticks=20) == []  # armed and cleared in the same tick: the check ran before COMINT


@pytest.mark.parametrize(
    ("type_index", "response"),
    [(0x00F5, "GUARD-CONTINUE"), (0x7FF5, "GUARD-STOP"), (0x0105, "GUARD-STOP"), (0x8005, "GUARD-STOP")],
)
def test_guard_type_is_the_high_byte(type_index: int, response: str) -> None:
    """Erratum guard-type-bit: any bit of the high byte makes a stop guard (the safe reading of 'hi bit'
    and 'high byte'); bits 4-7 are ignored."""
    d = Driver(CougarSim(environment=ceiling(5.0)))
    got = d.run(cmd("GUARDS", type_index=type_index, dvec=(0, 0, 1, 0, 0, 0), tol=1.0), ticks=3)
    assert [(m.name, m.values["index"]) for m in got] == [(response, 5)]


def test_guard_trips_at_equality() -> None:
    """Erratum guard-trip-comparison: a dot product equal to tol trips (a zero dvec makes it exactly 0)."""
    d = Driver(CougarSim(environment=ceiling(5.0)))
    got = d.run(guard(2, False, (0.0,) * 6, 0.0), guard(6, False, (0.0,) * 6, 2.0**-127), ticks=3)
    assert [(m.name, m.values["index"]) for m in got] == [("GUARD-CONTINUE", 2)]


def test_several_guards_trip_in_index_order() -> None:
    d = Driver(CougarSim(environment=ceiling(5.0)))
    got = d.run(guard(12, True, (0, 0, 1, 0, 0, 0), 1.0), guard(4, False, (0, 0, 2, 0, 0, 0), 1.0), ticks=3)
    assert [(m.name, m.values["index"]) for m in got] == [("GUARD-CONTINUE", 4), ("GUARD-STOP", 12)]


# ------------------------------------------------------------------------------------ memory
@settings(max_examples=50, deadline=None)
@given(index=st.integers(0, region("b").words - 1), value=st.integers(0, 0xFFFF))
def test_deposit_then_examine_round_trip(index: int, value: int) -> None:
    sim = CougarSim()
    address = region("b").address + 2 * index
    d = Driver(sim)
    msg = d.one(cmd("DPST", address=address, value=value), cmd("EXMN", address=address, count=1))
    assert msg.values["words"] == (value,)


def test_examine_a_region_reads_what_the_command_wrote() -> None:
    d = Driver(CougarSim())
    k = (1.5, -2.0, 0.25, 100.0, 0.0, -7.0)
    r = region("k")
    msg = d.one(cmd("NK", k=k), cmd("EXMN", address=r.address, count=r.words))
    words = [w for x in k for w in float_words(x)]
    assert msg.values["words"] == tuple(words)


def test_examine_at_bad_addresses() -> None:
    """Erratum cougar-memory-map: a bad address is answered with the count word alone, 0 -- one word
    fewer than Table 1's 'at least 2', acknowledged there; a count of 0 is answered alike."""
    d = Driver(CougarSim())
    for address, count in ((0o1001, 3), (0o170000, 3), (0o1000, 0)):
        msg = d.one(cmd("EXMN", address=address, count=count))
        assert msg.name == "EXMN-DATA" and msg.values["words"] == ()
        assert msg.words == (msg.code, 0)  # the response code, then the count word and nothing else
    tail = d.one(cmd("EXMN", address=MEMORY_BYTES - 4, count=10))
    assert tail.values["words"] == tuple(d.sim.memory.read_words(MEMORY_BYTES - 4, 2))
    d.run(cmd("DPST", address=0o1003, value=1), cmd("DPST", address=0o177776, value=1))
    assert d.sim.stats.bad_addresses == 4


def test_deposited_spring_constants_change_the_answer_like_nk() -> None:
    base = CougarConfig(hand_weight_oz=0.0)
    by_nk, by_dpst = Driver(CougarSim(base)), Driver(CougarSim(base))
    k = (2.0, 3.0, 4.0, 0.5, 0.5, 0.5)
    setup = [cmd("NBJI", bji=(0.01,) * 6)]
    by_nk.run(cmd("NK", k=k), *setup, ticks=2)
    deposits = [
        cmd("DPST", address=region("k").address + 2 * i, value=w)
        for i, w in enumerate(w for x in k for w in float_words(x))
    ]
    by_dpst.run(*deposits, *setup, ticks=2)
    npr = cmd("NPR", theta_sensed=READY, theta_commanded=(1, -89, 91, 2, 3, 4), rate_difference=(0.0,) * 6)
    a, b = by_nk.one(npr), by_dpst.one(npr)
    assert a.values == b.values
    assert any(v != 0 for v in a.values["delta_theta"])  # type: ignore[union-attr]


def test_memory_map_addresses_are_the_documented_ones() -> None:
    # errata cougar-memory-map names these; moving them breaks deposits a Puma program relies on
    documented = {
        "version": 0o1000,
        "flags": 0o1004,
        "fv": 0o1130,
        "k": 0o1144,
        "b": 0o1174,
        "bji": 0o1414,
        "gauge_offsets": 0o1714,
        "gauge_filtered": 0o1754,
        "force": 0o2024,
    }
    assert {name: region(name).address for name in documented} == documented


def test_memory_map_is_ordered_and_in_memory() -> None:
    ends = 0
    for r in MAP:
        assert r.address >= ends and r.address % 2 == 0
        ends = r.end
    assert ends <= MEMORY_BYTES
    assert Memory.valid(MAP[-1].address, MAP[-1].words)


# ------------------------------------------------------------------------------------ NPR
def test_npr_is_zero_until_parameters_are_given() -> None:
    d = Driver(CougarSim(environment=ceiling(5.0)))
    msg = d.one(cmd("NPR", theta_sensed=READY, theta_commanded=READY, rate_difference=(1.0,) * 6))
    assert msg.values["delta_theta"] == (0.0,) * 6


def test_npr_force_term_is_bji_times_j_transpose_times_force_error() -> None:
    q = (10.0, -80.0, 100.0, 20.0, 30.0, 40.0)
    bji = (0.01, 0.02, 0.03, 0.04, 0.05, 0.06)
    fc = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
    d = Driver(CougarSim(CougarConfig(hand_weight_oz=0.0)))
    d.run(cmd("SEN", theta_sensed=q), cmd("NBJI", bji=bji), cmd("NFC", force=fc), ticks=3)
    msg = d.one(cmd("NPR", theta_sensed=q, theta_commanded=q, rate_difference=(0.0,) * 6))
    expected = np.array(bji) * (jacobian(q, frame="tool").T @ np.array(fc))
    assert np.allclose(msg.values["delta_theta"], expected, rtol=1e-5, atol=1e-6)


def test_npr_spring_and_damper_pull_toward_the_command() -> None:
    d = Driver(CougarSim(CougarConfig(hand_weight_oz=0.0)))
    d.run(
        cmd("NK", k=(1.0,) * 6), cmd("NB", b=tuple(np.eye(6).reshape(-1) * 2.0)), cmd("NBJI", bji=(1e-3,) * 6)
    )
    d.run(ticks=2)
    error = np.array([0.5, -0.3, 0.2, 1.0, -0.7, 0.4])
    sensed = np.array(READY) + error
    d.run(cmd("SEN", theta_sensed=tuple(sensed)), ticks=2)
    spring = d.one(cmd("NPR", theta_sensed=tuple(sensed), theta_commanded=READY, rate_difference=(0.0,) * 6))
    assert float(np.dot(spring.values["delta_theta"], error)) < 0
    damper = d.one(
        cmd("NPR", theta_sensed=tuple(sensed), theta_commanded=tuple(sensed), rate_difference=tuple(error))
    )
    assert float(np.dot(damper.values["delta_theta"], error)) < 0


def test_under_compliance_the_arm_yields_to_a_contact() -> None:
    q0 = (10.0, -60.0, 120.0, 0.0, 30.0, 0.0)  # away from READY's elbow singularity
    sim = CougarSim(CougarConfig(initial_angles=q0))
    tool = sim.tool_pose()
    # the tool point is 5 mm into a wall that faces it
    surface = Surface(point=tuple(tool.p - 5.0 * tool.a), normal=tuple(-tool.a), stiffness=10.0)
    sim.environment = surface
    d = Driver(sim)
    d.run(cmd("NBJI", bji=(2e-3,) * 6), ticks=40)
    assert d.forces()[2] == pytest.approx(50.0, abs=1.5)  # pushing along its approach vector
    theta = np.array(q0)
    zero = (0.0,) * 6
    for _ in range(120):  # the Puma's side of the loop: send NPR, integrate the NTD it gets back
        msg = d.one(cmd("NPR", theta_sensed=tuple(theta), theta_commanded=tuple(theta), rate_difference=zero))
        theta = theta + np.array(msg.values["delta_theta"]) * DT
    assert surface.penetration(sim.tool_pose()) < 0.5
    assert np.abs(theta - q0).max() < 5.0


def test_rst_zeroes_the_filter_state() -> None:
    config = CougarConfig(hand_weight_oz=0.0, filter_con3=1.0, filter_con4=0.0)
    d = Driver(CougarSim(config))
    d.run(cmd("NBJI", bji=(0.1,) * 6), cmd("NFC", force=(10.0,) * 6), ticks=2)
    npr = cmd("NPR", theta_sensed=READY, theta_commanded=READY, rate_difference=(0.0,) * 6)
    first = d.one(npr)
    assert any(v != 0 for v in first.values["delta_theta"])  # type: ignore[union-attr]
    d.run(cmd("RST"))
    assert np.all(d.sim.memory.get("dtheta_filtered") == 0)
    assert np.all(d.sim.memory.get("dtheta_previous") == 0)
    assert d.one(npr).values == first.values  # the step starts again from rest


# ------------------------------------------------------------------------------------ JACOB
def test_jacobian_double_buffer_never_shows_a_half_computed_one() -> None:
    sim = CougarSim(CougarConfig(jacob_steps_per_tick=0))
    old = front_buffer(sim.memory)
    q = (20.0, -70.0, 110.0, 10.0, 40.0, 0.0)
    bji = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    sim.receive(cmd("SEN", theta_sensed=q) + cmd("NBJI", bji=tuple(bji)))
    sim.tick(0.0)
    for _ in range(STEPS - 1):
        sim.run_background(1)
        for a, b in zip(front_buffer(sim.memory), old, strict=True):
            assert np.array_equal(a, b)  # the foreground still reads the old complete set
    sim.run_background(1)
    j, jt, p = front_buffer(sim.memory)
    assert np.allclose(
        j, centre_jacobian(np.array(q), np.zeros(3), sim.config.geometry), rtol=1e-6, atol=1e-6
    )
    assert np.array_equal(jt, j.T)
    assert np.allclose(p, bji[:, None] * j.T, rtol=1e-6)
    assert not np.array_equal(j, old[0])


def test_jacob_uses_a_snapshot_taken_at_its_first_step() -> None:
    sim = CougarSim(CougarConfig(jacob_steps_per_tick=0))
    q1, q2 = (20.0, -70.0, 110.0, 10.0, 40.0, 0.0), (-20.0, -100.0, 80.0, 0.0, 10.0, 0.0)
    sim.receive(cmd("SEN", theta_sensed=q1))
    sim.tick(0.0)
    sim.run_background(1)
    sim.receive(cmd("SEN", theta_sensed=q2))  # arrives mid-computation
    sim.tick(1.0)
    sim.run_background(STEPS - 1)
    j = front_buffer(sim.memory)[0]
    assert np.allclose(j, centre_jacobian(np.array(q1), np.zeros(3), sim.config.geometry), atol=1e-5)
    sim.run_background(STEPS)
    j = front_buffer(sim.memory)[0]
    assert np.allclose(j, centre_jacobian(np.array(q2), np.zeros(3), sim.config.geometry), atol=1e-5)
    assert sim.stats.jacob_cycles == 3  # INIT's, then two


# ------------------------------------------------------------------------------------ GUTS
def test_guts_reentry_by_time_is_reported_on_the_terminal() -> None:
    sim = CougarSim()
    sim.receive(cmd("VERS", version=1))
    assert sim.tick(0.0) != []
    sim.receive(cmd("VERS", version=1))
    assert sim.tick(0.001) == []  # GUTS would still be running: 4 ms plus the command
    assert sim.terminal.endswith("!")
    assert sim.stats.guts_reentries == 1
    assert sim.tick(DT) != []  # the command waited in the buffer
    assert sim.stats.ticks == 2


def test_guts_reentry_by_a_nested_call() -> None:
    nested: list[list[int]] = []

    class Meddler:
        sim: CougarSim | None = None

        def wrench(self, tool: Transform) -> Wrench:
            if self.sim is not None:
                nested.append(self.sim.tick(99.0))
            return Wrench()

    env = Meddler()
    sim = CougarSim(environment=env)
    env.sim = sim
    sim.receive(cmd("RFRC"))
    out = sim.tick(0.0)
    assert nested == [[]]
    assert len(answers(out)) == 1
    assert sim.stats.guts_reentries == 1
    assert sim.memory.word("guts_busy") == 0


def test_time_must_not_go_backwards() -> None:
    sim = CougarSim()
    sim.tick(1.0)
    with pytest.raises(ValueError, match="backwards"):
        sim.tick(0.5)


def test_noise_is_deterministic_given_the_seed() -> None:
    config = CougarConfig(gauges=GaugeModel(noise=3.0))

    def raws(seed: int) -> list[Any]:
        d = Driver(CougarSim(config, seed=seed))
        return [d.one(cmd("RRAW")).values["gauges"] for _ in range(10)]

    assert raws(5) == raws(5)
    assert raws(5) != raws(6)


def test_stats_count_words_and_commands() -> None:
    sim = CougarSim()
    sim.receive([0, 0, *cmd("RFRC"), 200, 1, 2])
    out = sim.tick(0.0)
    s = sim.stats
    assert (s.words_received, s.commands, s.out_of_sync, s.discarded_words) == (6, 3, 1, 3)
    assert s.words_sent == len(out) == 13 + 2


# ------------------------------------------------------------------------------------ environment
def test_surface_spring_and_contacts() -> None:
    pose = Transform.trans(0.0, 0.0, -2.0)
    table = Surface(stiffness=5.0)
    assert table.penetration(pose) == 2.0
    assert table.wrench(pose).force == (0.0, 0.0, 10.0)
    assert table.wrench(Transform.trans(0.0, 0.0, 3.0)) == Wrench()
    spring = Spring(anchor=(10.0, 0.0, -2.0), stiffness=0.5, rest_length=4.0)
    assert spring.wrench(pose).force == pytest.approx((3.0, 0.0, 0.0))
    both = Contacts((table, spring, FreeSpace()))
    assert both.wrench(pose).force == pytest.approx((3.0, 0.0, 10.0))
    with pytest.raises(ValueError):
        Surface(normal=(0.0, 0.0, 0.0))


def test_tool_torque_about_the_wrist_centre() -> None:
    # A sideways pull at the tool point (150 mm out along z) is a torque about y at the wrist centre.
    spring = Spring(anchor=(-20.32 + 1000.0, 149.09, TOOL_Z), stiffness=0.01, rest_length=0.0)
    sim = CougarSim(CougarConfig(hand_weight_oz=0.0), environment=spring)
    d = Driver(sim)
    d.run(ticks=40)
    f = d.forces()
    pull = 0.01 * 1000.0  # oz along +x on the tool; the robot applies -x
    assert f[0] == pytest.approx(-pull, abs=0.3)
    assert f[4] == pytest.approx(-(150.0 / 25.4) * pull, abs=0.6)
    assert math.isclose(f[1], 0.0, abs_tol=0.3)
